"""Per-vertex masks (numpy) from head regions and landmarks: the shader-layer rigs (makeup:
:func:`makeup_masks`, skin detail: :func:`skin_detail_mask`) and the body of fitted shells
use them.

All masks are floats in [0, 1] per head vertex, computed on the current vertices at build
time; they are attached to vertices, so they follow every later expression.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from synth.assets.params import DEFAULT_REACH
from synth.model.meshutil import smoothstep


#: the jaw line the assets fit to starts this far below the lateral canthi, in canthus-to-chin heights
JAW_LINE_TOP = 0.15


def jaw_line(lm: np.ndarray) -> np.ndarray:
    """(17, 3) the jaw line that beards, collars and hoods fit to, in ibug68's jaw order: the jaw
    contour (ibug68 0-16) from ``JAW_LINE_TOP`` canthus-to-chin heights below the lateral canthi
    (36 / 45) down to the chin (8), each half resampled to 9 points evenly spaced in arc length
    (where the contour starts lower, from 0 / 16 themselves). 300-W's jaw points start at the
    canthi's height, beside the eyes; these rules mean the lower line, where the default model's
    beard region ends (its ``region_jaw_line``: the same height)."""
    from synth.assets.fit.strands import resample_fast

    lm = np.asarray(lm, np.float64)
    out = np.empty((17, 3))
    for ids, canthus in ((range(0, 9), 36), (range(16, 7, -1), 45)):
        P = lm[list(ids)]
        z_top = lm[canthus, 2] - JAW_LINE_TOP * (lm[canthus, 2] - lm[8, 2])
        k = int(np.argmax(P[:, 2] <= z_top)) if np.any(P[:, 2] <= z_top) else len(P) - 1
        if k > 0:
            a = (P[k - 1, 2] - z_top) / max(P[k - 1, 2] - P[k, 2], 1e-12)
            P = np.concatenate([(P[k - 1] + a * (P[k] - P[k - 1]))[None], P[k:]])
        half = resample_fast(P[None], np.array([np.inf]), 9)[0]
        out[list(ids)] = half
    return out


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
    return 1.0 - smoothstep(d, inner, inner + max(outer - inner, 1e-9))


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
        if wing:  # the envelope of the wing; the line itself is drawn in the shader (wing_coordinates)
            corner = lm[outer_i]
            tip = corner + np.array([sign, 1.0, 1.0]) * WING_TIP_M
            wingm = np.maximum(wingm, feather(segment_distance(V, corner, tip), WING_ENVELOPE_M[0],
                                              WING_ENVELOPE_M[1]) * front)
        # blush: on the cheek apple, below and outside the eye
        cheek = c + np.array([sign * 0.008, -0.002, -0.03])
        blush = np.maximum(blush, feather(np.linalg.norm(V - cheek, axis=1), 0.006, 0.022))
    shadow *= skin * (1 - lips)
    eyeliner = eyeliner * skin
    wingm = wingm * skin
    blush *= skin * (1 - lips)
    face = region_mask(data.regions, ("face",), n).astype(float)
    face = np.maximum(face, feather(distance_to(V, V[face > 0]), 0.0, 0.01)) if face.any() else np.ones(n)
    m1 = np.stack([lips, shadow, eyeliner, blush], 1)
    m2 = np.stack([face * skin, wingm, np.zeros(n), np.zeros(n)], 1)
    return np.clip(m1, 0, 1), np.clip(m2, 0, 1)


#: an eyeliner wing runs from the outer eye corner this far out (x, away from the nose), back (y)
#: and up (z), metres
WING_TIP_M = np.array([0.007, 0.002, 0.0035])
#: the wing's envelope (makeup_masks' second attribute, channel 1): 1 within the first distance of
#: the wing's segment, 0 beyond the second (m). The line itself is drawn per shading point
#: (:func:`wing_line`): drawn per vertex (2 mm apart at the eye corner, 6 mm further out), a
#: 1-2 mm wide line came out as blobs, a dark dot at its tip. At (3, 5) mm the envelope,
#: interpolated over the skin's triangles at the widened lids' outer corner (up to 5.7 mm across),
#: falls to 0.63 on the wing's first millimetres.
WING_ENVELOPE_M = (0.0045, 0.0065)


def wing_coordinates(V: np.ndarray, lm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) per eye (right: ibug 36, left: 45): (u, v, 0) with u the position along the wing
    (0 at the eye corner, 1 at its tip) and v the signed distance from its axis across it (m,
    perpendicular to the wing and to the view from the front). Both are affine in the position,
    so their linear interpolation over a triangle is exact at every shading point."""
    V = np.asarray(V, np.float64)
    out = []
    for outer_i, sign in ((36, -1.0), (45, 1.0)):
        corner = np.asarray(lm[outer_i], np.float64)
        t = np.array([sign, 1.0, 1.0]) * WING_TIP_M
        L = float(np.linalg.norm(t))
        t = t / L
        b = np.cross(np.array([0.0, -1.0, 0.0]), t)
        b /= np.linalg.norm(b)
        rel = V - corner
        out.append(np.stack([rel @ t / L, rel @ b, np.zeros(len(V))], 1))
    return out[0], out[1]


def wing_width(liner: float) -> float:
    """Half width (m) of the wing at the eye corner; it tapers to a quarter at the tip."""
    return 0.0004 + 0.0006 * float(liner)


#: the wing's edge: its coverage falls from 1 to 0 over this distance (m)
WING_EDGE_M = 0.0002


def wing_line(u, v, liner: float):
    """The wing's coverage from :func:`wing_coordinates` (numpy; the makeup rig builds the same
    formula from shader nodes): 1 within the tapering half width of the segment, 0 beyond it
    plus :data:`WING_EDGE_M`."""
    L = float(np.linalg.norm(WING_TIP_M))
    along = np.maximum(np.maximum(-u, u - 1.0), 0.0) * L
    d = np.sqrt(along * along + v * v)
    hw = wing_width(liner) * (1.0 - 0.75 * np.clip(u, 0.0, 1.0))
    return np.clip((hw + WING_EDGE_M - d) / WING_EDGE_M, 0.0, 1.0)


def skin_detail_mask(data, V, lm, reach: float = DEFAULT_REACH) -> np.ndarray:
    """The skin-detail rig's point-colour attribute (V, 4): R cheeks and nose, G T-zone,
    B wrinkle zones (forehead, crow's feet), A beard area (the beard region under the cheek
    line of ``reach``, :func:`cheek_line`: the beard pick's, or
    :data:`synth.assets.params.DEFAULT_REACH` without a beard); zero off the skin."""
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
    beard = beard_area(data, V) * below_cheek_line(V, lm, reach)
    m = np.stack([cheeks, tz, wr, beard], 1) * skin[:, None]
    return np.clip(m, 0, 1)


#: the under-eye area (periorbital darkening, the tear trough): an ellipse on the face's plane
#: centred this far below the lower lid's middle (metres), its half-width this share of the eye's
#: width, its half-height UNDER_EYE_HALF_HEIGHT_M; full strength inside half of it, none past
#: UNDER_EYE_OUTER of it
UNDER_EYE_DROP_M = 0.006
UNDER_EYE_HALF_WIDTH = 0.55
UNDER_EYE_HALF_HEIGHT_M = 0.009
UNDER_EYE_OUTER = 1.4


def under_eye_area(V: np.ndarray, lm: np.ndarray) -> np.ndarray:
    """(V,) the darker skin under each eye, 0 .. 1 (before :func:`skin_only`): an ellipse in
    the x-z plane below the lower lid (ibug68 41/40 and 47/46 its middle, the corners 36/39 and
    42/45 the eye's width), shifted a fifth of the eye's width toward the nose (the tear trough
    is deepest medially), and nothing above the lower lid's line; every edge of it a smooth fade."""
    V = np.asarray(V, np.float64)
    out = np.zeros(len(V))
    for lower, (c0, c1) in (((40, 41), (36, 39)), ((46, 47), (42, 45))):
        lid = lm[list(lower)].mean(0)
        width = float(np.linalg.norm(lm[c1] - lm[c0]))
        medial = np.sign(float(lm[27][0] - lid[0])) * 0.2 * width  # toward the nose bridge
        cx, cz = lid[0] + medial, lid[2] - UNDER_EYE_DROP_M
        d = np.hypot((V[:, 0] - cx) / (UNDER_EYE_HALF_WIDTH * width), (V[:, 2] - cz) / UNDER_EYE_HALF_HEIGHT_M)
        # the face's side of the head (the face looks along -y): full to 2 cm behind the lid, none
        # past 4 cm (the ellipse is a cylinder along y: it would reach the back of the scalp)
        front = np.clip((lid[1] + 0.04 - V[:, 1]) / 0.02, 0.0, 1.0)
        below = np.clip((lid[2] - V[:, 2]) / 0.002, 0.0, 1.0)  # faded in over 2 mm under the lid line
        out = np.maximum(out, feather(d, 0.5, UNDER_EYE_OUTER) * below * front)
    return out


def skin_tint_mask(data, V, lm) -> np.ndarray:
    """The skin-detail rig's second attribute (V, 3): X the under-eye area (:func:`under_eye_area`),
    Y the ears (the ``ears`` region where the model has one, feathered 4 mm into the skin around
    it), Z 0; zero off the skin and in the eye sockets' hidden lining."""
    n = len(V)
    skin = (skin_only(data, n) & ~region_mask(data.regions, ("eye_socket",), n)).astype(float)
    ears = region_mask(data.regions, ("ears", "ear_l", "ear_r"), n)
    ear = soft_region(V, ears, 0.004) if ears.any() else np.zeros(n)
    m = np.stack([under_eye_area(V, lm), ear, np.zeros(n)], 1) * skin[:, None]
    return np.clip(m, 0, 1)


#: Gaussian width (metres) over which the skin-detail beard area fades out: the region is a
#: set of vertices 7-11 mm apart, and as a hard 0/1 mask the stubble shadow ended in the
#: triangles' staircase
BEARD_FEATHER_M = 0.008


#: the regions a beard meets without fading: hair grows up to the lips' and the nostrils' edge
#: (faded there too, the 8 mm feather left the upper lip and the skin under the lower lip bare)
BEARD_HARD_EDGES = ("lips", "mouth_interior", "teeth", "nose")


def beard_area(data, V: np.ndarray) -> np.ndarray:
    """(V,) the beard region smoothed (:func:`soft_region`, :data:`BEARD_FEATHER_M`) where it
    meets the rest of the skin, not where it meets :data:`BEARD_HARD_EDGES`; 0 on those."""
    n = len(V)
    inside = region_mask(data.regions, ("beard",), n)
    hard = region_mask(data.regions, BEARD_HARD_EDGES, n)
    a = soft_region(V, inside | hard, BEARD_FEATHER_M)
    near = distance_to(V, V[inside]) < 2.5 * BEARD_FEATHER_M if inside.any() else np.zeros(n, bool)
    return a * near * ~hard


def hair_grows(P: np.ndarray, hf: dict, recession: float) -> np.ndarray:
    """(N,) bool: whether scalp hair grows at points ``P`` (on the scalp) for a hairline receding
    by ``recession`` (0 none, 1 far): the hair groom's root rule (``synth.assets.fit.hair``),
    given the head frame ``hf`` (``synth.assets.fit.groom.head_frame``). The recession bares the
    front of the scalp above the brows, more at the temples than in the middle."""
    P = np.asarray(P, np.float64)
    lo, hi, c = hf["scalp_lo"], hf["scalp_hi"], hf["centre"]
    u = (P[:, 1] - lo[1]) / max(hi[1] - lo[1], 1e-6)  # 0 at the front hairline, 1 at the back
    thr = recession * (0.22 + 0.35 * (np.abs(P[:, 0] - c[0]) / 0.06) ** 2)
    return ~((u < thr) & (P[:, 2] > hf["brow_z"] + 0.02))


#: width (metres) over which the scalp shadow fades out at the hairline
SCALP_FEATHER_M = 0.006


def scalp_hair_area(data, V: np.ndarray, hf: dict, recession: float) -> np.ndarray:
    """(V,) where scalp hair grows (the ``scalp`` region, less a receding hairline:
    :func:`hair_grows`), faded over :data:`SCALP_FEATHER_M` at its edge (:func:`soft_region`,
    squared): the skin-detail rig's scalp shadow."""
    V = np.asarray(V, np.float64)
    inside = region_mask(data.regions, ("scalp",), len(V)) & hair_grows(V, hf, recession)
    # squared: the fade of soft_region straddles the region's edge; squared, the skin just
    # outside the hairline (the forehead's top row) keeps at most about a seventh of the shadow
    return soft_region(V, inside, SCALP_FEATHER_M) ** 2 * skin_only(data, len(V))


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


#: how far above a beard's cheek line its roots fade out (metres)
CHEEK_FADE_M = 0.005
#: the sideburn's width: the cheek line meets the sideburn this far inside the jaw line's top (metres)
SIDEBURN_WIDTH_M = 0.012


def cheek_line(lm: np.ndarray, reach: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The upper edge of beard growth in (|x - face centre|, z), from the ibug68 points ``lm``:
    the upper lip up to the subnasale, the moustache's outer end beside the mouth corner, the
    cheek, and the sideburn's front edge up to the top of the jaw line (:func:`jaw_line`) at the ear.

    ``reach`` (0..1) is how high the line runs over the cheek: at 1 it follows the model's beard
    region edge (from the nostril's wing straight to the jaw line's top, across the cheekbone); at 0
    the moustache keeps the nostrils' height out to the mouth corner, and the line rises from
    6 mm above the corner, 6 mm further out, to the jaw line's point 2 below the sideburn, where most men's
    cheek line runs. Returns the polyline's |x| (increasing) and z."""
    lm = np.asarray(lm, np.float64)
    jaw = jaw_line(lm)
    r = float(np.clip(reach, 0.0, 1.0))
    x31 = 0.5 * abs(lm[35, 0] - lm[31, 0])
    x0, z0 = 0.5 * abs(jaw[16, 0] - jaw[0, 0]), 0.5 * (jaw[0, 2] + jaw[16, 2])
    z33, z31 = lm[33, 2], 0.5 * (lm[31, 2] + lm[35, 2])
    high = lambda x: np.interp(x, [0.0, x31, x0], [z33, z31, z0])  # noqa: E731 (the region's own line)
    half_w = 0.5 * abs(lm[54, 0] - lm[48, 0])
    xm = max(half_w, x31 + 0.002)  # the moustache keeps its height out to the mouth corner
    xa = xm + 0.006
    xb = max(x0 - SIDEBURN_WIDTH_M, xa + 0.005)
    za_low = min(0.5 * (lm[48, 2] + lm[54, 2]) + 0.006, z31)
    zb_low = min(0.5 * (jaw[2, 2] + jaw[14, 2]), float(high(xb)))
    zm = (1 - r) * min(z31, float(high(xm))) + r * float(high(xm))
    za = (1 - r) * za_low + r * float(high(xa))
    zb = (1 - r) * zb_low + r * float(high(xb))
    return np.array([0.0, x31, xm, xa, xb, max(x0, xb + 0.005)]), np.array([z33, z31, zm, za, zb, z0])


def below_cheek_line(P: np.ndarray, lm: np.ndarray, reach: float = 1.0, fade: float = CHEEK_FADE_M) -> np.ndarray:
    """(N,) weight of the points ``P`` under the cheek line (:func:`cheek_line`): 1 below it,
    falling smoothly to 0 at ``fade`` metres above it; beyond the jaw line's top it stays at its
    height."""
    P = np.asarray(P, np.float64)
    lm = np.asarray(lm, np.float64)
    xs, zs = cheek_line(lm, reach)
    jaw = jaw_line(lm)
    xc = 0.5 * (jaw[0, 0] + jaw[16, 0])
    z_line = np.interp(np.abs(P[:, 0] - xc), xs, zs)
    return feather(P[:, 2] - z_line, 0.0, max(fade, 1e-6))
