"""Dot products, unit vectors, face normals and vertex normals of triangle meshes (numpy, batched).

``vertices`` are (V, 3) floats, ``triangles`` (T, 3) vertex indices, counter-clockwise seen
from the side the normal points to. Everything is computed in float64.
"""

from __future__ import annotations

import numpy as np


def dot(a, b) -> np.ndarray:
    """Dot products along the last axis of broadcastable arrays."""
    return np.einsum("...i,...i->...", a, b)


def normalize(v: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """Vectors divided by their length along the last axis (lengths below ``eps`` divide by ``eps``)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, eps)


def face_normals(vertices: np.ndarray, triangles: np.ndarray, unit: bool = True) -> np.ndarray:
    """(T, 3) triangle normals. ``unit=False`` gives the raw cross product (length = twice the
    area); ``unit=True`` unit vectors, and exactly zero for zero-area triangles."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    return _unit_or_zero(n) if unit else n


def corner_angles(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(T, 3) interior angle of each triangle at each corner, radians (pi/2 next to a zero-length edge)."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    out = np.empty(t.shape)
    for k in range(3):
        u = v[t[:, (k + 1) % 3]] - v[t[:, k]]
        w = v[t[:, (k + 2) % 3]] - v[t[:, k]]
        den = np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1)
        cos = np.einsum("ij,ij->i", u, w) / np.maximum(den, 1e-300)
        out[:, k] = np.arccos(np.clip(cos, -1.0, 1.0))
    return out


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray, weighting: str = "area",
                   fallback: np.ndarray | None = None) -> np.ndarray:
    """(V, 3) unit vertex normals: the normalised sum of the normals of the triangles around
    each vertex, weighted by triangle area (``"area"``) or by the corner angle at the vertex
    (``"angle"``, the pseudo-normal of Thuerrner and Wuethrich). Zero-area triangles add
    nothing. A vertex whose sum is zero (in no triangle, or only in zero-area ones, or
    where normals cancel) gets ``fallback`` if given, else the zero vector."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    if weighting == "area":
        fn = face_normals(v, t, unit=False)  # |cross| = 2 area: area weights for free
        per_corner = (fn, fn, fn)
    elif weighting == "angle":
        fn = face_normals(v, t, unit=True)
        ang = corner_angles(v, t)
        per_corner = tuple(fn * ang[:, k, None] for k in range(3))
    else:
        raise ValueError(f"vertex_normals weighting must be 'area' or 'angle', not {weighting!r}")
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, t[:, k], per_corner[k])
    out = _unit_or_zero(n)
    if fallback is not None:
        out[~np.any(out != 0.0, axis=1)] = np.asarray(fallback, np.float64)
    return out


def _unit_or_zero(n: np.ndarray) -> np.ndarray:
    ln = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
