"""Ray-triangle intersection (Möller-Trumbore), brute force over all triangles.

Meant for tens to a few thousand rays against meshes of up to ~100k triangles (landmark
placement, region rules): every ray is tested against every triangle, in blocks of rays so
that memory stays bounded. A ray is ``o + t d`` with ``t_min < t < t_max`` (``d`` need not be
unit length; ``t`` is in units of ``|d|``). A triangle counts as hit when the barycentric
coordinates of the crossing are all >= 0 (edges and corners included), and never when the
ray is parallel to its plane (``|det| <= det_eps``, which also skips zero-area triangles).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

DET_EPS = 1e-15


def ray_triangle_blocks(origins: np.ndarray, directions: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                        t_min: float = 0.0, t_max: float = np.inf, det_eps: float = DET_EPS,
                        chunk: int = 2_000_000) -> Iterator[tuple[slice, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Yield ``(rows, hit, t, u, v)`` per block of rays: ``rows`` the slice of rays, and (n, T)
    arrays of the hit mask, ray parameter and barycentric coordinates (the crossing is
    ``(1 - u - v) a + u b + v c`` of triangle ``(a, b, c)``). ``chunk`` bounds n * T."""
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    if o.shape != d.shape:
        raise ValueError(f"origins {o.shape} and directions {d.shape} differ in shape")
    vtx = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    a = vtx[tri[:, 0]]
    e1, e2 = vtx[tri[:, 1]] - a, vtx[tri[:, 2]] - a
    rows = max(1, chunk // max(len(tri), 1))
    for s in range(0, len(o), rows):
        oo, dd = o[s:s + rows, None, :], d[s:s + rows, None, :]
        p = np.cross(dd, e2[None])
        det = np.einsum("nti,ti->nt", p, e1)
        ok = np.abs(det) > det_eps
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tv = oo - a[None]
        u = np.einsum("nti,nti->nt", tv, p) * inv
        q = np.cross(tv, e1[None])
        v = np.einsum("nti,nti->nt", np.broadcast_to(dd, q.shape), q) * inv
        t = np.einsum("ti,nti->nt", e2, q) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > t_min) & (t < t_max)
        yield slice(s, s + len(oo)), hit, t, u, v


def ray_hit_counts(origins: np.ndarray, directions: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                   t_min: float = 1e-4, t_max: float = np.inf, chunk: int = 2_000_000) -> np.ndarray:
    """(N,) number of triangles each ray crosses (for inside/outside parity and occlusion tests)."""
    counts = np.zeros(len(np.asarray(origins).reshape(-1, 3)), np.int64)
    for rows, hit, *_ in ray_triangle_blocks(origins, directions, vertices, triangles, t_min, t_max, chunk=chunk):
        counts[rows] = hit.sum(1)
    return counts


def first_hits(origins: np.ndarray, directions: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
               t_min: float = 0.0, t_max: float = np.inf, farthest: bool = False,
               chunk: int = 2_000_000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest (or, with ``farthest``, the last) crossing of each ray: (triangle (N,) int64,
    barycentric (N, 3), t (N,)). Rays that hit nothing get triangle -1, barycentric 0 and
    t = inf. Ties go to the lowest triangle index."""
    n = len(np.asarray(origins).reshape(-1, 3))
    tri = np.full(n, -1, np.int64)
    bary = np.zeros((n, 3))
    tt = np.full(n, np.inf)
    if len(np.asarray(triangles).reshape(-1, 3)) == 0:
        return tri, bary, tt
    for rows, hit, t, u, v in ray_triangle_blocks(origins, directions, vertices, triangles, t_min, t_max, chunk=chunk):
        k = np.argmax(np.where(hit, t, -np.inf), axis=1) if farthest else np.argmin(np.where(hit, t, np.inf), axis=1)
        r = np.arange(len(k))
        found = hit[r, k]
        uk, vk = u[r, k], v[r, k]
        tri[rows] = np.where(found, k, -1)
        bary[rows] = np.where(found[:, None], np.stack([1 - uk - vk, uk, vk], 1), 0.0)
        tt[rows] = np.where(found, t[r, k], np.inf)
    return tri, bary, tt
