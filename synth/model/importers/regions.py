"""Landmark-driven region rules shared by the importers (see docs/importers.md).

A source model gives us a mesh, its skin vertices, its ears and 68 iBUG landmarks; the
rules below turn them into the semantic skin regions every synth model carries (face,
scalp, neck, brow, beard, lips) with plain, documented geometry. Axes are synth's:
metres, Z up, face toward -Y, +X the subject's left.

iBUG-68 indices used: 0/16 jaw contour top, 4/12 lower jaw contour, 8 menton,
17-21/22-26 brows, 27 nasion, 30 nose tip, 33 subnasale, 36/45 outer eye corners,
48/54 mouth corners, 48-59 outer lip contour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.geometry.raycast import ray_hit_counts
from synth.model import meshutil as mu

#: Names of the 68 iBUG / Multi-PIE points ("r"/"l" = the subject's right/left).
IBUG68_NAMES: list[str] = (
    [f"jaw_{i:02d}" for i in range(17)]
    + [f"brow_r_{i}" for i in range(5)] + [f"brow_l_{i}" for i in range(5)]
    + [f"nose_bridge_{i}" for i in range(4)] + [f"nose_base_{i}" for i in range(5)]
    + [f"eye_r_{i}" for i in range(6)] + [f"eye_l_{i}" for i in range(6)]
    + [f"lip_outer_{i:02d}" for i in range(12)] + [f"lip_inner_{i}" for i in range(8)]
)
assert len(IBUG68_NAMES) == 68


@dataclass
class Anatomy:
    """Reference points and heights derived from the landmarks (and the ears, if known)."""

    lm: np.ndarray  # (68, 3)
    eye_dist: float  # outer eye corner to outer eye corner
    menton: np.ndarray
    jaw_low: np.ndarray  # midpoint of landmarks 4 and 12 (lower jaw contour)
    subnasale: np.ndarray
    brow_z: float
    hairline_z: float
    mouth_half_width: float
    ear_front_y: float
    ear_centre: np.ndarray  # (3,) with x = mean |x|
    ear_top_z: float
    ear_bottom_z: float


def anatomy(vertices: np.ndarray, lm: np.ndarray, ears: np.ndarray | None = None) -> Anatomy:
    lm = np.asarray(lm, np.float64)
    v = np.asarray(vertices, np.float64)
    eye_dist = float(np.linalg.norm(lm[45] - lm[36]))
    brow_z = float(lm[17:27, 2].mean())
    sub = lm[33]
    if ears is not None and len(ears) >= 8:
        e = v[ears]
        front = float(np.mean([e[e[:, 0] > 0, 1].min(), e[e[:, 0] < 0, 1].min()])) if np.any(e[:, 0] > 0) and \
            np.any(e[:, 0] < 0) else float(e[:, 1].min())
        centre = np.array([np.abs(e[:, 0]).mean(), e[:, 1].mean(), e[:, 2].mean()])
        top, bottom = float(e[:, 2].max()), float(e[:, 2].min())
    else:  # no ears: typical proportions relative to the jaw contour top (landmarks 0/16)
        j = (lm[0] + lm[16]) / 2
        front = float(j[1] + 0.15 * eye_dist)
        centre = np.array([abs(lm[16, 0] - lm[0, 0]) / 2, front + 0.25 * eye_dist, float(j[2] - 0.35 * eye_dist)])
        top, bottom = float(centre[2] + 0.35 * eye_dist), float(centre[2] - 0.35 * eye_dist)
    return Anatomy(
        lm=lm, eye_dist=eye_dist, menton=lm[8], jaw_low=(lm[4] + lm[12]) / 2, subnasale=sub, brow_z=brow_z,
        hairline_z=brow_z + 0.8 * (brow_z - float(sub[2])), mouth_half_width=float(abs(lm[54, 0] - lm[48, 0]) / 2),
        ear_front_y=front, ear_centre=centre, ear_top_z=top, ear_bottom_z=bottom,
    )


def jaw_line_height(y: np.ndarray, an: Anatomy) -> np.ndarray:
    """Height of the jaw line above which skin belongs to the head: the line (in the
    sagittal plane) through the menton and the lower jaw contour, horizontal behind it."""
    (y0, z0), (y1, z1) = an.menton[1:], an.jaw_low[1:]
    slope = (z1 - z0) / (y1 - y0) if abs(y1 - y0) > 1e-9 else 0.0
    yy = np.minimum(np.asarray(y, np.float64), y1)
    return z0 + slope * (yy - y0)


def neck_mask(v: np.ndarray, an: Anatomy) -> np.ndarray:
    return v[:, 2] < jaw_line_height(v[:, 1], an)


def scalp_mask(v: np.ndarray, an: Anatomy) -> np.ndarray:
    """Above the hairline in front (the hairline drops linearly from ``hairline_z`` at the
    outer brows to the ear centre height at the front of the ears: temples, sideburns),
    or anywhere behind the ear centre."""
    y_b = float(an.lm[[17, 26], 1].mean())
    ramp = np.clip((v[:, 1] - y_b) / max(an.ear_front_y - y_b, 1e-6), 0.0, 1.0)
    z_hl = an.hairline_z + (an.ear_centre[2] - an.hairline_z) * ramp
    return (v[:, 2] > z_hl) | (v[:, 1] > an.ear_centre[1])


def lips_mask(v: np.ndarray, an: Anatomy) -> np.ndarray:
    """Inside the outer lip contour (48-59) seen from the front, in front of the mouth corners."""
    poly = an.lm[48:60][:, [0, 2]]
    y_corner = float(an.lm[[48, 54], 1].mean())
    return mu.point_in_polygon(v[:, [0, 2]], poly) & (v[:, 1] < y_corner + 0.05 * an.eye_dist)


def brow_mask(v: np.ndarray, an: Anatomy) -> np.ndarray:
    """Within 0.08 x eye distance of either brow polyline (17-21, 22-26)."""
    r = 0.08 * an.eye_dist
    d = np.full(len(v), np.inf)
    for ids in (range(17, 21), range(22, 26)):
        for i in ids:
            a, b = an.lm[i], an.lm[i + 1]
            ab = b - a
            t = np.clip((v - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
            d = np.minimum(d, np.linalg.norm(v - (a + t[:, None] * ab), axis=1))
    return d < r


def beard_mask(v: np.ndarray, an: Anatomy) -> np.ndarray:
    """Below the subnasale between the mouth corners; beyond them, below the cheek line from
    the mouth corner at subnasale height to the ear centre; in front of the ears; down to
    0.5 x (subnasale - menton) below the jaw line (the upper neck)."""
    ax = np.abs(v[:, 0])
    z_sub = float(an.subnasale[2])
    w = np.clip((ax - an.mouth_half_width) / max(an.ear_centre[0] - an.mouth_half_width, 1e-6), 0.0, 1.0)
    z_cheek = z_sub + (an.ear_centre[2] - z_sub) * w
    depth = 0.5 * (z_sub - float(an.menton[2]))
    return (v[:, 2] < z_cheek) & (v[:, 1] < an.ear_front_y) & (v[:, 2] > jaw_line_height(v[:, 1], an) - depth)


def skin_regions(vertices: np.ndarray, skin: np.ndarray, ears: np.ndarray, an: Anatomy) -> dict[str, np.ndarray]:
    """face / scalp / ears / neck partition the skin; brow, beard and lips are parts of face
    (beard also takes the upper neck). Returns sorted int32 index arrays."""
    v = np.asarray(vertices, np.float64)
    skin = np.asarray(skin, np.int64)
    n = len(v)
    is_ear = np.zeros(n, bool)
    is_ear[ears] = True
    sv = v[skin]
    neck = ~is_ear[skin] & neck_mask(sv, an)
    scalp = ~is_ear[skin] & ~neck & scalp_mask(sv, an)
    face = ~is_ear[skin] & ~neck & ~scalp
    lips = face & lips_mask(sv, an)
    brow = face & ~lips & brow_mask(sv, an)
    beard = (face | neck) & ~lips & beard_mask(sv, an)

    def ids(mask):
        return np.sort(skin[mask]).astype(np.int32)

    return {"face": ids(face), "scalp": ids(scalp), "ears": np.sort(np.asarray(ears, np.int64)).astype(np.int32),
            "neck": ids(neck), "lips": ids(lips), "brow": ids(brow), "beard": ids(beard)}


def ear_flaps(vertices: np.ndarray, triangles: np.ndarray, skin: np.ndarray, lm: np.ndarray) -> np.ndarray:
    """Generic ear finder for a skin mesh without ear labels (approximate).

    In a window behind each jaw contour top (landmark 0/16), the auricle is the part of the
    skin whose inward ray (toward the midsagittal plane, along X) crosses the skin again
    (the flap stands off the head); the ear is that flap plus the window vertices inside
    its outline (seen from the side) whose outward ray leaves the head freely (the concha),
    which excludes the scalp hidden behind the flap."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    skin = np.asarray(skin, np.int64)
    is_skin = np.zeros(len(v), bool)
    is_skin[skin] = True
    ts = t[is_skin[t].all(1)]
    de = float(np.linalg.norm(lm[45] - lm[36]))
    out = []
    for side, k in ((1.0, 16), (-1.0, 0)):
        ref = lm[k]
        sv = v[skin]
        win = ((side * sv[:, 0] > 0.5 * abs(ref[0])) & (sv[:, 1] > ref[1] - 0.1 * de) & (sv[:, 1] < ref[1] + 1.5 * de)
               & (sv[:, 2] > lm[33, 2] - 0.8 * de) & (sv[:, 2] < ref[2] + 0.6 * de))
        cand = skin[win]
        if len(cand) < 8:
            continue
        in_win = np.zeros(len(v), bool)
        in_win[cand] = True
        tw = ts[in_win[ts].all(1)]
        d = np.zeros((len(cand), 3))
        d[:, 0] = -side
        flap = ray_hit_counts(v[cand], d, v, tw) >= 1
        if flap.sum() < 8:
            continue
        hull = mu.convex_hull_2d(v[cand[flap]][:, 1:])
        inside = mu.point_in_polygon(v[cand][:, 1:], hull) & ~flap
        free = np.zeros(len(cand), bool)
        free[inside] = ray_hit_counts(v[cand[inside]], -d[inside], v, tw) == 0
        out.append(cand[flap | free])
    return np.sort(np.concatenate(out)) if out else np.zeros(0, np.int64)


def dense_landmarks(vertices: np.ndarray, triangles: np.ndarray, face: np.ndarray, start_vertex: int,
                    n: int = 600) -> tuple[np.ndarray, np.ndarray]:
    """``n`` face vertices by farthest-point sampling from ``start_vertex``, as one-hot
    barycentric landmarks on triangles containing them."""
    face = np.asarray(face, np.int64)
    pos = np.nonzero(face == start_vertex)[0]
    picks = face[mu.farthest_point_sampling(np.asarray(vertices)[face], n, int(pos[0]) if len(pos) else 0)]
    return mu.vertex_landmarks(triangles, picks)
