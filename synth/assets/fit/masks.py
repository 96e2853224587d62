"""Per-vertex masks (numpy) from head regions and landmarks: the shader-layer rigs (makeup:
:func:`makeup_masks`, skin detail: :func:`skin_detail_mask`) and the body of fitted shells
use them.

All masks are floats in [0, 1] per head vertex, computed on the current vertices at build
time; they are attached to vertices, so they follow every later expression.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def region_mask(regions: dict, names, n: int) -> np.ndarray:
    """True on the ``n`` vertices of any of the named regions (absent regions: none)."""
    m = np.zeros(n, bool)
    for name in names:
        r = regions.get(name)
        if r is not None:
            m[np.asarray(r, np.int64)] = True
    return m


def distance_to(V: np.ndarray, pts: np.ndarray) -> np.ndarray:
    if len(pts) == 0:
        return np.full(len(V), np.inf)
    return cKDTree(pts).query(V)[0]


def feather(d: np.ndarray, inner: float, outer: float) -> np.ndarray:
    """1 within ``inner``, smooth falloff to 0 at ``outer``."""
    t = np.clip((d - inner) / max(outer - inner, 1e-9), 0.0, 1.0)
    return 1.0 - t * t * (3 - 2 * t)


def segment_distance(V, a, b):
    ab = b - a
    t = np.clip(((V - a) @ ab) / max(ab @ ab, 1e-12), 0, 1)
    return np.linalg.norm(V - (a + t[:, None] * ab), axis=1)


def skin_only(data, n):
    """Vertices that are skin (not eyes, teeth, mouth interior)."""
    return ~region_mask(data.regions, ("eyes", "teeth", "mouth_interior"), n)


def makeup_masks(data, V: np.ndarray, lm: np.ndarray, extent: float = 0.6, liner: float = 0.6,
                 wing: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The makeup rig's two point-colour attributes: (V, 4) [lips, eyeshadow, eyeliner, blush]
    and (V, 4) [foundation, eyeliner wing, 0, 0], from the lips region (else the ibug68 lip
    contour), the eye landmarks (shadow above the upper lid, liner along the lash line, wing
    at the outer corner) and the cheeks (blush). ``extent`` and ``liner`` (0..1) widen the
    shadow and thicken the liner."""
    n = len(V)
    skin = skin_only(data, n).astype(float)
    lips_idx = data.regions.get("lips")
    lips_pts = V[np.asarray(lips_idx)] if lips_idx is not None else V[0:0]
    if len(lips_pts) == 0:  # fall back to the landmark lip contour
        lips_pts = lm[48:60]
    lips = feather(distance_to(V, lips_pts), 0.0005, 0.0025) * skin
    shadow = np.zeros(n)
    eyeliner = np.zeros(n)
    wingm = np.zeros(n)
    blush = np.zeros(n)
    for sl, outer_i, sign in ((slice(36, 42), 36, -1.0), (slice(42, 48), 45, 1.0)):
        eye = lm[sl]
        c = eye.mean(0)
        half_w = 0.5 * np.linalg.norm(eye[0] - eye[3])
        upper = eye[1:3]  # upper lid points
        z_lid = upper[:, 2].mean()
        dx = np.abs(V[:, 0] - c[0]) / (half_w * (1.15 + 0.3 * extent))
        dz = (V[:, 2] - z_lid) / (0.006 + 0.008 * extent)
        front = V[:, 1] < c[1] + 0.012
        shadow = np.maximum(shadow, feather(dx, 0.6, 1.0) * np.clip(dz * 4, 0, 1) * feather(dz, 0.5, 1.0) * front)
        # eyeliner: along the upper lash line (upper lid landmarks + corners)
        line = np.concatenate([eye[[0, 1, 2, 3]]])
        dl = np.min([segment_distance(V, line[i], line[i + 1]) for i in range(3)], axis=0)
        eyeliner = np.maximum(eyeliner, feather(dl, 0.0004 + 0.0008 * liner, 0.0012 + 0.0012 * liner)
                              * (V[:, 2] > z_lid - 0.0025) * front)
        if wing:
            corner = lm[outer_i]
            tip = corner + np.array([sign * 0.007, 0.002, 0.0035])
            wingm = np.maximum(wingm, feather(segment_distance(V, corner, tip), 0.0005 * (1 + liner), 0.0015)
                               * front)
        # blush: on the cheek apple, below and outside the eye
        cheek = c + np.array([sign * 0.008, -0.002, -0.03])
        blush = np.maximum(blush, feather(np.linalg.norm(V - cheek, axis=1), 0.006, 0.022))
    shadow *= skin * (1 - lips)
    eyeliner = np.maximum(eyeliner, wingm) * skin
    blush *= skin * (1 - lips)
    face = region_mask(data.regions, ("face",), n).astype(float)
    face = np.maximum(face, feather(distance_to(V, V[face > 0]), 0.0, 0.01)) if face.any() else np.ones(n)
    m1 = np.stack([lips, shadow, eyeliner, blush], 1)
    m2 = np.stack([face * skin, wingm, np.zeros(n), np.zeros(n)], 1)
    return np.clip(m1, 0, 1), np.clip(m2, 0, 1)


def skin_detail_mask(data, V, lm) -> np.ndarray:
    """The skin-detail rig's point-colour attribute (V, 4): R cheeks and nose, G T-zone,
    B wrinkle zones (forehead, crow's feet), A beard area; zero off the skin."""
    n = len(V)
    skin = skin_only(data, n).astype(float)
    nose_tip, c_l, c_r = lm[30], lm[42:48].mean(0), lm[36:42].mean(0)
    cheeks = np.maximum.reduce([feather(np.linalg.norm(V - (c + [0, -0.003, -0.025]), axis=1), 0.008, 0.025)
                                for c in (c_l, c_r)] + [feather(np.linalg.norm(V - nose_tip, axis=1), 0.006, 0.02)])
    brow_c = 0.5 * (lm[19] + lm[24])
    tz = np.maximum(feather(np.abs(V[:, 0] - nose_tip[0]), 0.008, 0.02) * (V[:, 2] > nose_tip[2] - 0.01)
                    * (V[:, 2] < brow_c[2] + 0.05), feather(np.linalg.norm(V - lm[8], axis=1), 0.01, 0.025))
    forehead = ((V[:, 2] > brow_c[2] + 0.012) * feather(np.abs(V[:, 0] - brow_c[0]), 0.035, 0.055)
                * (V[:, 1] < brow_c[1] + 0.03))
    crows = np.maximum(feather(np.linalg.norm(V - (lm[45] + [0.01, 0.004, 0]), axis=1), 0.002, 0.012),
                       feather(np.linalg.norm(V - (lm[36] + [-0.01, 0.004, 0]), axis=1), 0.002, 0.012))
    wr = np.maximum(forehead, crows)
    beard = soft_region(V, region_mask(data.regions, ("beard",), n), BEARD_FEATHER_M)
    beard = beard * ~region_mask(data.regions, ("lips",), n)  # the stubble stops at the lips' edge
    m = np.stack([cheeks, tz, wr, beard], 1) * skin[:, None]
    return np.clip(m, 0, 1)


#: Gaussian width (metres) over which the skin-detail beard area fades out: the region is a
#: set of vertices 7-11 mm apart, and as a hard 0/1 mask the stubble shadow ended in the
#: triangles' staircase
BEARD_FEATHER_M = 0.008


def soft_region(V: np.ndarray, inside: np.ndarray, sigma: float) -> np.ndarray:
    """(V,) a 0/1 vertex set smoothed in space: the Gaussian-weighted (width ``sigma``) share of
    region vertices among the vertices within 2.5 sigma, rescaled (``(share - 0.05) / 0.75``,
    clipped) so that a vertex with mostly region vertices around it is 1; 0 further than
    2.5 sigma outside. It falls along a smoothed version of the region's boundary over a few
    rows of vertices, whatever the triangles' layout."""
    inside = np.asarray(inside, bool)
    out = inside.astype(np.float64)
    if not inside.any() or sigma <= 0:
        return out
    tree = cKDTree(V)
    near = np.flatnonzero(cKDTree(V[inside]).query(V, distance_upper_bound=2.5 * sigma)[0] < np.inf)
    for i, nb in zip(near, tree.query_ball_point(V[near], 2.5 * sigma)):
        nb = np.asarray(nb)
        k = np.exp(-0.5 * (np.linalg.norm(V[nb] - V[i], axis=1) / sigma) ** 2)
        out[i] = float((k * inside[nb]).sum() / k.sum())
    # rescaled so that the interior (its 5th percentile has 0.8 at 8 mm) keeps 1: on the beard
    # the value then runs 0, ~0.2, ~0.55, 1 over the last rows of vertices out and in
    return np.clip((out - 0.05) / 0.75, 0.0, 1.0)
