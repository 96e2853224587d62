"""The head model's forward evaluation in torch: differentiable, batched, on any device.

The same maths as :class:`synth.model.head.HeadModel` (the numpy reference, see its
docstring and docs/model-format.md):

    v_shaped = template + sum_k (beta_k s_k) B_k + sum_k (psi_k e_k) E_k
    joints   = joint_rest + sum_k (beta_k s_k) JB_k
    v_posed  = sum_j w_vj (Rw_j v_shaped + tw_j - Rw_j joints_j)  (+ translation, in tw)

with Rw_j, tw_j the world rotation and position of joint j composed down the kinematic
chain from local axis-angle rotations about the joints' (identity-dependent) rest positions.

Evaluation can be restricted to a subset of the vertices (:meth:`TorchHeadModel.subset`):
fitting to landmarks only needs the corners of the landmark triangles (183 of 6,393
vertices for ibug68 on the embedded default model), so the basis product, the skinning
and the gradients are computed for those rows only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
import torch

from prior.fit.rotations import axis_angle_to_matrix
from synth.errors import CodeError
from synth.model.eyelids import EyelidRig, apply_eyelids
from synth.model.format import HeadModelData


@dataclass
class VertexSubset:
    """Rows of the model restricted to some vertices (all tensors on the model's device)."""

    index: torch.Tensor  # (n,) long, vertex indices into the full model
    template: torch.Tensor  # (m*3,) of the m rows evaluated: the n vertices, then what the eyelid rig reads
    basis: torch.Tensor  # (Ki + Ke, m*3), scales applied
    weights: torch.Tensor  # (n, J) skinning weights
    joints: torch.Tensor  # (k,) long, the joints with a non-zero weight on some vertex of the subset
    eyelids: EyelidRig | None = None  # the rig with row indices (None: no lid vertex in the subset)
    n: int = -1  # the first n rows are the subset's vertices (-1: all rows)


@dataclass
class Pose:
    """World frames of the posed joints: rotations Rw (B, J, 3, 3), positions tw (B, J, 3),
    and the rest joint positions (B, J, 3) they were posed from."""

    rotations: torch.Tensor
    positions: torch.Tensor
    rest: torch.Tensor

    def matrices(self) -> torch.Tensor:
        """(B, J, 4, 4) joint-to-world transforms (as HeadModel.joint_transforms)."""
        B, J = self.positions.shape[:2]
        G = torch.zeros(B, J, 4, 4, dtype=self.rotations.dtype, device=self.rotations.device)
        G[..., :3, :3] = self.rotations
        G[..., :3, 3] = self.positions
        G[..., 3, 3] = 1.0
        return G


class TorchHeadModel:
    """Evaluates a :class:`HeadModelData` in torch (float64 by default)."""

    def __init__(self, data: HeadModelData, dtype: torch.dtype = torch.float64, device="cpu"):
        self.data = data
        self.dtype, self.device = dtype, torch.device(device)
        self.V, self.J = data.num_vertices, len(data.joint_names)
        self.Ki, self.Ke = data.identity_dims, data.expression_dims
        self.joint_names = list(data.joint_names)
        self.joint_index = {n: i for i, n in enumerate(self.joint_names)}
        self.parents = [int(p) for p in data.joint_parents]
        basis = np.concatenate([
            data.identity_basis.astype(np.float64) * data.identity_scale.astype(np.float64)[:, None, None],
            data.expression_basis.astype(np.float64) * data.expression_scale.astype(np.float64)[:, None, None]])
        self._basis_np = basis  # (K, V, 3), float64; subsets slice it before conversion
        self.joint_rest = self._t(data.joint_rest)  # (J, 3)
        self.joint_basis = self._t(data.joint_identity_basis.astype(np.float64)
                                   * data.identity_scale.astype(np.float64)[:, None, None]).reshape(self.Ki, -1)
        self._landmark_sets = {s: (np.asarray(data.triangles)[tri].astype(np.int64), np.asarray(bary, np.float64))
                               for s, (tri, bary) in data.landmarks.items()}
        self._subsets: dict[str, tuple[VertexSubset, torch.Tensor, torch.Tensor]] = {}
        self._full: VertexSubset | None = None
        self._eyelids = EyelidRig.from_data(data)
        self._ops = SimpleNamespace(atan2=torch.atan2, asin=torch.asin, acos=torch.acos, sqrt=torch.sqrt, sin=torch.sin,
                                    cos=torch.cos, clip=torch.clamp, maximum=torch.maximum, stack=torch.stack,
                                    const=self._t)

    def _t(self, a) -> torch.Tensor:
        return torch.as_tensor(np.asarray(a, np.float64), dtype=self.dtype, device=self.device)

    # ---- subsets ----------------------------------------------------------------------

    def subset(self, vertex_index) -> VertexSubset:
        """The model rows of the given vertices (evaluate with :meth:`points`)."""
        idx = np.asarray(vertex_index, np.int64).reshape(-1)
        if idx.size and (idx.min() < 0 or idx.max() >= self.V):
            raise CodeError("vertex index out of range", "vertex_index", f"indices must be in [0, {self.V})")
        d = self.data
        rows, rig = idx, None
        if self._eyelids is not None and np.isin(idx, np.concatenate([e.vertices for e in self._eyelids.eyes])).any():
            # the rig moves a lid vertex from the margins and an eyeball radius: evaluate those rows too
            rows = np.r_[idx, np.setdiff1d(self._eyelids.support(), idx)]
            at = {int(v): i for i, v in enumerate(rows)}
            rig = replace(self._eyelids, eyes=[replace(e, vertices=np.array([at[int(v)] for v in e.vertices], np.int64),
                                                       sclera_vertex=at[e.sclera_vertex]) for e in self._eyelids.eyes])
        return VertexSubset(
            index=torch.as_tensor(idx, device=self.device),
            template=self._t(d.template[rows]).reshape(-1),
            basis=self._t(self._basis_np[:, rows]).reshape(self.Ki + self.Ke, -1),
            weights=self._t(d.skin_weights[idx]),
            joints=torch.as_tensor(np.nonzero(np.any(d.skin_weights[idx] != 0, axis=0))[0], device=self.device),
            eyelids=rig, n=len(idx) if rig is not None else -1)

    def full(self) -> VertexSubset:
        if self._full is None:
            self._full = self.subset(np.arange(self.V))
        return self._full

    def define_landmarks(self, name: str, triangles, bary) -> None:
        """Add (or replace) a landmark set: triangle indices (L,) and barycentric weights (L, 3)."""
        tri = np.asarray(triangles, np.int64).reshape(-1)
        b = np.asarray(bary, np.float64).reshape(-1, 3)
        T = len(self.data.triangles)
        if len(tri) != len(b) or (tri.size and (tri.min() < 0 or tri.max() >= T)):
            raise CodeError(f"landmark set '{name}' needs (L,) triangles in [0, {T}) and (L, 3) barycentrics",
                            "landmarks", "check the landmark definition")
        self._landmark_sets[name] = (np.asarray(self.data.triangles)[tri].astype(np.int64), b)
        self._subsets.pop(name, None)

    def landmark_subset(self, landmark_set: str = "ibug68") -> tuple[VertexSubset, torch.Tensor, torch.Tensor]:
        """(subset of the corner vertices, corner positions in the subset (L, 3), barycentric (L, 3))."""
        if landmark_set not in self._subsets:
            if landmark_set not in self._landmark_sets:
                raise CodeError(f"unknown landmark set '{landmark_set}'", "landmark_set",
                                f"choose one of {sorted(self._landmark_sets)}")
            corners, bary = self._landmark_sets[landmark_set]
            uniq, inv = np.unique(corners, return_inverse=True)
            self._subsets[landmark_set] = (self.subset(uniq), torch.as_tensor(inv.reshape(corners.shape),
                                                                              device=self.device), self._t(bary))
        return self._subsets[landmark_set]

    # ---- evaluation -------------------------------------------------------------------

    def _codes(self, identity, expression, joint_rotations, translation):
        beta = self._as(identity, "identity", (self.Ki,))
        psi = self._as(expression, "expression", (self.Ke,))
        rot = None if joint_rotations is None else self._as(joint_rotations, "joint_rotations", (self.J, 3))
        trans = None if translation is None else self._as(translation, "translation", (3,))
        sizes = {x.shape[0] for x in (beta, psi, rot, trans) if x is not None}
        B = max(sizes)
        if sizes - {1, B}:
            raise CodeError(f"batch sizes differ: {sorted(sizes)}", "codes", "pass equal batch sizes or single codes")
        beta, psi = beta.expand(B, -1), psi.expand(B, -1)
        rot = None if rot is None else rot.expand(B, -1, -1)
        trans = None if trans is None else trans.expand(B, -1)
        return beta, psi, rot, trans

    def _as(self, x, name: str, shape: tuple[int, ...]) -> torch.Tensor:
        t = torch.as_tensor(x, dtype=self.dtype, device=self.device)
        if t.dim() == len(shape):
            t = t.unsqueeze(0)
        if t.dim() != len(shape) + 1 or tuple(t.shape[1:]) != shape:
            raise CodeError(f"argument '{name}' has shape {tuple(t.shape)}, expected {shape} or (B, *{shape})",
                            name, "see docs/model-format.md")
        return t

    def pose(self, identity, joint_rotations=None, translation=None) -> Pose:
        """Joint world frames for identity codes (B, Ki), local axis-angle rotations (B, J, 3)
        and a translation (B, 3) of the whole head (None = zero)."""
        beta = self._as(identity, "identity", (self.Ki,))
        rest = (beta @ self.joint_basis).reshape(-1, self.J, 3) + self.joint_rest
        B = rest.shape[0]
        if joint_rotations is None:
            R = torch.eye(3, dtype=self.dtype, device=self.device).expand(B, self.J, 3, 3)
        else:
            R = axis_angle_to_matrix(self._as(joint_rotations, "joint_rotations", (self.J, 3)).expand(B, -1, -1))
        Rw, tw = [], []
        for j, p in enumerate(self.parents):
            if p < 0:
                Rw.append(R[:, j])
                tw.append(rest[:, j])
            else:  # the joint moves rigidly with its parent
                Rw.append(Rw[p] @ R[:, j])
                tw.append((Rw[p] @ (rest[:, j] - rest[:, p]).unsqueeze(-1)).squeeze(-1) + tw[p])
        Rw_t, tw_t = torch.stack(Rw, 1), torch.stack(tw, 1)
        if translation is not None:
            tw_t = tw_t + self._as(translation, "translation", (3,)).expand(B, -1).unsqueeze(1)
        return Pose(Rw_t, tw_t, rest)

    def points(self, sub: VertexSubset, identity, expression, joint_rotations=None, translation=None) -> torch.Tensor:
        """(B, n, 3) posed positions of the subset's vertices."""
        beta, psi, rot, trans = self._codes(identity, expression, joint_rotations, translation)
        B = beta.shape[0]
        shaped = (torch.cat([beta, psi], 1) @ sub.basis + sub.template).reshape(B, -1, 3)
        if sub.eyelids is not None:
            shaped = self._move_eyelids(sub, shaped, beta, psi, rot)
        if rot is None and trans is None:
            return shaped
        P = self.pose(beta, rot, trans)
        offset = P.positions - (P.rotations @ P.rest.unsqueeze(-1)).squeeze(-1)  # (B, J, 3)
        # blend the joints' affine maps per vertex, then apply them once (cheaper than
        # transforming every vertex by every joint, notably under forward-mode autodiff);
        # joints that move none of the subset's vertices are skipped
        W, j = sub.weights[:, sub.joints], sub.joints
        M = (W @ P.rotations[:, j].reshape(B, -1, 9)).reshape(B, -1, 3, 3)
        return (M * shaped.unsqueeze(-2)).sum(-1) + W @ offset[:, j]

    def _move_eyelids(self, sub: VertexSubset, shaped, beta, psi, rot) -> torch.Tensor:
        """The eyelid rig (synth.model.eyelids, as HeadModel applies it), then only the subset's rows."""
        B = shaped.shape[0]
        rest = (beta @ self.joint_basis).reshape(-1, self.J, 3) + self.joint_rest
        eye = torch.eye(3, dtype=self.dtype, device=self.device).expand(B, 3, 3)
        eye_rot = {e.joint: eye if rot is None else axis_angle_to_matrix(rot[:, e.joint]) for e in sub.eyelids.eyes}
        shaped = shaped.clone()
        for rows, p in apply_eyelids(sub.eyelids, shaped, rest, psi, eye_rot, self._ops).values():
            shaped[:, rows] = p
        return shaped[:, :sub.n]

    def eyelid_parameters(self, share: float = 0.1) -> tuple[list[int], list[int]]:
        """(expression indices, joint indices) on which the eyelid rig bends the lids
        non-linearly: the eye joints, and the codes whose blendshape moves a lid-margin vertex
        by at least ``share`` of the most any code does (the margins are what the rig lays on
        the pitched cornea). Both empty for models without the rig."""
        if self._eyelids is None:
            return [], []
        d = self.data
        margins = np.concatenate([np.r_[d.regions[f"eyelid_{s}_upper"], d.regions[f"eyelid_{s}_lower"]] for s in "lr"])
        move = np.abs(self._basis_np[self.Ki:, margins]).max(axis=(1, 2))
        return np.nonzero(move >= share * move.max())[0].tolist(), sorted(e.joint for e in self._eyelids.eyes)

    def vertices(self, identity, expression, joint_rotations=None, translation=None) -> torch.Tensor:
        """(B, V, 3) posed vertices."""
        return self.points(self.full(), identity, expression, joint_rotations, translation)

    def landmarks(self, identity, expression, joint_rotations=None, translation=None,
                  landmark_set: str = "ibug68") -> torch.Tensor:
        """(B, L, 3) landmarks on the posed surface, evaluating only their triangles' corners."""
        sub, corners, bary = self.landmark_subset(landmark_set)
        p = self.points(sub, identity, expression, joint_rotations, translation)
        return torch.einsum("blkc,lk->blc", p[:, corners], bary)

    def joint_transforms(self, identity, joint_rotations=None, translation=None) -> torch.Tensor:
        """(B, J, 4, 4) world transforms of the posed joints."""
        return self.pose(identity, joint_rotations, translation).matrices()
