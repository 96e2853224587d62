"""ICT-FaceKit topology facts and the rig derived from its shapes (joints, skin weights,
regions). Used by :mod:`synth.model.importers.ict_facekit`; see docs/importers.md.

Vertex ranges are those of the ICT-FaceKit README (half-open here). All geometry is in
synth axes (metres, Z up, face -Y, +X subject's left).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.geometry.rotations import fit_rigid, rotation_pivot
from synth.model import meshutil as mu
from synth.model.importers import regions as rg

NUM_VERTICES = 26719
FACE = (0, 9409)  # the narrow face area 0-6706, then the ears, then the rest of the face
EAR_BLOCK = (6706, 8186)  # both ears (plus a few stray skin vertices)
SKIN = (0, 11248)  # the face, then the head and neck 9409-11248
MOUTH_SOCKET = (11248, 13294)
EYE_SOCKET = {"l": (13294, 13678), "r": (13678, 14062)}
GUMS_TONGUE = (14062, 17039)
TEETH = (17039, 21451)
TEETH_LOWER = (19247, 21451)
SCLERA = {"l": (21451, 22221), "r": (23021, 23791)}
IRIS = {"l": (22221, 23021), "r": (23791, 24591)}
EYEBALL = {"l": (21451, 23021), "r": (23021, 24591)}
EYE_FLUIDS = {"l": [(24591, 24795), (24999, 25023), (25047, 25199)],  # lacrimal, blend, occlusion
              "r": [(24795, 24999), (25023, 25047), (25199, 25351)]}
LASHES = {"l": (25351, 26035), "r": (26035, 26719)}

#: a cornea vertex stands this far (m) proud of the eyeball's fitted sphere (:func:`cornea`)
CORNEA_RISE_M = 2e-4

JOINT_NAMES = ["neck", "head", "jaw", "eye_l", "eye_r"]
JOINT_PARENTS = np.array([-1, 0, 1, 1, 1], np.int32)


def rng(*ranges: tuple[int, int]) -> np.ndarray:
    return np.concatenate([np.arange(a, b) for a, b in ranges]).astype(np.int64)


def cornea(v: np.ndarray, shell: np.ndarray) -> np.ndarray:
    """The corneal cap of an eyeball's outer shell ``shell`` (ICT's "sclera" range: the whole
    eye surface, cornea included; ICT's "iris" range is an inner eyeball behind it). The
    vertices standing more than CORNEA_RISE_M proud of the shell's robust sphere fit within 45
    degrees of -Y give the optical axis (their mean direction) and the limbus (their largest
    angle from it); the cap is every shell vertex within that angle. Returns sorted indices."""
    shell = np.asarray(shell, np.int64)
    c, r, _ = mu.fit_sphere_robust(v[shell])
    q = v[shell] - c
    d = np.linalg.norm(q, axis=1)
    u = q / d[:, None]
    raised = (d > r + CORNEA_RISE_M) & (-u[:, 1] > np.cos(np.radians(45.0)))
    if not raised.any():
        return np.zeros(0, np.int64)
    axis = u[raised].mean(0)
    axis /= np.linalg.norm(axis)
    cos_limbus = float((u[raised] @ axis).min())
    return np.sort(shell[u @ axis >= cos_limbus - 1e-9])


@dataclass
class JointRule:
    """Everything needed to recompute the joints on a deformed copy of the template."""

    sclera_keep: dict  # side -> (index array) vertices used for the eye sphere fit
    jaw_rest: np.ndarray  # (3,) pivot on the template (from jawOpen)
    jaw_anchors: np.ndarray  # skin vertices whose mean displacement moves the jaw pivot
    ear_sides: list  # index arrays of the left and right ear
    ear_top: np.ndarray  # per side, the highest / lowest ear vertex
    ear_bottom: np.ndarray
    neck_slab: np.ndarray  # skin vertices of the slice at the neck base
    neck_front: int
    neck_back: int
    swap_eyes: bool = False

    def joints(self, v: np.ndarray, template: np.ndarray) -> np.ndarray:
        """(5, 3) joints of the vertices ``v`` (same topology as ``template``)."""
        v = np.asarray(v, np.float64)
        out = np.zeros((5, 3))
        s = v[self.neck_slab]
        out[0] = [s[:, 0].mean(), 0.5 * (v[self.neck_front, 1] + v[self.neck_back, 1]), s[:, 2].mean()]
        centre = np.mean([v[ids].mean(0) for ids in self.ear_sides], axis=0)  # mean of the two ear centroids
        height = v[self.ear_top, 2].mean() - v[self.ear_bottom, 2].mean()
        out[1] = centre - [0.0, 0.0, height / 3.0]
        out[2] = self.jaw_rest + (v[self.jaw_anchors] - template[self.jaw_anchors]).mean(0)
        for j, side in ((3, "l"), (4, "r")):
            ids = self.sclera_keep[side]
            out[j] = mu.fit_sphere(v[ids])[0]
        if self.swap_eyes:
            out[[3, 4]] = out[[4, 3]]
        return out


def find_ears(v: np.ndarray, tris: np.ndarray, edges: np.ndarray, tri_uv: np.ndarray | None,
              lm: np.ndarray) -> np.ndarray:
    """Both ears: the two large connected pieces of the index block after the narrow face
    area, plus the small UV islands of the skin next to them (the backs of the helices).
    Falls back to the generic ray-cast rule if that does not give one ear per side."""
    n = len(v)
    block = rng(EAR_BLOCK)
    lab = mu.connected_components(edges, n, block)
    sizes = np.bincount(lab[block])
    big = np.argsort(sizes)[::-1][:2]
    ears = [block[lab[block] == b] for b in big]
    if len(ears) == 2 and sizes[big].min() > 100 and np.sign(v[ears[0], 0].mean()) != np.sign(v[ears[1], 0].mean()):
        out = np.concatenate(ears)
        if tri_uv is not None:
            skin_tri = (tris < SKIN[1]).all(1)
            uvlab = mu.connected_components(mu.triangle_edges(tri_uv[skin_tri]), int(tri_uv.max()) + 1)
            isl = uvlab[tri_uv[skin_tri][:, 0]]
            st = tris[skin_tri]
            for i in np.unique(isl):
                vs = np.unique(st[isl == i])
                if len(vs) >= 200:
                    continue
                c = v[vs].mean(0)
                if min(np.linalg.norm(c - v[e].mean(0)) for e in ears) < 0.02:
                    out = np.union1d(out, vs)
        return np.sort(out)
    return rg.ear_flaps(v, tris, rng(SKIN), lm)


def neck_base(v: np.ndarray, skin: np.ndarray, menton_z: float) -> tuple[np.ndarray, int, int]:
    """Slice of the skin at the neck base: going down from the narrowest neck slice, the
    first level where the half-width exceeds 1.25 x the narrowest."""
    sv = v[skin]
    zs = np.arange(menton_z, sv[:, 2].min(), -0.002)
    width = np.array([np.abs(sv[np.abs(sv[:, 2] - z) < 0.003, 0]).max(initial=0.0) for z in zs])
    ok = width > 0
    zs, width = zs[ok], width[ok]
    k = int(np.argmin(width))
    lim = 1.25 * width[k]
    base = k
    while base + 1 < len(zs) and width[base + 1] <= lim:
        base += 1
    z = zs[base]
    sel = (np.abs(sv[:, 2] - z) < 0.004) & (np.abs(sv[:, 0]) <= lim)
    slab = skin[sel]
    return slab, int(slab[np.argmin(v[slab, 1])]), int(slab[np.argmax(v[slab, 1])])


def jaw_pivot(v: np.ndarray, jaw_open: np.ndarray | None,
              an: rg.Anatomy) -> tuple[np.ndarray, float, np.ndarray | None]:
    """Pivot (on x = 0) of the rigid motion of the lower teeth from neutral to jawOpen, its
    angle (radians about +X) and the motion (R, t); an anatomical estimate without jawOpen."""
    if jaw_open is not None:
        low = rng(TEETH_LOWER)
        R, t = fit_rigid(v[low], jaw_open[low])
        try:
            c, n, _ = rotation_pivot(R, t, 0)
            ang = float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))) * float(np.sign(n[0]) or 1.0)
            return c, ang, np.c_[R, t]
        except ValueError:
            pass
    c = np.array([0.0, an.ear_front_y + 0.09 * an.eye_dist, an.ear_centre[2] - 0.15 * an.eye_dist])
    return c, 0.0, None


def jaw_anchors(v: np.ndarray, pivot: np.ndarray, exclude: np.ndarray, k: int = 12) -> np.ndarray:
    """The ``k`` lateral skin vertices per side nearest (in the sagittal plane) to the pivot."""
    skin = np.setdiff1d(rng(SKIN), exclude)
    sv = v[skin]
    xmax = np.abs(sv[:, 0]).max()
    out = []
    for side in (1.0, -1.0):
        cand = skin[side * sv[:, 0] > 0.5 * xmax]
        d = np.linalg.norm(v[cand][:, 1:] - pivot[1:], axis=1)
        out.append(cand[np.argsort(d, kind="stable")[:k]])
    return np.concatenate(out)


def skin_weights(v: np.ndarray, jaw_open: np.ndarray | None, motion: np.ndarray | None, joints: np.ndarray,
                 an: rg.Anatomy, swap_eyes: bool) -> np.ndarray:
    """(V, 5) weights: eyeballs rigid to their eye joint; jaw = share of the jawOpen
    displacement explained by the fitted rigid jaw motion; the rest split head/neck by
    height between the neck base and the jaw line."""
    n = len(v)
    w = np.zeros((n, 5))
    jaw = np.zeros(n)
    if jaw_open is not None and motion is not None:
        r = v @ motion[:, :3].T + motion[:, 3] - v
        d = jaw_open - v
        jaw = np.clip(np.einsum("ij,ij->i", d, r) / (np.einsum("ij,ij->i", r, r) + 1e-6), 0.0, 1.0)
        jaw[jaw < 0.02] = 0.0
    z_neck = joints[0, 2]
    top = rg.jaw_line_height(v[:, 1], an)
    head = mu.smoothstep((v[:, 2] - z_neck) / np.maximum(top - z_neck, 1e-6))
    w[:, 2] = jaw
    w[:, 1] = (1 - jaw) * head
    w[:, 0] = (1 - jaw) * (1 - head)
    for j, side in ((3, "l"), (4, "r")):
        ids = rng(EYEBALL[side])
        w[ids] = 0.0
        w[ids, (7 - j) if swap_eyes else j] = 1.0
    return w
