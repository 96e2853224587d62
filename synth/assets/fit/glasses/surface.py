"""Signed distance to an open triangle mesh and parity rays (the glasses' contact queries).

:class:`Surface`: closest point on the surface, signed by the angle-weighted pseudo-normal of
the closest feature (face, edge or vertex; Baerentzen & Aanaes 2005), exact for closed meshes
and well behaved near an open one. :class:`RayGrid`: crossings of lines along one axis with
the mesh through a 2D grid of projected triangles; the parity of the crossings decides
inside/outside where the head folds over itself. Both are geometry and belong in
``synth/geometry/`` when that package exists (issue 9, item 4).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from synth.assets.fit.closest import closest_on_triangles, dot


class Surface:
    """Signed-distance queries against a triangle mesh (open meshes allowed)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, k: int = 24):
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(triangles, np.int64)
        self.k = int(k)
        V, F = self.V, self.F
        a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
        n = np.cross(b - a, c - a)
        ln = np.linalg.norm(n, axis=1, keepdims=True)
        self.face_normals = n / np.maximum(ln, 1e-30)
        # angle-weighted vertex pseudo-normals
        vn = np.zeros_like(V)
        for i in range(3):
            p0, p1, p2 = V[F[:, i]], V[F[:, (i + 1) % 3]], V[F[:, (i + 2) % 3]]
            u, w = p1 - p0, p2 - p0
            cosang = dot(u, w) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-30)
            ang = np.arccos(np.clip(cosang, -1.0, 1.0))
            np.add.at(vn, F[:, i], self.face_normals * ang[:, None])
        self.vertex_normals = vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)
        # edge pseudo-normals: edge opposite local vertex j of face f
        keys = np.stack([np.sort(np.stack([F[:, (j + 1) % 3], F[:, (j + 2) % 3]], 1), 1) for j in range(3)], 1)
        flat = keys.reshape(-1, 2)
        uniq, inv = np.unique(flat, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        en = np.zeros((len(uniq), 3))
        np.add.at(en, inv, np.repeat(self.face_normals, 3, axis=0))
        en /= np.maximum(np.linalg.norm(en, axis=1, keepdims=True), 1e-30)
        self.edge_of_face = inv.reshape(-1, 3)
        self.edge_normals = en
        # candidate faces come from the k nearest face centroids (a face's centroid is within
        # its circumradius of every point of it; k = 16 covers the mesh's size variation)
        self.tree = cKDTree((a + b + c) / 3.0)

    def query(self, points: np.ndarray, chunk: int = 4096):
        """Closest points, unsigned and signed distances, pseudo-normals, closest faces."""
        P = np.asarray(points, np.float64).reshape(-1, 3)
        outs = [self._query(P[i:i + chunk]) for i in range(0, len(P), chunk)] or [self._query(P)]
        return tuple(np.concatenate([o[i] for o in outs]) for i in range(5))

    def _query(self, P):
        k = min(self.k, len(self.F))
        _, cand = self.tree.query(P, k=k)
        cand = np.asarray(cand).reshape(len(P), -1)
        tri = self.F[cand]
        q, bary = closest_on_triangles(P[:, None, :], self.V[tri[..., 0]], self.V[tri[..., 1]],
                                             self.V[tri[..., 2]])
        d2 = ((q - P[:, None, :]) ** 2).sum(-1)
        best = np.argmin(d2, axis=1)
        r = np.arange(len(P))
        face = cand[r, best]
        cp = q[r, best]
        bc = bary[r, best]
        dist = np.sqrt(d2[r, best])
        nz = bc > 1e-12
        cnt = nz.sum(1)
        normal = self.face_normals[face].copy()
        # edge: the zero coordinate's local index names the opposite edge
        e = cnt == 2
        if e.any():
            j = np.argmin(np.where(nz[e], 1, 0), axis=1)
            normal[e] = self.edge_normals[self.edge_of_face[face[e], j]]
        v = cnt == 1
        if v.any():
            j = np.argmax(bc[v], axis=1)
            normal[v] = self.vertex_normals[self.F[face[v], j]]
        side = np.sign(dot(P - cp, normal))
        side = np.where(side == 0, 1.0, side)
        return cp, dist, dist * side, normal, face

    def signed_distance(self, points):
        return self.query(points)[2]

    def push_out(self, points, clearance, iterations: int = 6):
        """Move points along the surface normal until their signed distance is >= clearance."""
        P = np.array(points, np.float64).reshape(-1, 3)
        clearance = np.broadcast_to(np.asarray(clearance, np.float64), (len(P),))
        for _ in range(iterations):
            cp, dist, sd, n, _ = self.query(P)
            short = sd < clearance - 1e-7
            if not short.any():
                break
            # direction: away from the closest point (outside) or along the pseudo-normal (inside)
            d = np.where((sd > 1e-6)[:, None], (P - cp) / np.maximum(dist, 1e-12)[:, None], n)
            P[short] = cp[short] + d[short] * clearance[short, None]
        return P


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
            # half-open edge rule so a ray through a shared edge counts once (up to round-off)
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
