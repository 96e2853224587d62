"""Closest points on triangles: one implementation, vectorised, used by every caller (asset
fitting, signed distance, the model builder's landmark placement).

- :func:`closest_on_triangles`: point-triangle closest point after Ericson, *Real-Time
  Collision Detection* 5.1.5, for broadcastable arrays of points and triangles;
- :func:`nearest_on_candidates`: the closest of a few candidate triangles per point (ties
  go to the first candidate);
- :class:`ClosestPoints`: closest points on a triangle mesh (or a subset of its triangles),
  the candidates being the ``k`` triangles with the nearest centroids (a KD tree).

Tested against ``trimesh`` (per triangle and on whole meshes) and brute force.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from synth.geometry.normals import dot


def closest_on_triangles(p, a, b, c):
    """Closest points of p to triangles (a, b, c) (all broadcastable (..., 3)), after Ericson,
    Real-Time Collision Detection 5.1.5, vectorised. Returns (point, barycentric (..., 3));
    vertex/edge regions give exact 0/1 coordinates; a degenerate triangle gives its centroid
    weights where the face-region test cannot decide."""
    p, a, b, c = np.broadcast_arrays(p, a, b, c)
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp = p - b
    d3, d4 = dot(ab, bp), dot(ac, bp)
    cp = p - c
    d5, d6 = dot(ab, cp), dot(ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v_in = np.where(den != 0, vb / den, 1.0 / 3.0)
        w_in = np.where(den != 0, vc / den, 1.0 / 3.0)
        t_ab = np.where(d1 - d3 != 0, d1 / (d1 - d3), 0.0)
        t_ac = np.where(d2 - d6 != 0, d2 / (d2 - d6), 0.0)
        e1, e2 = d4 - d3, d5 - d6
        t_bc = np.where(e1 + e2 != 0, e1 / (e1 + e2), 0.0)
    z = np.zeros_like(d1)
    o = np.ones_like(d1)
    bary = np.stack([1.0 - v_in - w_in, v_in, w_in], -1)
    conds = [
        (va <= 0) & (e1 >= 0) & (e2 >= 0),  # edge BC
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),  # edge AC
        (d6 >= 0) & (d5 <= d6),  # vertex C
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),  # edge AB
        (d3 >= 0) & (d4 <= d3),  # vertex B
        (d1 <= 0) & (d2 <= 0),  # vertex A
    ]
    vals = [
        np.stack([z, 1.0 - t_bc, t_bc], -1),
        np.stack([1.0 - t_ac, z, t_ac], -1),
        np.stack([z, z, o], -1),
        np.stack([1.0 - t_ab, t_ab, z], -1),
        np.stack([z, o, z], -1),
        np.stack([o, z, z], -1),
    ]
    # Ericson's tests run A, B, AB, C, AC, BC, inside and the first match wins: apply them in
    # reverse so that earlier tests overwrite later ones.
    for cond, val in zip(conds, vals):
        bary = np.where(cond[..., None], val, bary)
    q = bary[..., 0:1] * a + bary[..., 1:2] * b + bary[..., 2:3] * c
    return q, bary


class Closest(NamedTuple):
    """Closest points: ``point`` (N, 3), ``face`` (N,) index into the mesh's triangles,
    ``bary`` (N, 3) barycentric coordinates on that face, ``distance`` (N,)."""

    point: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    distance: np.ndarray


def nearest_on_candidates(points, vertices, triangles, candidates, by: str = "squared",
                          tie_m: float | None = None) -> Closest:
    """The closest point of each point's candidate triangles: ``candidates`` (N, K) indices into
    ``triangles`` (rows may repeat an index). Ties go to the first candidate of the row.

    ``by`` is what is compared: ``"squared"`` distances, or the ``"distance"`` itself, whose
    square root rounds candidates within about an ulp of each other (a point nearest to an
    edge shared by two triangles) to a tie. Both give the same distance; the triangle (and so
    the barycentrics and a face normal) can differ in such near-ties. The strand rigs use
    ``"distance"``, everything else ``"squared"``, which keeps every rig's geometry as it was
    before the two implementations became one.

    ``tie_m``: candidates within this distance (m) of the nearest count as a tie, which goes to
    the lowest triangle index: a discrete choice that no rounding of the inputs can change
    (what a model builder needs; a point on an edge is as near to both of its triangles)."""
    if by not in ("squared", "distance"):
        raise ValueError(f"by must be 'squared' or 'distance', not {by!r}")
    P = np.asarray(points, np.float64).reshape(-1, 3)
    V = np.asarray(vertices, np.float64)
    cand = np.asarray(candidates, np.int64).reshape(len(P), -1)
    tri = np.asarray(triangles, np.int64)[cand]
    q, bary = closest_on_triangles(P[:, None, :], V[tri[..., 0]], V[tri[..., 1]], V[tri[..., 2]])
    d2 = ((q - P[:, None, :]) ** 2).sum(-1)
    dist = np.sqrt(d2)
    best = np.argmin(d2 if by == "squared" else dist, axis=1)
    r = np.arange(len(P))
    if tie_m is not None:
        near = dist <= dist[r, best][:, None] + float(tie_m)
        best = np.argmin(np.where(near, cand, np.iinfo(np.int64).max), axis=1)
    return Closest(q[r, best], cand[r, best], bary[r, best], dist[r, best])


class ClosestPoints:
    """Closest points on the triangles ``faces`` (default: all) of a mesh.

    The candidates for a point are the ``k`` triangles whose centroids are nearest to it: exact
    whenever the closest triangle is among them, which holds for points near a surface whose
    triangles are of similar size (a point on a triangle is within its circumradius of the
    centroid). Memory is bounded by answering ``chunk`` points at a time. ``by`` and ``tie_m``:
    see :func:`nearest_on_candidates`."""

    def __init__(self, vertices, triangles, faces=None, k: int = 16, chunk: int = 4096, by: str = "squared",
                 tie_m: float | None = None):
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(triangles, np.int64)
        self.faces = np.arange(len(self.F)) if faces is None else np.asarray(faces, np.int64)
        self.k = int(min(k, len(self.faces)))
        self.chunk = int(chunk)
        self.by = by
        self.tie_m = tie_m
        t = self.V[self.F[self.faces]]
        self.tree = cKDTree((t[:, 0] + t[:, 1] + t[:, 2]) / 3.0)

    def __call__(self, points) -> Closest:
        P = np.asarray(points, np.float64).reshape(-1, 3)
        if len(P) == 0 or self.k == 0:
            if len(P):
                raise ValueError("closest point on an empty set of triangles")
            return Closest(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))
        parts = [self._query(P[i:i + self.chunk]) for i in range(0, len(P), self.chunk)]
        return Closest(*(np.concatenate(x) for x in zip(*parts)))

    def _query(self, P) -> Closest:
        # threads pay off for large batches only (each query starts them anew); same answer
        _, cand = self.tree.query(P, k=self.k, workers=-1 if len(P) >= 1024 else 1)
        return nearest_on_candidates(P, self.V, self.F, self.faces[np.asarray(cand).reshape(len(P), -1)], self.by,
                                     self.tie_m)
