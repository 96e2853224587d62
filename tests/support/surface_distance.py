"""Distances to the head's outer surface for strand tests (no bpy): closest points by trimesh,
an implementation independent of the rigs' own (synth.geometry), and a sign that is right at thin
folds (the edge of a lid). Used by tests/blender/test_strands.py and
tests/assets/test_lashes_follow_lids.py."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


#: trimesh's closest point takes absolute tolerances (``tol.zero`` = 1e-12) on products of up to
#: four lengths, which for the head's sub-millimetre lid triangles in metres are about 1e-13: it
#: then picks the wrong Voronoi region (a point 0.30 mm off a triangle was given 0.33 mm, and a
#: neighbour's sign). Coordinates are given to it in millimetres.
MM = 1e3


def closest_points(tri, P):
    """Closest points on triangles ``tri`` (n, 3, 3) to points P (n, 3), by trimesh (in mm)."""
    import trimesh

    return trimesh.triangles.closest_point(np.asarray(tri) * MM, np.asarray(P) * MM) / MM


def _closest_on_triangles(P, A, B, C):
    """Closest points on triangles (A, B, C) to points P (all broadcastable (..., 3)), by trimesh:
    an implementation independent of the rigs' own."""
    shape = np.broadcast_shapes(P.shape, A.shape, B.shape, C.shape)
    P, A, B, C = (np.broadcast_to(x, shape).reshape(-1, 3) for x in (P, A, B, C))
    return closest_points(np.stack([A, B, C], 1), P).reshape(shape)


def _tie_sign(points, Q, d, tri):
    """Sign of each point from its candidate closest points ``Q`` (n, m, 3), distances ``d``
    (n, m) and triangles ``tri`` (n, m, 3, 3): a point is inside only if it is behind the plane
    of every face at the closest distance (to 0.1 %). One of those faces alone is not enough: a
    point in front of a thin convex fold (the edge of a lid seen from beyond its tip) is as close
    to the fold's underside as to its top, and behind the underside's plane, yet outside.
    Where the closest point is an edge, this agrees with the angle-weighted pseudo-normal
    (Baerentzen and Aanaes 2005), which is exact for a closed mesh."""
    n = np.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
    h = ((points[:, None] - Q) * n).sum(-1) / np.maximum(np.linalg.norm(n, axis=-1), 1e-30)
    tied = d <= d.min(1, keepdims=True) * (1.0 + 1e-3) + 1e-9
    return np.where(np.where(tied, h, -np.inf).max(1) < 0.0, -1.0, 1.0)


def surface_distance(points, V, T, k: int = 24, exact: bool = False):
    """Unsigned and signed distance to a triangle mesh (the same distances as
    trimesh.proximity.closest_point, without needing rtree; the sign by :func:`_tie_sign`). The
    k triangles with the nearest centroids are tried; with ``exact`` every point found farther
    than 0.1 mm is checked against all triangles (a large triangle's centroid can be far from a
    point on it)."""
    tri = V[T]
    cen = tri.mean(1)
    _, idx = cKDTree(cen).query(points, k=k)
    t = tri[idx]
    Pk = np.broadcast_to(points[:, None], t.shape[:2] + (3,))
    Q = _closest_on_triangles(Pk, t[..., 0, :], t[..., 1, :], t[..., 2, :])
    d = np.linalg.norm(Pk - Q, axis=-1)
    best = d.min(1)
    sign = _tie_sign(points, Q, d, t)
    redo = np.flatnonzero(best > 1e-4) if exact else np.zeros(0, np.int64)
    for a in range(0, len(redo), 64):
        r = redo[a:a + 64]
        Pa = np.broadcast_to(points[r][:, None], (len(r), len(T), 3))
        Qa = _closest_on_triangles(Pa, tri[None, :, 0], tri[None, :, 1], tri[None, :, 2])
        da = np.linalg.norm(Pa - Qa, axis=-1)
        best[r] = da.min(1)
        sign[r] = _tie_sign(points[r], Qa, da, np.broadcast_to(tri[None], (len(r),) + tri.shape))
    return best, sign * best


#: regions inside the head (mouth cavity, teeth, lash helper strips): not part of the skin surface
INTERIOR = ("mouth_interior", "teeth", "lash_helper_l_upper", "lash_helper_l_lower", "lash_helper_r_upper",
            "lash_helper_r_lower")


def head_distance(ctx, points, exact: bool = False):
    """Distance (and signed distance) to the head's outer surface (interior parts left out)."""
    T = ctx.data.triangles.astype(np.int64)
    inner = np.zeros(len(ctx.vertices), bool)
    for r in INTERIOR:
        if r in ctx.data.regions:
            inner[ctx.data.regions[r]] = True
    return surface_distance(points, np.asarray(ctx.vertices, np.float64), T[~inner[T].any(1)], exact=exact)
