"""Batched evaluation of a linear head model: shape blending, joints, skinning, landmarks.

    v_shaped = template + sum_k (beta_k * s_k) B_k + sum_k (psi_k * e_k) E_k
    joints   = joint_rest + sum_k (beta_k * s_k) JB_k
    v_posed  = sum_j w_vj * G_j(rot) (v_shaped - joints_j) + translation

Joint rotations are local axis-angle vectors (radians), one per joint, applied about the
joint's (identity-dependent) rest position and composed down the kinematic chain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.errors import CodeError, SynthError
from synth.geometry import exact
from synth.geometry.rotations import axis_angle_to_matrix
from synth.model.eyelids import EXACT_OPS, EyelidRig, apply_eyelids
from synth.model.format import HeadModelData


@dataclass
class Evaluation:
    vertices: np.ndarray  # (B, V, 3) float32
    joint_transforms: np.ndarray  # (B, J, 4, 4) float32, world frames of the posed joints
    landmarks: dict[str, np.ndarray]  # set -> (B, L, 3) float32


def _check_codes(x, name: str, dim: int, dtype) -> tuple[np.ndarray, bool]:
    if x is None:
        raise CodeError(f"argument '{name}' is required", name, f"pass an array of length {dim}")
    try:
        a = np.asarray(x, dtype=dtype)
    except (TypeError, ValueError):
        raise CodeError(f"argument '{name}' is not numeric", name, f"pass an array of length {dim}") from None
    single = a.ndim == 1
    if single:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != dim:
        raise CodeError(f"argument '{name}' has shape {np.shape(x)}, expected ({dim},) or (B, {dim})",
                        name, f"this model has {dim} {name} dimensions")
    if not np.all(np.isfinite(a)):
        raise CodeError(f"argument '{name}' contains NaN or Inf", name, "pass finite values")
    return a, single


class HeadModel:
    """Evaluates a :class:`HeadModelData`. Thread-safe (no mutable state after init)."""

    def __init__(self, data: HeadModelData, dtype=np.float32):
        self.data = data
        self.dtype = np.dtype(dtype)
        d = data
        V = d.num_vertices
        self.V, self.J = V, len(d.joint_names)
        self.Ki, self.Ke = d.identity_dims, d.expression_dims
        dt = self.dtype
        self._template = d.template.astype(dt).reshape(1, V * 3)
        # identity and expression bases, scaled and stacked into one (Ki + Ke, 3V) matrix
        self._basis = np.concatenate([
            (d.identity_basis * d.identity_scale[:, None, None]).reshape(self.Ki, V * 3),
            (d.expression_basis * d.expression_scale[:, None, None]).reshape(self.Ke, V * 3)]).astype(dt)
        self._joint_rest = d.joint_rest.astype(dt).reshape(1, self.J * 3)
        self._joint_basis = (d.joint_identity_basis * d.identity_scale[:, None, None]).astype(dt).reshape(
            self.Ki, self.J * 3)
        self._parents = d.joint_parents.astype(np.int64)
        # sparse skinning: vertices bound rigidly to one joint are transformed once; only the
        # blended ones (weights split between joints) are accumulated per joint
        w = d.skin_weights
        rigid = w.max(1) >= 1.0 - 1e-6
        self._rigid = [np.nonzero(rigid & (w[:, j] >= 1.0 - 1e-6))[0] for j in range(self.J)]
        self._blend_idx = np.nonzero(~rigid)[0]
        wb = w[self._blend_idx]
        self._skin = []
        for j in range(self.J):
            sel = np.nonzero(wb[:, j] > 0)[0]
            self._skin.append((sel, wb[sel, j].astype(dt)[None, :, None]))
        # landmarks: vertex indices of the corners and barycentric weights
        self._lm = {s: (d.triangles[tri].astype(np.int64), bary.astype(dt)) for s, (tri, bary) in d.landmarks.items()}
        self.joint_index = {n: i for i, n in enumerate(d.joint_names)}
        self._eyelids = EyelidRig.from_data(d)  # None for models without the rig (imported ones)

    # ---- public API -----------------------------------------------------------------

    def vertices(self, identity, expression, joint_rotations=None, translation=None) -> np.ndarray:
        """(B, V, 3) posed vertices. 1-D codes give B = 1."""
        return self.evaluate(identity, expression, joint_rotations, translation, landmarks=False).vertices

    def joint_transforms(self, identity, expression=None, joint_rotations=None, translation=None) -> np.ndarray:
        """(B, J, 4, 4) world transforms of the posed joints (rotation and position)."""
        beta, _ = _check_codes(identity, "identity", self.Ki, self.dtype)
        rot, trans = self._check_pose(joint_rotations, translation, beta.shape[0])
        joints = self._joints(beta)
        G, _ = self._chain(joints, rot, trans)
        return G

    def landmarks(self, identity, expression, joint_rotations=None, translation=None,
                  landmark_set: str = "ibug68") -> np.ndarray:
        """(B, L, 3) 3D landmarks on the posed surface."""
        ev = self.evaluate(identity, expression, joint_rotations, translation, landmarks=True)
        if landmark_set not in ev.landmarks:
            raise CodeError(f"unknown landmark set '{landmark_set}'", "landmark_set",
                            f"choose one of {sorted(ev.landmarks)}")
        return ev.landmarks[landmark_set]

    def evaluate(self, identity, expression, joint_rotations=None, translation=None,
                 landmarks: bool = True) -> Evaluation:
        beta, _ = _check_codes(identity, "identity", self.Ki, self.dtype)
        psi, _ = _check_codes(expression, "expression", self.Ke, self.dtype)
        B = beta.shape[0]
        if psi.shape[0] != B:
            if psi.shape[0] == 1:
                psi = np.broadcast_to(psi, (B, self.Ke))
            elif B == 1:
                beta = np.broadcast_to(beta, (psi.shape[0], self.Ki))
                B = psi.shape[0]
            else:
                raise CodeError(f"batch sizes differ: identity {B}, expression {psi.shape[0]}", "expression",
                                "pass equal batch sizes or a single code")
        rot, trans = self._check_pose(joint_rotations, translation, B)
        shaped = exact.lincomb(np.concatenate([beta, psi], axis=1), self._basis)
        shaped += self._template
        shaped = shaped.reshape(B, self.V, 3)
        joints = self._joints(beta)
        if self._eyelids is not None:
            self._move_eyelids(shaped, joints, psi, rot)
        G, A = self._chain(joints, rot, trans)
        posed = self._skin_vertices(shaped, A, rot is None and trans is None)
        lms = {}
        if landmarks:
            for s, (corners, bary) in self._lm.items():
                lms[s] = ((posed[:, corners[:, 0]] * bary[None, :, 0, None]
                           + posed[:, corners[:, 1]] * bary[None, :, 1, None])
                          + posed[:, corners[:, 2]] * bary[None, :, 2, None]).astype(self.dtype)
        return Evaluation(posed, G, lms)

    # ---- internals ------------------------------------------------------------------

    def _check_pose(self, joint_rotations, translation, B):
        rot = trans = None
        if joint_rotations is not None:
            r = np.asarray(joint_rotations, dtype=self.dtype)
            if r.ndim == 2:
                r = r[None]
            if r.ndim != 3 or r.shape[1:] != (self.J, 3) or r.shape[0] not in (1, B):
                raise CodeError(f"argument 'joint_rotations' has shape {np.shape(joint_rotations)}, expected "
                                f"(B, {self.J}, 3) axis-angle", "joint_rotations",
                                f"joints are {list(self.data.joint_names)}")
            if not np.all(np.isfinite(r)):
                raise CodeError("argument 'joint_rotations' contains NaN or Inf", "joint_rotations",
                                "pass finite values")
            rot = np.broadcast_to(r, (B, self.J, 3))
        if translation is not None:
            t = np.asarray(translation, dtype=self.dtype)
            if t.ndim == 1:
                t = t[None]
            if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] not in (1, B):
                raise CodeError(f"argument 'translation' has shape {np.shape(translation)}, expected (B, 3)",
                                "translation", "pass metres as (3,) or (B, 3)")
            if not np.all(np.isfinite(t)):
                raise CodeError("argument 'translation' contains NaN or Inf", "translation", "pass finite values")
            trans = np.broadcast_to(t, (B, 3))
        return rot, trans

    def _move_eyelids(self, shaped: np.ndarray, joints: np.ndarray, psi: np.ndarray, rot) -> None:
        """The eyelid rig (synth.model.eyelids), in place, before skinning."""
        B = shaped.shape[0]
        eye_rot = {}
        for e in self._eyelids.eyes:
            eye_rot[e.joint] = (np.broadcast_to(np.eye(3), (B, 3, 3)) if rot is None
                                else axis_angle_to_matrix(rot[:, e.joint].astype(np.float64)))
        moved = apply_eyelids(self._eyelids, shaped, joints, psi, eye_rot, EXACT_OPS)
        for idx, p in moved.values():
            shaped[:, idx] = p

    def _joints(self, beta: np.ndarray) -> np.ndarray:
        return (exact.lincomb(beta, self._joint_basis) + self._joint_rest).reshape(-1, self.J, 3)

    def _chain(self, joints: np.ndarray, rot, trans):
        """World joint frames G (B,J,4,4) and skinning transforms A = G * [I | -j_rest]."""
        B, J = joints.shape[0], self.J
        dt = self.dtype
        if rot is None:
            R = np.broadcast_to(np.eye(3, dtype=dt), (B, J, 3, 3))
        else:
            R = axis_angle_to_matrix(rot).astype(dt)
        Rw = np.empty((B, J, 3, 3), dt)
        tw = np.empty((B, J, 3), dt)
        for j in range(J):
            p = self._parents[j]
            if p < 0:
                Rw[:, j] = R[:, j]
                tw[:, j] = joints[:, j]
            else:
                Rw[:, j] = exact.matmul3(Rw[:, p], R[:, j])
                # joint position moves rigidly with its parent
                tw[:, j] = exact.matvec3(Rw[:, p], joints[:, j] - joints[:, p]) + tw[:, p]
        if trans is not None:
            tw = tw + trans[:, None, :]
        G = np.zeros((B, J, 4, 4), dt)
        G[:, :, :3, :3] = Rw
        G[:, :, :3, 3] = tw
        G[:, :, 3, 3] = 1.0
        A_t = tw - exact.matvec3(Rw, joints)
        return G, (Rw, A_t)

    def _skin_vertices(self, shaped: np.ndarray, A, identity_pose: bool) -> np.ndarray:
        if identity_pose:
            return shaped
        Rw, At = A
        RwT = np.swapaxes(Rw, -1, -2)
        out = np.empty_like(shaped)
        for j, idx in enumerate(self._rigid):
            if idx.size:
                out[:, idx] = exact.points_times_matrix(shaped[:, idx], RwT[:, j]) + At[:, j, None, :]
        if self._blend_idx.size:
            vb = shaped[:, self._blend_idx]
            acc = np.zeros_like(vb)
            for j, (sel, w) in enumerate(self._skin):
                if sel.size:
                    acc[:, sel] += w * (exact.points_times_matrix(vb[:, sel], RwT[:, j]) + At[:, j, None, :])
            out[:, self._blend_idx] = acc
        return out


def landmark_basis(model: HeadModelData, landmark_set: str = "ibug68") -> tuple[np.ndarray, np.ndarray]:
    """Neutral landmarks as template (L, 3) + code @ basis (Ki, L, 3) (identity_scale applied)."""
    if landmark_set not in model.landmarks:
        raise SynthError(f"the model has no '{landmark_set}' landmarks", model.name,
                         "use camera.target = 'origin' or a model with ibug68 landmarks")
    tri, bary = model.landmarks[landmark_set]
    corners = model.triangles[tri]  # (L, 3)
    b = bary.astype(np.float64)
    T = model.template[corners].astype(np.float64)  # (L, 3 corners, 3), summed corner by corner in order
    t = (T[:, 0] * b[:, 0, None] + T[:, 1] * b[:, 1, None]) + T[:, 2] * b[:, 2, None]
    basis = model.identity_basis.astype(np.float64) * model.identity_scale.astype(np.float64)[:, None, None]
    C = basis[:, corners]
    B = (C[:, :, 0] * b[None, :, 0, None] + C[:, :, 1] * b[None, :, 1, None]) + C[:, :, 2] * b[None, :, 2, None]
    return t, B
