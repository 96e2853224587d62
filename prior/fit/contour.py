"""Jaw landmarks on the face's visible outline (the jaw line as people annotate it).

iBUG's 17 jaw points (ibug68 0-16) mark the *visible* outline of the face in the image. The
outline moves over the skin as the head turns: on the far side of a turned head it is the
cheek's silhouette, while a model's fixed jaw landmark stays on one spot of the skin, hidden
behind the cheek and drawn inside the face. :func:`visible_contour` moves each fixed contour
landmark's projection out, across the contour, to the outline of the face in front of it.

Each contour landmark has a *line* of surface points on the template, precomputed once per model
(:func:`contour_lines`): the template's skin cut by the plane through the fixed landmark ``p_j``
across the contour (normal to the contour's direction there, ``p_{j+1} - p_{j-1}``; horizontal
slices at the cheeks, a sagittal slice at the chin), sampled every ``step_deg`` by rays cast
inwards (the outermost skin hit) around the head's centre (the midpoint of the ears' centroids)
projected onto that plane, from ``p_j`` to ``inner_deg`` towards the face's front (the direction
from the head's centre to the nose tip). A line ends before an ear triangle, a miss or a gap.
Samples are (triangle, barycentric) surface points, as landmarks are, so they follow every
identity, expression and joint rotation.

For a posed head and a camera, with ``n_j`` the image normal of the projected fixed contour
(pointing out of the face) at landmark ``j``'s projection ``q_j``, the landmark is
``q_j + max(0, max_k (x_jk - q_j) . n_j) n_j`` over the projections ``x_jk`` of its line: moved
out to the farthest projection of the skin in front of it, and only across the contour. A
maximum of continuous functions, so no discrete choice is made; ``n_j``'s side comes from the sign
of the projected contour's area (a face-sized number), and a contour of under
:data:`MIN_AREA_PX2` (seen edge-on) is left as it is.

Along the outline, 300-W's jaw points are spaced evenly from the ear-level point (0, 16) to the
chin (8), as the outline shows in the image; a fixed point of the skin is not (seen from above,
from below or from the side, the skin's even spacing foreshortens unevenly).
:func:`spaced_evenly` keeps the anchors (:data:`IBUG68_JAW_ANCHORS`: 0, 8, 16, each on the
outline after the move across) and puts the points between two anchors at equal arc lengths of
the polyline through the moved points; :func:`annotated_jaw` does both.

Used by the photo benchmark (benchmarks/photo_landmarks.py) to score the jaw as annotated. Not in
the fit: its contour points are mediapipe's face-oval points, whose correspondence was derived from
renders as fixed surface points; moving those detections' model points to the outline between
refits (tried on the benchmark's photos) raised the landmark residual and the NME on three of four.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from synth.errors import SynthError
from synth.geometry.normals import normalize
from synth.geometry.raycast import first_hits
from synth.model.meshutil import barycentric_points

#: ibug68 points that follow the face's outline
IBUG68_CONTOUR = tuple(range(17))
#: jaw points that stay where the model puts them (on the outline); the rest are spaced evenly
#: along the outline between them (:func:`spaced_evenly`): the ear-level ends and the chin
IBUG68_JAW_ANCHORS = (0, 8, 16)
#: the ibug68 nose tip: the face's front is the direction from the head's centre to it
IBUG68_NOSE_TIP = 30
#: a projected contour enclosing less than this (pixels squared) is seen edge-on and left as it is
MIN_AREA_PX2 = 1.0
#: a gap between neighbouring samples longer than this many times their mean spacing ends a line
MAX_GAP_FACTOR = 4.0
#: the lines' rays accept barycentric coordinates down to -this (raycast.first_hits' ``edge_eps``):
#: the chin's line lies in the symmetric template's midline plane and its rays run along the
#: midline edges, where rounding alone could let them slip between the two triangles to a skin
#: surface behind (the throat's): the line then broke into one sample
RAY_EDGE_EPS = 1e-9


@dataclasses.dataclass(frozen=True)
class ContourLines:
    """Per contour point a line of ``S`` samples, inner end first:
    ``tri`` (L, S) triangle indices, ``bary`` (L, S, 3), ``count`` (L,) valid samples per line
    (the rest repeat the last valid one), ``fixed`` (L,) the sample at the fixed landmark."""

    tri: np.ndarray
    bary: np.ndarray
    count: np.ndarray
    fixed: np.ndarray


def _skin_triangles(model) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the triangles whose corners are all skin, and of those touching an ear."""
    tris = np.asarray(model.triangles, np.int64)
    skin = np.zeros(len(model.template), bool)
    skin[np.asarray(model.regions["skin"])] = True
    ear = np.zeros(len(model.template), bool)
    ear[np.asarray(model.regions["ears"])] = True
    return np.flatnonzero(skin[tris].all(1)), ear[tris].any(1)


def contour_lines(model, points: np.ndarray | None = None, front: np.ndarray | None = None, *,
                  step_deg: float = 1.0, inner_deg: float = 45.0, outer_deg: float = 0.0) -> ContourLines:
    """The contour lines (module docstring) through ``points`` (L, 3), template positions in their
    order along the contour (default: ibug68's jaw, :data:`IBUG68_CONTOUR`); ``front`` (3,) a
    template point at the face's front (default: ibug68's nose tip)."""
    V = np.asarray(model.template, np.float64)
    T = np.asarray(model.triangles, np.int64)
    tri0, bary0 = model.landmarks["ibug68"]
    ibug = barycentric_points(V, T, np.asarray(tri0), np.asarray(bary0, np.float64))
    P = ibug[list(IBUG68_CONTOUR)] if points is None else np.asarray(points, np.float64)
    front = ibug[IBUG68_NOSE_TIP] if front is None else np.asarray(front, np.float64)
    skin_tris, ear_tri = _skin_triangles(model)
    pts = list(range(len(P)))
    centre = 0.5 * (V[model.regions["ear_l"]].mean(0) + V[model.regions["ear_r"]].mean(0))
    forward = normalize(front - centre)  # from the head's centre towards the face
    angles = np.deg2rad(np.arange(-inner_deg, outer_deg + 0.5 * step_deg, step_deg))
    lines_tri, lines_bary, counts, fixed = [], [], [], []
    for i, j in enumerate(pts):
        prev, nxt = pts[max(i - 1, 0)], pts[min(i + 1, len(pts) - 1)]
        t = normalize(P[nxt] - P[prev])
        c = centre - np.dot(centre - P[j], t) * t  # the head's centre projected onto the plane
        r = normalize(P[j] - c)
        o = normalize(np.cross(t, r))
        if np.dot(o, forward) > 0:
            o = -o
        dirs = np.cos(angles)[:, None] * r + np.sin(angles)[:, None] * o
        radius = 2.0 * np.linalg.norm(V - c, axis=1).max()
        hit, bary, _ = first_hits(c + radius * dirs, -dirs, V, T[skin_tris], edge_eps=RAY_EDGE_EPS)
        hit = np.where(hit >= 0, skin_tris[np.maximum(hit, 0)], -1)
        X = barycentric_points(V, T, np.maximum(hit, 0), bary)
        k0 = int(np.argmin(np.abs(angles)))
        n = _valid_run(hit, ear_tri, X, k0)
        lo, hi = n
        lines_tri.append(hit[lo:hi])
        lines_bary.append(bary[lo:hi])
        counts.append(hi - lo)
        fixed.append(k0 - lo)
    S = max(counts)
    tri = np.stack([np.concatenate([a, np.repeat(a[-1:], S - len(a))]) for a in lines_tri])
    bary = np.stack([np.concatenate([b, np.repeat(b[-1:], S - len(b), 0)]) for b in lines_bary])
    return ContourLines(tri, bary, np.asarray(counts), np.asarray(fixed))


def _valid_run(hit: np.ndarray, ear_tri: np.ndarray, X: np.ndarray, k0: int) -> tuple[int, int]:
    """[lo, hi): the samples around ``k0`` (the fixed landmark's) up to a miss, an ear or a gap."""
    ok = (hit >= 0) & ~ear_tri[np.maximum(hit, 0)]
    step = np.linalg.norm(np.diff(X, axis=0), axis=1)
    typical = np.median(step[ok[1:] & ok[:-1]])
    gap = np.concatenate([step > MAX_GAP_FACTOR * typical, [False]])  # gap[k]: between k and k + 1
    if not ok[k0]:
        raise SynthError("a contour line misses the skin at its own landmark", "head model",
                         "contour lines need the landmark on the model's skin region, off the ears")
    lo = k0
    while lo > 0 and ok[lo - 1] and not gap[lo - 1]:
        lo -= 1
    hi = k0 + 1
    while hi < len(hit) and ok[hi] and not gap[hi - 1]:
        hi += 1
    return lo, hi


def visible_contour(lines: ContourLines, triangles: np.ndarray, vertices: np.ndarray, fixed_px: np.ndarray,
                    project) -> np.ndarray:
    """(L, 2) pixels: the contour landmarks moved out to the face's visible outline (module
    docstring). ``vertices`` (V, 3) posed, ``fixed_px`` (L, 2) the fixed landmarks' projections,
    ``project`` maps (N, 3) points in the vertices' frame to (N, 2) pixels."""
    V = np.asarray(vertices, np.float64)
    q = np.asarray(fixed_px, np.float64)
    L, S = lines.tri.shape
    X = barycentric_points(V, np.asarray(triangles, np.int64), lines.tri.reshape(-1), lines.bary.reshape(-1, 3))
    x = np.asarray(project(X), np.float64).reshape(L, S, 2)
    area = 0.5 * np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
    if abs(area) < MIN_AREA_PX2:
        return q.copy()
    tangent = q[np.minimum(np.arange(L) + 1, L - 1)] - q[np.maximum(np.arange(L) - 1, 0)]
    normal = np.sign(area) * np.stack([tangent[:, 1], -tangent[:, 0]], 1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    valid = np.arange(S)[None] < lines.count[:, None]
    reach = np.where(valid, np.einsum("lsc,lc->ls", x - q[:, None], normal), 0.0)
    return q + np.maximum(reach.max(1), 0.0)[:, None] * normal


def spaced_evenly(points: np.ndarray, anchors=IBUG68_JAW_ANCHORS) -> np.ndarray:
    """(L, 2): ``points`` (L, 2) along a contour, the ``anchors`` (increasing indices, first 0 and
    last L - 1) kept, and the points between two anchors moved along the polyline through
    ``points`` to equal arc lengths between them (module docstring)."""
    p = np.asarray(points, np.float64)
    a = [int(k) for k in anchors]
    if a[0] != 0 or a[-1] != len(p) - 1 or np.any(np.diff(a) <= 0):
        raise SynthError(f"anchors {a} must increase from 0 to {len(p) - 1}", "contour",
                         "pass the indices of the contour's fixed points, ends included")
    out = p.copy()
    for lo, hi in zip(a[:-1], a[1:]):
        seg = p[lo:hi + 1]
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(seg, axis=0), axis=1))])
        at = np.linspace(0.0, s[-1], hi - lo + 1)
        out[lo:hi + 1] = np.stack([np.interp(at, s, seg[:, 0]), np.interp(at, s, seg[:, 1])], 1)
        out[hi] = seg[-1]  # exactly the anchor
    return out


def annotated_jaw(lines: ContourLines, triangles: np.ndarray, vertices: np.ndarray, fixed_px: np.ndarray,
                  project, anchors=IBUG68_JAW_ANCHORS) -> np.ndarray:
    """(L, 2) pixels: the contour landmarks as 300-W annotates them, moved out across the contour to
    the visible outline (:func:`visible_contour`) and spaced evenly along it between the
    ``anchors`` (:func:`spaced_evenly`); arguments as :func:`visible_contour`'s."""
    return spaced_evenly(visible_contour(lines, triangles, vertices, fixed_px, project), anchors)
