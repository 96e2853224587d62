"""Signed distance to a triangle mesh (open meshes allowed): the closest point
(:mod:`synth.geometry.closest`) signed by a normal there. One routine; the normal is chosen
per use (``sign``):

``"pseudo"``
    the angle-weighted pseudo-normal of the closest feature (face, edge or vertex; Baerentzen
    and Aanaes 2005): the sign is exact for a closed mesh and well behaved near an open one;
``"vertex"``
    the barycentric blend of the area-weighted vertex normals at the closest point: smooth,
    robust on open, non-watertight meshes (a bust), so pushing points along it gives smooth
    shells;
``"face"``
    the closest triangle's normal; the signed value is then the height above that triangle's
    plane (equal to the signed distance when the closest point is inside the triangle).

The normals come from the whole mesh ``triangles``; queries can be restricted to a subset
``faces``. A point exactly on the surface counts as outside (sign +1). ``k`` and ``by`` pass
to :class:`synth.geometry.closest.ClosestPoints`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from synth.geometry.closest import ClosestPoints
from synth.geometry.normals import dot, face_normals, normalize, vertex_normals

SIGNS = ("pseudo", "vertex", "face")


class SurfaceHit(NamedTuple):
    """``point`` (N, 3), ``face`` (N,) index into the mesh's triangles, ``bary`` (N, 3),
    ``distance`` (N,) unsigned, ``signed`` (N,), ``normal`` (N, 3) unit (the one that signed it)."""

    point: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    distance: np.ndarray
    signed: np.ndarray
    normal: np.ndarray


class SignedDistance:
    """Signed-distance queries against a triangle mesh (see the module docstring for ``sign``)."""

    def __init__(self, vertices, triangles, *, faces=None, sign: str = "pseudo", k: int = 16, by: str = "squared"):
        if sign not in SIGNS:
            raise ValueError(f"sign must be one of {SIGNS}, not {sign!r}")
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(triangles, np.int64)
        self.sign = sign
        self.closest = ClosestPoints(self.V, self.F, faces, k=k, by=by)
        self.face_normals = face_normals(self.V, self.F)
        if sign == "pseudo":
            self.vertex_normals = vertex_normals(self.V, self.F, "angle")
            self.edge_of_face, self.edge_normals = _edge_normals(self.F, self.face_normals)
        elif sign == "vertex":
            self.vertex_normals = vertex_normals(self.V, self.F, "area", fallback=(0.0, 0.0, 1.0))

    def query(self, points) -> SurfaceHit:
        P = np.asarray(points, np.float64).reshape(-1, 3)
        c = self.closest(P)
        if self.sign == "face":
            n = self.face_normals[c.face]
            return SurfaceHit(*c, dot(P - c.point, n), n)
        if self.sign == "vertex":
            n = normalize((c.bary[:, :, None] * self.vertex_normals[self.F[c.face]]).sum(1))
        else:
            n = self._pseudo_normals(c.face, c.bary)
        side = np.where(dot(P - c.point, n) < 0.0, -1.0, 1.0)
        return SurfaceHit(*c, side * c.distance, n)

    def __call__(self, points) -> np.ndarray:
        """Signed distances (N,)."""
        return self.query(points).signed

    def _pseudo_normals(self, face, bary):
        nz = bary > 1e-12
        cnt = nz.sum(1)
        normal = self.face_normals[face].copy()
        e = cnt == 2  # on an edge: the zero coordinate's local index names the opposite edge
        if e.any():
            j = np.argmin(np.where(nz[e], 1, 0), axis=1)
            normal[e] = self.edge_normals[self.edge_of_face[face[e], j]]
        v = cnt == 1  # on a vertex
        if v.any():
            j = np.argmax(bary[v], axis=1)
            normal[v] = self.vertex_normals[self.F[face[v], j]]
        return normal


def _edge_normals(F: np.ndarray, fn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3) edge id of the edge opposite each corner, and (E, 3) unit edge pseudo-normals (the
    normalised sum of the unit normals of the faces sharing the edge)."""
    keys = np.stack([np.sort(np.stack([F[:, (j + 1) % 3], F[:, (j + 2) % 3]], 1), 1) for j in range(3)], 1)
    uniq, inv = np.unique(keys.reshape(-1, 2), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    en = np.zeros((len(uniq), 3))
    np.add.at(en, inv, np.repeat(fn, 3, axis=0))
    return inv.reshape(-1, 3), normalize(en, 1e-30)
