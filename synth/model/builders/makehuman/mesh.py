"""The model mesh: the hm08 base mesh cropped to head, neck and upper shoulders, the mouth and
eyelash helpers kept, the low-poly eye helpers replaced by UV-sphere eyeballs; and its
triangulation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.errors import SynthError
from synth.model.builders.makehuman.sources import BaseObj

CROP_MIN_Z = 0.45  # metres, on the base mesh: keep body polygons entirely above this ...
CROP_MAX_ABS_X = 0.19  # ... and entirely within |x| < this (cuts the arms at the shoulder)
KEPT_HELPERS = ("helper-upper-teeth", "helper-lower-teeth", "helper-tongue",
                "helper-l-eyelashes-1", "helper-l-eyelashes-2", "helper-r-eyelashes-1", "helper-r-eyelashes-2")
# eyeball: rings at these polar angles (degrees from the gaze axis), N_AZIMUTH vertices each
EYE_RING_DEG = (3.0, 6.5, 10.0, 14.0, 18.0, 21.5, 25.0, 31.0, 40.0, 52.0, 66.0, 82.0, 100.0, 122.0, 150.0)
EYE_N_AZIMUTH = 32
EYE_PUPIL_DEG = 6.5  # pupil edge
EYE_LIMBUS_DEG = 21.5  # iris edge (iris diameter ~11 mm on the 15 mm MakeHuman eyeball)
EYE_CORNEA_BULGE = 0.08  # cornea apex height above the sclera sphere, fraction of the radius


def uv_sphere_eye(center: np.ndarray, radius: float):
    """Left-eye eyeball around ``center`` looking toward -Y. Returns verts (n,3), polys, poly uvs
    (lists of arrays of indices into the returned uv array), uvs (m,2), polar angle per vertex."""
    th = np.deg2rad(np.array(EYE_RING_DEG))
    n = EYE_N_AZIMUTH
    phi = 2 * np.pi * np.arange(n) / n
    lim = np.deg2rad(EYE_LIMBUS_DEG)

    def rad(t):
        bump = np.where(t < lim, (1.0 - (t / lim) ** 2) ** 2, 0.0)
        return radius * (1.0 + EYE_CORNEA_BULGE * bump)

    def uvrad(t):
        return np.where(t <= lim, 0.25 * t / lim, 0.25 + 0.25 * (t - lim) / (np.pi - lim))

    theta = np.concatenate([[0.0], np.repeat(th, n), [np.pi]])
    ph = np.concatenate([[0.0], np.tile(phi, len(th)), [0.0]])
    d = np.stack([np.sin(theta) * np.cos(ph), -np.cos(theta), np.sin(theta) * np.sin(ph)], 1)
    verts = center + d * rad(theta)[:, None]
    uv_v = np.stack([0.5 + uvrad(theta) * np.cos(ph), 0.5 + uvrad(theta) * np.sin(ph)], 1)
    back = len(theta) - 1

    def ring(i, j):
        return 1 + i * n + (j % n)

    polys, puv = [], []
    extra_uv = []
    for j in range(n):
        polys.append([0, ring(0, j), ring(0, j + 1)])
        puv.append(list(polys[-1]))
    for i in range(len(th) - 1):
        for j in range(n):
            q = [ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)]
            polys.append(q)
            puv.append(list(q))
    for j in range(n):
        polys.append([ring(len(th) - 1, j), back, ring(len(th) - 1, j + 1)])
        a = 2 * np.pi * (j + 0.5) / n
        extra_uv.append([0.5 + 0.5 * np.cos(a), 0.5 + 0.5 * np.sin(a)])
        puv.append([ring(len(th) - 1, j), len(theta) + j, ring(len(th) - 1, j + 1)])
    uvs = np.concatenate([uv_v, np.array(extra_uv)])
    # orient outward
    a, b, c = verts[polys[n + 1][:3]]
    if np.dot(np.cross(b - a, c - a), a - center) < 0:
        polys = [p[::-1] for p in polys]
        puv = [p[::-1] for p in puv]
    return verts, [np.array(p) for p in polys], [np.array(p) for p in puv], uvs, theta


@dataclass
class Mesh:
    base: np.ndarray  # (V, 3) base-mesh positions of the model vertices
    kept: np.ndarray  # (Vk,) hm08 indices of the first Vk model vertices
    polys: list[np.ndarray]
    poly_uvs: list[np.ndarray]
    uvs: np.ndarray
    mirror: np.ndarray  # (V,) model index of each vertex's mirror image
    eye_slices: dict[str, slice]  # "eye_l"/"eye_r" -> model vertex range
    eye_theta: np.ndarray  # polar angle of each eyeball vertex (same for both eyes)
    eye_center: dict[str, np.ndarray]
    eye_radius: float
    helper_rows: dict[str, np.ndarray]  # group name -> model indices (helpers kept)
    lookup: np.ndarray  # hm08 index -> model index (or -1)


def build_mesh(obj: BaseObj, groups: dict[str, np.ndarray], mirror_hm: np.ndarray) -> Mesh:
    P = obj.verts
    keep = []
    for i, (p, g) in enumerate(zip(obj.polys, obj.groups)):
        if g == "body":
            if np.all(P[p, 2] > CROP_MIN_Z) and np.all(np.abs(P[p, 0]) < CROP_MAX_ABS_X):
                keep.append(i)
        elif g in KEPT_HELPERS:
            keep.append(i)
    kept = np.unique(np.concatenate([obj.polys[i] for i in keep]))
    lookup = np.full(len(P), -1, np.int64)
    lookup[kept] = np.arange(len(kept))
    if np.any(lookup[mirror_hm[kept]] < 0):
        raise SynthError("the crop is not mirror-symmetric", "makehuman builder", "report this as a bug")
    used_uv = np.unique(np.concatenate([obj.poly_uvs[i] for i in keep]))
    uv_lookup = np.full(len(obj.uvs), -1, np.int64)
    uv_lookup[used_uv] = np.arange(len(used_uv))
    polys = [lookup[obj.polys[i]] for i in keep]
    puvs = [uv_lookup[obj.poly_uvs[i]] for i in keep]
    uvs = [obj.uvs[used_uv]]
    base = [P[kept]]
    mirror = [lookup[mirror_hm[kept]]]
    nv, nuv = len(kept), len(used_uv)
    # eyeballs: UV spheres fitted to the hm08 eye helpers (same centre, mean radius)
    hl = groups["helper-l-eye"]
    c_l = P[hl].mean(0)
    radius = float(np.linalg.norm(P[hl] - c_l, axis=1).mean())
    ev, ep, epuv, euv, theta = uv_sphere_eye(c_l, radius)
    ne = len(ev)
    slices = {}
    centers = {}
    for side in ("eye_l", "eye_r"):
        if side == "eye_l":
            v, pl, pu, uv = ev, ep, epuv, euv
        else:  # exact mirror image of the left eyeball, same vertex order, reversed winding
            v = ev * np.array([-1.0, 1.0, 1.0])
            pl = [p[::-1] for p in ep]
            pu = [p[::-1] for p in epuv]
            uv = np.stack([1.0 - euv[:, 0], euv[:, 1]], 1)
        slices[side] = slice(nv, nv + ne)
        centers[side] = c_l * (np.array([-1.0, 1.0, 1.0]) if side == "eye_r" else 1.0)
        base.append(v)
        polys += [p + nv for p in pl]
        puvs += [p + nuv for p in pu]
        uvs.append(uv)
        nv += ne
        nuv += len(uv)
    sl, sr = slices["eye_l"], slices["eye_r"]
    mirror.append(np.arange(sr.start, sr.stop))
    mirror.append(np.arange(sl.start, sl.stop))
    helper_rows = {g: lookup[groups[g]] for g in KEPT_HELPERS}
    return Mesh(np.concatenate(base), kept, polys, puvs, np.concatenate(uvs), np.concatenate(mirror),
                slices, theta, centers, radius, helper_rows, lookup)


#: quads whose diagonals differ in length by at most this (m) count as a tie. The UV-sphere eyeballs'
#: quads are isosceles trapezoids (diagonals equal up to rounding: at most 1.2e-16 m apart); the base
#: mesh's nearest non-tied quads differ by 74 nm, the next by 1.2 um. Rounding noise of the rest
#: shape (1e-9 m per coordinate moves a difference by about 2e-9 m) stays far from either side.
DIAGONAL_TIE_M = 3e-8


def split_diagonal(base: np.ndarray, quad: np.ndarray) -> int:
    """Which diagonal splits ``quad``: 0 for corners 0-2, 1 for corners 1-3. The shorter one on
    ``base``; within :data:`DIAGONAL_TIE_M` the one through the quad's lowest vertex index.
    Lengths are summed term by term (no BLAS call), so the decision is the same on every CPU,
    BLAS kernel and thread count."""
    d = base[quad[[1, 0]]] - base[quad[[3, 2]]]
    d13, d02 = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]).tolist()
    if abs(d13 - d02) <= DIAGONAL_TIE_M:
        return int(np.argmin(quad)) % 2
    return 1 if d13 < d02 else 0


def triangulate(base: np.ndarray, polys: list[np.ndarray], puvs: list[np.ndarray]):
    """Fan-split triangles and quads (quads along :func:`split_diagonal`)."""
    tris, tuv = [], []
    for p, u in zip(polys, puvs):
        if len(p) == 4 and split_diagonal(base, p):
            p, u = np.roll(p, -1), np.roll(u, -1)
        for k in range(1, len(p) - 1):
            tris.append((p[0], p[k], p[k + 1]))
            tuv.append((u[0], u[k], u[k + 1]))
    return np.array(tris, np.int64), np.array(tuv, np.int64)
