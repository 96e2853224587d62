"""Ray-triangle intersection: brute force (Möller-Trumbore) and, for many rays along one
axis, a grid of the projected triangles (:class:`RayGrid`).

The brute-force functions are meant for tens to a few thousand rays against meshes of up to ~100k triangles (landmark
placement, region rules): every ray is tested against every triangle, in blocks of rays so
that memory stays bounded. A ray is ``o + t d`` with ``t_min < t < t_max`` (``d`` need not be
unit length; ``t`` is in units of ``|d|``). A triangle counts as hit when the barycentric
coordinates of the crossing are all >= 0 (edges and corners included), and never when the
ray is parallel to its plane (``|det| <= det_eps``, which also skips zero-area triangles).
A ray running exactly along an edge shared by two triangles (a ray in a symmetric mesh's
midline plane, along its midline edges) can get a barycentric coordinate of -1e-15 in both, from
rounding, and slip between them; ``edge_eps`` (> 0) accepts coordinates down to ``-edge_eps``, so
such a ray hits the nearer of the two (and the ties rule picks one).

:class:`RayGrid` answers lines along one fixed axis (thousands of points against a whole
head, many times per fit): the triangles are projected on the plane normal to the axis and
binned in a 2D grid, so each line is tested only against the triangles of its cell.
Crossing parities (inside/outside) stay right where a surface folds over itself. A crossing
counts where the line meets a triangle's interior or edges, but not its corners 0 and 1
(corner 2 counts): a line exactly through an edge shared by two triangles counts twice and
one through a shared vertex once per triangle having it as corner 2, so parity is only
reliable for lines that miss edges and vertices, as lines through points in general position
(the fitting's) do.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

DET_EPS = 1e-15


def ray_triangle_blocks(origins: np.ndarray, directions: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                        t_min: float = 0.0, t_max: float = np.inf, det_eps: float = DET_EPS,
                        chunk: int = 2_000_000, edge_eps: float = 0.0) -> Iterator[tuple[slice, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
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
        hit = ok & (u >= -edge_eps) & (v >= -edge_eps) & (u + v <= 1 + edge_eps) & (t > t_min) & (t < t_max)
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
               chunk: int = 2_000_000, edge_eps: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest (or, with ``farthest``, the last) crossing of each ray: (triangle (N,) int64,
    barycentric (N, 3), t (N,)). Rays that hit nothing get triangle -1, barycentric 0 and
    t = inf. Ties go to the lowest triangle index. ``edge_eps``: see the module docstring (the
    barycentric weights of a hit within it of an edge are clipped to >= 0 and summed to 1)."""
    n = len(np.asarray(origins).reshape(-1, 3))
    tri = np.full(n, -1, np.int64)
    bary = np.zeros((n, 3))
    tt = np.full(n, np.inf)
    if len(np.asarray(triangles).reshape(-1, 3)) == 0:
        return tri, bary, tt
    for rows, hit, t, u, v in ray_triangle_blocks(origins, directions, vertices, triangles, t_min, t_max,
                                                  chunk=chunk, edge_eps=edge_eps):
        k = np.argmax(np.where(hit, t, -np.inf), axis=1) if farthest else np.argmin(np.where(hit, t, np.inf), axis=1)
        r = np.arange(len(k))
        found = hit[r, k]
        uk, vk = u[r, k], v[r, k]
        tri[rows] = np.where(found, k, -1)
        bary[rows] = np.where(found[:, None], np.stack([1 - uk - vk, uk, vk], 1), 0.0)
        tt[rows] = np.where(found, t[r, k], np.inf)
    if edge_eps > 0.0:
        bary = np.maximum(bary, 0.0)
        bary /= np.maximum(bary.sum(1, keepdims=True), 1e-300)
    return tri, bary, tt


class RayGrid:
    """Rays along one axis against a triangle mesh, through a 2D grid of the projected triangles.

    ``hits(P)`` gives, per point, the signed ray parameters ``t`` (along ``axis``) of every
    crossing of the line through the point (NaN padded). Parity of the crossings on one side
    decides inside/outside robustly even where the surface folds over itself (a fold adds two
    crossings) or is open elsewhere.
    """

    def __init__(self, vertices, triangles, axis, cell: float = 0.002):
        V = np.asarray(vertices, np.float64)
        F = np.asarray(triangles, np.int64)
        d = np.asarray(axis, np.float64)
        d = d / np.linalg.norm(d)
        e1 = np.cross(d, [0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.cross(d, [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(d, e1)
        self.d, self.E = d, np.stack([e1, e2])
        p2 = V @ self.E.T
        self.tri2 = p2[F]  # (T, 3, 2)
        self.depth = (V @ d)[F]  # (T, 3)
        self.cell = cell
        lo = self.tri2.min(1)
        hi = self.tri2.max(1)
        self.origin = lo.min(0) - cell
        i0 = np.floor((lo - self.origin) / cell).astype(np.int64)
        i1 = np.floor((hi - self.origin) / cell).astype(np.int64)
        self.shape = (int(i1[:, 0].max()) + 2, int(i1[:, 1].max()) + 2)
        ni, nj = i1[:, 0] - i0[:, 0] + 1, i1[:, 1] - i0[:, 1] + 1
        cnt = ni * nj
        tid = np.repeat(np.arange(len(F)), cnt)
        loc = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ci = i0[tid, 0] + loc % ni[tid]
        cj = i0[tid, 1] + loc // ni[tid]
        cid = ci * self.shape[1] + cj
        order = np.argsort(cid, kind="stable")
        cid, tid = cid[order], tid[order]
        counts = np.bincount(cid, minlength=self.shape[0] * self.shape[1])
        mx = max(1, int(counts.max()))
        start = np.cumsum(counts) - counts
        pos = np.arange(len(cid)) - start[cid]
        table = np.full((self.shape[0] * self.shape[1], mx), -1, np.int64)
        table[cid, pos] = tid
        self.table = table
        self.counts = counts

    def hits(self, P):
        P = np.asarray(P, np.float64).reshape(-1, 3)
        q = P @ self.E.T
        ij = np.floor((q - self.origin) / self.cell).astype(np.int64)
        ok = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < self.shape[0]) & (ij[:, 1] < self.shape[1])
        cid = np.where(ok, ij[:, 0] * self.shape[1] + ij[:, 1], 0)
        cnt = np.where(ok, self.counts[cid], 0)
        out = np.full((len(P), max(1, int(cnt.max(initial=0)))), np.nan)
        order = np.argsort(cnt, kind="stable")
        pd = P @ self.d
        for g in range(0, len(P), 256):  # groups of similar candidate counts: little padding
            idx = order[g:g + 256]
            w = int(cnt[idx].max(initial=0))
            if w == 0:
                continue
            cand = self.table[cid[idx], :w]
            cand = np.where(ok[idx, None], cand, -1)
            tri = self.tri2[np.maximum(cand, 0)]
            a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
            x = q[idx, None, :]
            v0, v1, v2 = b - a, c - a, x - a
            den = v0[..., 0] * v1[..., 1] - v1[..., 0] * v0[..., 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                bb = (v2[..., 0] * v1[..., 1] - v1[..., 0] * v2[..., 1]) / den
                cc = (v0[..., 0] * v2[..., 1] - v2[..., 0] * v0[..., 1]) / den
                aa = 1.0 - bb - cc
            valid = (cand >= 0) & (den != 0)
            # interior and edges count, corners 0 and 1 do not (see the module docstring)
            inside = valid & (aa >= 0) & (bb >= 0) & (cc > 0) | valid & (aa > 0) & (bb > 0) & (cc == 0)
            dep = self.depth[np.maximum(cand, 0)]
            t = aa * dep[..., 0] + bb * dep[..., 1] + cc * dep[..., 2] - pd[idx, None]
            out[idx, :w] = np.where(inside, t, np.nan)
        return out

    def inside(self, P, direction: float = 1.0):
        """Odd number of crossings on the ``direction`` side of each point (+1: along axis)."""
        t = self.hits(P)
        n = np.sum(np.nan_to_num(t * direction, nan=-1.0) > 0, axis=1)
        return n % 2 == 1

    def first_hit(self, P, direction: float = 1.0):
        t = self.hits(P) * direction
        t = np.where(t > 0, t, np.inf)
        return t.min(1) if t.shape[1] else np.full(len(t), np.inf)
