"""Landmarks of the default model: the 68 iBUG points placed by anatomical rules on the
template (lid and lip loops, the midline profile, rays for brows and the jaw line), snapped to
the skin surface; and ``dense`` points by farthest-point sampling of the face. Also the
orchestration of regions and landmarks (the face regions need the landmarks)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.errors import SynthError
from synth.geometry.closest import ClosestPoints
from synth.geometry.normals import face_normals, vertex_normals
from synth.geometry.raycast import first_hits
from synth.model import meshutil as mu
from synth.model.builders.makehuman.mesh import Mesh
from synth.model.builders.makehuman.regions import (Features, feature_regions, landmark_regions, midline,
                                                    ring_midpoints)
from synth.model.builders.makehuman.surface import arc_at_x, level_points, polyline_at, split_loop, surface_hits
from synth.model.builders.makehuman.targets import TargetSpace

IBUG_GROUPS = (("jaw", 17), ("brow_r", 5), ("brow_l", 5), ("nose_bridge", 4), ("nose_base", 5),
               ("eye_r", 6), ("eye_l", 6), ("lip_outer", 12), ("lip_inner", 8))
DENSE_LANDMARKS = 600
CHIN_NORMAL_DOWN = 0.8  # chin landmark: first midline point below the lip whose normal points down by >= asin(0.8)
JAW_ANGLE = 0.35  # the jaw angle's height below the mouth corners, in mouth-corner-to-chin heights
JAW_SIDE_SAMPLES = 12  # heights at which the cheek's silhouette is traced, canthus to jaw angle
REGION_JAW_TOP = 0.15  # the face region's jaw line starts this far below the canthus, in canthus-to-chin heights
BROW_HEIGHT = (0.40, 0.53, 0.58, 0.55, 0.42)  # brow above the upper lid, in eye widths, medial -> lateral
BROW_HEAD = -0.10  # medial end of the brow (21/22), in eye widths from the medial canthus (negative: medial)
#: frontal rays that trace the nose base: spacing in height (m) along a column, and between columns
NOSE_BASE_STEP_M = 0.0001
NOSE_BASE_COLUMN_M = 0.00025
NOSE_BASE_TIE_M = 1e-4  # outline heights this close count as equal when the subalare (31/35) is chosen
#: distances (m) this close count as equal where landmarks are chosen: a landmark as near to two skin
#: triangles (on their shared edge) names the lower index
LANDMARK_TIE_M = 1e-8
_FORWARD = np.array([0.0, 1.0, 0.0])  # rays cast from in front of the face toward the back (+Y)


def regions_and_landmarks(mesh: Mesh, X: np.ndarray, tris: np.ndarray, family: np.ndarray,
                          joint_rest: np.ndarray, space: TargetSpace, data: Path):
    """(regions, landmarks, landmark names) of the template ``X`` in the model file's layout."""
    f = feature_regions(mesh, X, tris, space, data)
    pts, tip, jaw_line = ibug68_points(f, X, tris, joint_rest)
    P68 = np.array([pts[i] for i in range(68)])
    skin_tri = np.nonzero(f.skin[tris].all(1))[0]
    on_skin = ClosestPoints(X, tris, skin_tri, tie_m=LANDMARK_TIE_M)(P68)
    tri68, bary68 = on_skin.face, on_skin.bary
    names68 = [f"{grp}_{i:02d}" for grp, n in IBUG_GROUPS for i in range(n)]
    landmark_regions(f, X, family, joint_rest, pts, jaw_line)
    face = f.reg["face"]
    # spread over the base mesh's face (read from text, so the same bits on every machine; the
    # template's last bits depend on the BLAS kernels, and late picks are near ties)
    dense = face[mu.farthest_point_sampling(mesh.base[face], DENSE_LANDMARKS, int(np.nonzero(face == tip)[0][0]),
                                          tie_m=LANDMARK_TIE_M)]
    dtri, dbary = mu.vertex_landmarks(tris, dense)
    landmarks = {"ibug68": (tri68.astype(np.int32), bary68.astype(np.float32)),
                 "dense": (dtri.astype(np.int32), dbary.astype(np.float32))}
    names = {"ibug68": names68, "dense": [f"dense_{i:03d}" for i in range(DENSE_LANDMARKS)]}
    regions = {k: np.asarray(v, np.int32) for k, v in sorted(f.reg.items())}
    return regions, landmarks, names


def ibug68_points(f: Features, X: np.ndarray, tris: np.ndarray, joint_rest: np.ndarray):
    """({ibug index: 3D point}, nose-tip vertex, the face region's jaw line (9, 3)). The points
    lie on (or very near) the skin."""
    pts: dict[int, np.ndarray] = {}
    _eyes(f, X, pts)
    _mouth(f, X, pts)
    tip = _nose(f, X, joint_rest, pts)
    _nose_base(f, X, tris, pts)
    _brows(f, X, tris, pts)
    jaw_line = _jaw(f, X, tris, joint_rest, pts)
    return pts, tip, jaw_line


def _eyes(f: Features, X: np.ndarray, pts: dict) -> None:
    for t, ids in (("r", (36, 37, 38, 39, 40, 41)), ("l", (42, 43, 44, 45, 46, 47))):
        up, lo = f.lids[t]["upper"], f.lids[t]["lower"]
        x0, x1 = X[up[0], 0], X[up[-1], 0]
        xs = [x0 + (x1 - x0) * g for g in (1 / 3, 2 / 3)]
        pts[ids[0]], pts[ids[3]] = X[up[0]], X[up[-1]]
        pts[ids[1]], pts[ids[2]] = arc_at_x(X, up, xs[0]), arc_at_x(X, up, xs[1])
        pts[ids[4]], pts[ids[5]] = arc_at_x(X, lo, xs[1]), arc_at_x(X, lo, xs[0])


def _mouth(f: Features, X: np.ndarray, pts: dict) -> None:
    rings, k_out = f.lip_rings, f.lip_outer
    inner, outer = split_loop(X, rings[0]), split_loop(X, rings[k_out])
    ou, ol, iu, il = outer["upper"], outer["lower"], inner["upper"], inner["lower"]
    x48, x54 = X[ou[0], 0], X[ou[-1], 0]
    right_half = [v for v in ou if X[v, 0] < 0]
    peak = max(right_half, key=lambda v: X[v, 2])  # cupid's bow peak
    x50 = X[peak, 0] if x48 * 0.8 < X[peak, 0] < x48 * 0.15 else x48 / 3
    pts[48], pts[54] = X[ou[0]], X[ou[-1]]
    pts[51], pts[57] = X[ring_midpoints(X, rings[k_out])[0]], X[ring_midpoints(X, rings[k_out])[1]]
    pts[50], pts[52] = arc_at_x(X, ou, x50), arc_at_x(X, ou, -x50)
    pts[49], pts[53] = arc_at_x(X, ou, (x48 + x50) / 2), arc_at_x(X, ou, (x54 - x50) / 2)
    pts[58], pts[56] = arc_at_x(X, ol, x50), arc_at_x(X, ol, -x50)
    pts[59], pts[55] = arc_at_x(X, ol, (x48 + x50) / 2), arc_at_x(X, ol, (x54 - x50) / 2)
    x60, x64 = X[iu[0], 0], X[iu[-1], 0]
    pts[60], pts[64] = X[iu[0]], X[iu[-1]]
    pts[62], pts[66] = X[ring_midpoints(X, rings[0])[0]], X[ring_midpoints(X, rings[0])[1]]
    pts[61], pts[63] = arc_at_x(X, iu, x60 / 2), arc_at_x(X, iu, x64 / 2)
    pts[67], pts[65] = arc_at_x(X, il, x60 / 2), arc_at_x(X, il, x64 / 2)


def _nose(f: Features, X: np.ndarray, joint_rest: np.ndarray, pts: dict) -> int:
    """Bridge (27-30) from the midline profile; returns the tip vertex."""
    lid_top = X[f.lids["l"]["upper"], 2].max()
    profile = midline(f, X, joint_rest)
    front = profile[(X[profile, 2] > pts[51][2]) & (X[profile, 2] < lid_top)]
    tip = front[np.argmin(X[front, 1])]
    pts[30] = X[tip]
    above = front[X[front, 2] > X[tip, 2]]
    nasion = above[np.argmax(X[above, 1])]
    pts[27] = X[nasion]
    ridge = above[X[above, 2] <= X[nasion, 2]]
    ridge = ridge[np.argsort(-X[ridge, 2])]
    ridge_pts = np.concatenate([X[ridge], X[[tip]]])
    pts[28], pts[29] = polyline_at(ridge_pts, (1 / 3, 2 / 3))
    return int(tip)


def _brows(f: Features, X: np.ndarray, tris: np.ndarray, pts: dict) -> None:
    """Rays from the front at heights above the upper lid, in eye widths, from the brow head
    (``BROW_HEAD`` eye widths from the medial canthus) to the brow tail, which ends on the line
    from the alar base (31/35) through the lateral canthus (36/45)."""
    for t, ids in (("l", (22, 23, 24, 25, 26)), ("r", (21, 20, 19, 18, 17))):
        s = 1.0 if t == "l" else -1.0
        upper = f.lids[t]["upper"]
        med, lat = X[upper[0 if t == "l" else -1]], X[upper[-1 if t == "l" else 0]]
        w = abs(lat[0] - med[0])
        top = X[upper, 2].max()
        zs = top + w * np.array(BROW_HEIGHT)
        ala = pts[35 if t == "l" else 31]
        x_tail = ala[0] + (zs[-1] - ala[2]) / (lat[2] - ala[2]) * (lat[0] - ala[0])
        xs = np.linspace(med[0] + s * w * BROW_HEAD, x_tail, 5)
        o = np.stack([xs, np.full(5, X[:, 1].min() - 0.1), zs], 1)
        hits = surface_hits(X, tris[f.vis_tris], o, np.tile(_FORWARD, (5, 1)))
        for k in range(5):
            pts[ids[k]] = hits[k]


def _nose_base(f: Features, X: np.ndarray, tris: np.ndarray, pts: dict) -> None:
    """The lower outline of the nose seen from the front (31-35): where the skin under the
    nose, facing down, turns into the upper lip and cheek, facing forward (``_base_outline``,
    one column of rays every ``NOSE_BASE_COLUMN_M`` from the midline out to where the ala ends).
    33 (subnasale): on the midline, where the columella meets the lip. 31/35 (subalare): the
    lowest point of the outline's lateral half, where the alar lobule meets the lip. 32/34: the
    front-ray hit halfway between them (the nostril sill)."""
    vis = tris[f.vis_tris]
    normals = face_normals(X, vis)
    z_top, z_low = pts[30][2], pts[51][2]
    outline = [_base_outline(X, vis, normals, 0.0, z_top, z_low)]
    while (p := _base_outline(X, vis, normals, -NOSE_BASE_COLUMN_M * len(outline), z_top, z_low)) is not None:
        outline.append(p)
    line = np.array(outline)  # from the midline out to the lateral end of the ala
    pts[33] = line[0]
    lobule = line[len(line) // 2:]  # the lateral half: the alar lobules, lateral of the nostrils
    low = np.nonzero(lobule[:, 2] <= lobule[:, 2].min() + NOSE_BASE_TIE_M)[0]
    pts[31] = lobule[low[-1]]  # subalare: the lowest point of the lobule; near ties: the most lateral
    pts[35] = pts[31] * [-1, 1, 1]
    o = np.array([[pts[31][0] / 2, X[:, 1].min() - 0.1, (pts[31][2] + pts[33][2]) / 2]])
    pts[32] = surface_hits(X, vis, o, _FORWARD[None])[0]
    pts[34] = pts[32] * [-1, 1, 1]


def _base_outline(X: np.ndarray, vis: np.ndarray, normals: np.ndarray, x: float, z_top: float,
                  z_low: float) -> np.ndarray | None:
    """The point where a column of frontal rays at ``x``, going down from
    ``z_top`` to ``z_low``, first meets skin that faces down more than forward and then skin
    that faces forward again: the point where the normal leans 45 degrees between down and
    forward, interpolated between the two rays around the turn (continuous in the surface, so no
    ray decides it alone). None when no ray in the column meets skin facing down."""
    zs = z_top - NOSE_BASE_STEP_M * np.arange(int((z_top - z_low) / NOSE_BASE_STEP_M) + 1)
    o = np.stack([np.full(len(zs), x), np.full(len(zs), X[:, 1].min() - 0.1), zs], 1)
    tri, bary, _ = first_hits(o, np.tile(_FORWARD, (len(zs), 1)), X, vis)
    if np.any(tri < 0):
        raise SynthError("a landmark ray missed the template surface", "makehuman builder", "report this as a bug")
    hit = np.einsum("nk,nkc->nc", bary, X[vis[tri]])
    lean = normals[tri, 1] - normals[tri, 2]  # > 0: faces down (-Z) more than forward (-Y)
    down = np.nonzero(lean > 0.0)[0]
    if len(down) == 0:
        return None
    after = np.nonzero(lean[down[0]:] <= 0.0)[0]
    if len(after) == 0:
        raise SynthError("the nose base does not meet the upper lip", "makehuman builder", "report this as a bug")
    k = int(down[0] + after[0])
    a = lean[k - 1] / (lean[k - 1] - lean[k])
    return hit[k - 1] * (1 - a) + hit[k] * a


def _jaw(f: Features, X: np.ndarray, tris: np.ndarray, joint_rest: np.ndarray, pts: dict) -> np.ndarray:
    """Chin (8) on the midline profile, and 0..7 / 9..16 spaced evenly, as a frontal view measures
    length (x and z), along the face's outline from the height of the lateral canthus (36/45) down
    to the chin: the cheek's silhouette to the jaw angle, then the mandible body. Returns the face
    region's lower boundary (``region_jaw_line``), kept apart from the points."""
    vn = vertex_normals(X, tris[f.vis_tris])
    profile = midline(f, X, joint_rest)
    chin_line = profile[(X[profile, 2] < pts[57][2]) & (X[profile, 1] < joint_rest[2, 1])]
    chin_line = chin_line[np.argsort(-X[chin_line, 2])]
    dy = np.diff(X[chin_line, 1])
    fold = int(np.nonzero(dy < 0)[0][0])  # profile turns forward again below the labiomental fold
    pog = fold + int(np.nonzero(dy[fold:] > 0)[0][0])  # ... and back again under the chin (pogonion)
    chin_line = chin_line[pog:]
    g = vn[chin_line, 2] + CHIN_NORMAL_DOWN
    k = int(np.nonzero(g < 0)[0][0])
    a = g[k - 1] / (g[k - 1] - g[k])
    pts[8] = X[chin_line[k - 1]] * (1 - a) + X[chin_line[k]] * a
    contour = _outline(f, X, tris, joint_rest, pts, pts[36][2], JAW_SIDE_SAMPLES)
    for i, p in enumerate(polyline_at(contour, np.linspace(0.0, 1.0, 9), axes=(0, 2))[:8]):
        pts[i] = p
        pts[16 - i] = p * [-1, 1, 1]
    return region_jaw_line(f, X, tris, joint_rest, pts)


def region_jaw_line(f: Features, X: np.ndarray, tris: np.ndarray, joint_rest: np.ndarray,
                    pts: dict) -> np.ndarray:
    """(9, 3) the lower boundary of the face region (and the beard's cheek line), right side to
    the chin: the outline from ``REGION_JAW_TOP`` canthus-to-chin heights below the lateral canthus,
    9 points evenly spaced in 3D arc length. It is not the jaw landmarks (those start at the
    canthus): the regions, and the dense landmarks sampled on the face, stay where they were."""
    z_top = pts[36][2] - REGION_JAW_TOP * (pts[36][2] - pts[8][2])
    return polyline_at(_outline(f, X, tris, joint_rest, pts, z_top, 8), np.linspace(0.0, 1.0, 9))


def _outline(f: Features, X: np.ndarray, tris: np.ndarray, joint_rest: np.ndarray, pts: dict, z_top: float,
             n_side: int) -> np.ndarray:
    """The right half of the face's outline from height ``z_top`` to the chin (8): the frontal
    silhouette of the cheek (the most lateral skin point in front of the ear, at ``n_side``
    heights) down to the jaw angle at ``z48 - JAW_ANGLE (z48 - z8)``, then the mandible body as
    the straight side-view line from the jaw angle to the chin, projected onto the skin radially
    from the vertical axis through the jaw joint."""
    zg = pts[48][2] - JAW_ANGLE * (pts[48][2] - pts[8][2])
    y_ear = X[f.reg["ears"], 1].min()

    def silhouette(z):
        p = level_points(X, tris, X[:, 2] - z, f.vis_tris)
        p = p[(p[:, 1] < y_ear - 0.002) & (p[:, 0] < 0)]
        return p[np.argmin(p[:, 0])]

    side = np.array([silhouette(z) for z in np.linspace(z_top, zg, n_side)])
    angle = side[-1]
    origins, dirs = [], []
    for t in np.linspace(0.0, 1.0, 12)[1:-1]:
        q = angle * (1 - t) + pts[8] * t
        o = np.array([0.0, joint_rest[2, 1], q[2]])
        d = q - o
        d[2] = 0.0
        origins.append(o)
        dirs.append(d / np.linalg.norm(d))
    body_line = surface_hits(X, tris[f.vis_tris], np.array(origins), np.array(dirs), farthest=True)
    return np.concatenate([side, body_line, pts[8][None]])
