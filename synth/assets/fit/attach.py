"""Attaching shells to a body surface (garments, headwear), pure numpy.

* :func:`body_query`: closest point and signed distance on a triangle subset of the body
  (:class:`synth.geometry.sdf.SignedDistance` with the ``"vertex"`` sign: the interpolated
  vertex normal at the closest point, robust on open, non-watertight meshes such as the bust);
* :func:`push_out` moves every point closer than ``clearance`` (or inside) to the closest
  surface point plus ``clearance`` along that normal (iterated: fixes concave corners);
* :class:`Binding` stores point -> (triangle, barycentric, local-frame offset) so a fitted
  mesh follows the body exactly when its vertices change (expressions).
"""

from __future__ import annotations

import numpy as np

from synth.geometry.closest import ClosestPoints
from synth.geometry.normals import normalize
from synth.geometry.sdf import SignedDistance

#: candidate triangles per query (nearest centroids): with the bust's triangle sizes (<= 4 cm)
#: and points within a few cm of the surface this finds the exact closest triangle
CANDIDATES = 16


def body_query(V: np.ndarray, F: np.ndarray, tri_ids: np.ndarray | None = None) -> SignedDistance:
    """Signed distance to the triangles ``tri_ids`` of ``F`` (default all), signed by the
    interpolated vertex normals of the whole mesh."""
    return SignedDistance(V, F, faces=tri_ids, sign="vertex", k=CANDIDATES)


def push_out(P: np.ndarray, query: SignedDistance, clearance, iterations: int = 3,
             max_depth: float = np.inf) -> np.ndarray:
    """Move points with signed distance < clearance to closest + clearance * normal.

    ``clearance`` is a scalar or per-point array. Points deeper than ``max_depth`` are left
    alone (they belong to a different body part; callers trim them instead)."""
    P = np.array(P, np.float64, copy=True)
    clr = np.broadcast_to(np.asarray(clearance, np.float64), (len(P),))
    idx = np.arange(len(P))
    for _ in range(iterations):
        if not len(idx):
            break
        # only the points moved by the last pass are queried again: the others' answer is the same
        h = query.query(P[idx])
        bad = (h.signed < clr[idx] - 1e-7) & (h.signed > -max_depth)
        if not bad.any():
            break
        j = idx[bad]
        P[j] = h.point[bad] + h.normal[bad] * clr[j, None]
        idx = j
    return P


class Binding:
    """Attach points to the closest triangles of a body (subset) in a local triangle frame.

    ``apply(V)`` reproduces the points exactly for the bind-time vertices and follows any
    later deformation of the bound triangles (rigidly per triangle)."""

    def __init__(self, V: np.ndarray, F: np.ndarray, tri_ids: np.ndarray, P: np.ndarray):
        c = ClosestPoints(V, F, tri_ids, k=CANDIDATES)(P)
        self.F = np.asarray(F, np.int64)[c.face]
        self.bary = c.bary
        E = self._frames(np.asarray(V, np.float64))
        self.coords = np.einsum("nij,nj->ni", E, np.asarray(P, np.float64) - c.point)

    def _frames(self, V, F=None):
        F = self.F if F is None else F
        A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
        e1 = normalize(B - A)
        n = normalize(np.cross(B - A, C - A))
        e2 = np.cross(n, e1)
        return np.stack([e1, e2, n], 1)  # rows

    def apply(self, V: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """The points on body vertices ``V`` (``rows``: a mask or indices of the points wanted)."""
        V = np.asarray(V, np.float64)
        if rows is None:
            F, bary, coords = self.F, self.bary, self.coords
        else:
            F, bary, coords = self.F[rows], self.bary[rows], self.coords[rows]
        c = (bary[:, :, None] * V[F]).sum(1)
        return c + np.einsum("nij,ni->nj", self._frames(V, F), coords)
