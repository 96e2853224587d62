"""General mesh utilities (numpy/scipy, no Blender): sphere fit, farthest-point sampling,
connectivity, boundaries, vertex-to-triangle landmarks, 2-D polygons. Rotations and rigid
fits, normals and ray casting live in :mod:`synth.geometry`.

Every function is deterministic (no random numbers) and works on plain arrays:
``vertices`` (V, 3) float, ``triangles`` (T, 3) int. Nothing here knows about a specific
head model; importers and builders combine these with their own rules.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components as _cc
from scipy.spatial import cKDTree

from synth.geometry.closest import nearest_on_candidates


# --------------------------------------------------------------------------- fitting

def fit_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares sphere through ``points`` (N >= 4, not coplanar): (centre (3,), radius).

    Algebraic fit: |p|^2 = 2 c.p + (r^2 - |c|^2) is linear in (c, r^2 - |c|^2), solved in
    float64 after centring the points for conditioning. The centre is a smooth function
    of the points, so small per-vertex offsets give (nearly) linear centre offsets.
    """
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 4:
        raise ValueError("fit_sphere needs (N >= 4, 3) points")
    mu = p.mean(0)
    q = p - mu
    A = np.c_[2.0 * q, np.ones(len(q))]
    b = np.einsum("ij,ij->i", q, q)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    c = x[:3]
    r = float(np.sqrt(max(x[3] + c @ c, 0.0)))
    return c + mu, r


def fit_sphere_robust(points: np.ndarray, trim_sigma: float = 2.0,
                      iters: int = 2) -> tuple[np.ndarray, float, np.ndarray]:
    """:func:`fit_sphere`, then refit on the points whose radial residual is within
    ``trim_sigma`` standard deviations (drops bulges such as a cornea). Returns
    (centre, radius, mask of the points kept). The mask is fixed after the first call,
    so refitting the same vertex subset of a deformed mesh is a smooth function."""
    p = np.asarray(points, np.float64)
    keep = np.ones(len(p), bool)
    c, r = fit_sphere(p)
    for _ in range(iters):
        res = np.linalg.norm(p - c, axis=1) - r
        s = res[keep].std()
        new = np.abs(res) <= trim_sigma * max(s, 1e-12)
        if new.sum() < 4 or np.array_equal(new, keep):
            break
        keep = new
        c, r = fit_sphere(p[keep])
    return c, r, keep


# --------------------------------------------------------------------------- sampling

def farthest_point_sampling(points: np.ndarray, n: int, start: int = 0, tie_m: float = 0.0) -> np.ndarray:
    """Indices of ``n`` points picked greedily, each farthest (Euclidean) from those picked
    so far, starting at index ``start``. Deterministic: points within ``tie_m`` (m) of the
    farthest distance tie, and ties go to the lowest index (a positive ``tie_m`` keeps the
    picks the same under rounding noise of the points, e.g. on a mirror-symmetric mesh)."""
    p = np.asarray(points, np.float64)
    n = int(min(n, len(p)))
    out = np.empty(n, np.int64)
    if n == 0:
        return out
    out[0] = start
    d = np.sum((p - p[start]) ** 2, axis=1)
    for i in range(1, n):
        j = int(np.argmax(d))
        if tie_m > 0.0:
            j = int(np.argmax(np.sqrt(d) >= np.sqrt(d[j]) - tie_m))
        out[i] = j
        np.minimum(d, np.sum((p - p[j]) ** 2, axis=1), out=d)
    return out


# --------------------------------------------------------------------------- connectivity

def polygon_edges(poly_offsets: np.ndarray, poly_indices: np.ndarray) -> np.ndarray:
    """(N, 2) directed edges of polygons given as offsets/indices (each polygon closed)."""
    off = np.asarray(poly_offsets, np.int64)
    idx = np.asarray(poly_indices, np.int64)
    nxt = np.arange(len(idx)) + 1
    last = off[1:] - 1
    nxt[last] = off[:-1]
    return np.stack([idx, idx[nxt]], axis=1)


def triangle_edges(triangles: np.ndarray) -> np.ndarray:
    t = np.asarray(triangles, np.int64)
    return np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])


def adjacency(edges: np.ndarray, n: int) -> sp.csr_matrix:
    """Symmetric (n, n) 0/1 vertex adjacency from (E, 2) edges."""
    e = np.asarray(edges, np.int64)
    A = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()
    A.data[:] = 1.0
    return A


def connected_components(edges: np.ndarray, n: int, subset: np.ndarray | None = None) -> np.ndarray:
    """(n,) component label per vertex. With ``subset`` (vertex indices), only edges with
    both ends in the subset count; vertices outside get label -1."""
    e = np.asarray(edges, np.int64)
    if subset is not None:
        m = np.zeros(n, bool)
        m[subset] = True
        e = e[m[e[:, 0]] & m[e[:, 1]]]
    _, lab = _cc(adjacency(e, n), directed=False)
    if subset is not None:
        out = np.full(n, -1, np.int64)
        _, inv = np.unique(lab[subset], return_inverse=True)
        out[subset] = inv
        return out
    return lab


def boundary_edges(triangles: np.ndarray) -> np.ndarray:
    """(B, 2) edges used by exactly one triangle (oriented as in that triangle)."""
    e = triangle_edges(triangles)
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return e[cnt[inv.ravel()] == 1]


def boundary_loops(triangles: np.ndarray) -> list[np.ndarray]:
    """Boundary edges chained into vertex loops (each an ordered index array), longest first.
    Non-manifold boundaries are split where a vertex has several outgoing edges."""
    b = boundary_edges(triangles)
    nxt: dict[int, int] = {}
    for a, c in b.tolist():
        nxt.setdefault(a, c)
    loops = []
    seen: set[int] = set()
    for s in sorted(nxt):
        if s in seen:
            continue
        loop = [s]
        seen.add(s)
        v = nxt[s]
        while v != s and v in nxt and v not in seen:
            loop.append(v)
            seen.add(v)
            v = nxt[v]
        loops.append(np.asarray(loop, np.int64))
    loops.sort(key=len, reverse=True)
    return loops


# --------------------------------------------------------------------------- landmarks

def vertex_landmarks(triangles: np.ndarray, vertex_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Landmarks on vertices as (triangle (L,) int32, one-hot barycentric (L, 3) float32):
    for each vertex the lowest-numbered triangle containing it."""
    t = np.asarray(triangles, np.int64)
    vid = np.asarray(vertex_ids, np.int64)
    flat = t.ravel()
    order = np.argsort(flat, kind="stable")
    first = np.searchsorted(flat[order], vid)
    if np.any(first >= len(flat)) or np.any(flat[order][np.minimum(first, len(flat) - 1)] != vid):
        missing = vid[(first >= len(flat)) | (flat[order][np.minimum(first, len(flat) - 1)] != vid)]
        raise ValueError(f"vertices {missing[:5].tolist()} are in no triangle")
    pos = order[first]
    tri = pos // 3
    bary = np.zeros((len(vid), 3), np.float32)
    bary[np.arange(len(vid)), pos % 3] = 1.0
    return tri.astype(np.int32), bary


def barycentric_points(vertices: np.ndarray, triangles: np.ndarray, tri: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(L, 3) positions of barycentric landmarks."""
    return np.einsum("lkc,lk->lc", np.asarray(vertices)[np.asarray(triangles)[tri]], bary)


def point_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """(N,) bool: 2-D points inside a closed polygon (M, 2) by the even-odd rule."""
    p = np.asarray(points, np.float64)
    poly = np.asarray(polygon, np.float64)
    x, y = p[:, 0:1], p[:, 1:2]
    x0, y0 = poly[:, 0][None], poly[:, 1][None]
    x1, y1 = np.roll(poly[:, 0], -1)[None], np.roll(poly[:, 1], -1)[None]
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return (np.sum(crosses & (x < xint), axis=1) % 2) == 1


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """(H, 2) convex hull of 2-D points in counter-clockwise order (monotone chain)."""
    p = np.unique(np.asarray(points, np.float64), axis=0)
    if len(p) < 3:
        return p

    def half(pts):
        h: list[np.ndarray] = []
        for q in pts:
            while len(h) >= 2 and np.cross(h[-1] - h[-2], q - h[-2]) <= 0:
                h.pop()
            h.append(q)
        return h

    lower, upper = half(p), half(p[::-1])
    return np.asarray(lower[:-1] + upper[:-1])


def smoothstep(x, e0: float = 0.0, e1: float = 1.0) -> np.ndarray:
    """3t^2 - 2t^3 of t = (x - e0) / (e1 - e0) clamped to [0, 1]: 0 at e0, 1 at e1 (the one
    smoothstep of the project; with the default edges t is x itself, bit for bit)."""
    t = np.clip((np.asarray(x, np.float64) - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def mesh_mirror(template: np.ndarray, tris: np.ndarray, tol: float = 1e-6):
    """The left-right (x -> -x) mirror image of surface points (triangle, barycentric weights) of a
    mirror-symmetric mesh, as a function ``mirror(t (C,), bary (C, 3)) -> (t, bary)``. A triangle
    whose mirrored vertices form a triangle maps onto it exactly (the weights permuted); where a
    quad was split along the other diagonal on the mirror side, the mirrored point is moved onto
    the nearest triangle that shares a vertex with the mirrored ones (at most the quad's fold)."""
    flip = np.array([-1.0, 1.0, 1.0])
    d, vmap = cKDTree(template).query(template * flip)
    if d.max() > tol:
        raise ValueError(f"the mesh is not mirror-symmetric: a vertex lies {1000 * d.max():.3f} mm from the "
                         f"mirror image of its nearest vertex")
    index = {tuple(sorted(t)): i for i, t in enumerate(tris.tolist())}
    mirrored = vmap[tris]
    tmap = np.array([index.get(tuple(sorted(t)), -1) for t in mirrored.tolist()], np.int64)
    perm = np.argmax(tris[np.maximum(tmap, 0)][:, :, None] == mirrored[:, None, :], axis=2)

    def mirror(t: np.ndarray, bary: np.ndarray):
        mt = tmap[t].copy()
        mb = np.take_along_axis(bary, perm[t], axis=1)
        for i in np.nonzero(mt < 0)[0]:
            x = np.einsum("k,kd->d", bary[i], template[tris[t[i]]]) * flip
            near = np.nonzero(np.isin(tris, mirrored[t[i]]).any(axis=1))[0]
            hit = nearest_on_candidates(x[None], template, tris, near[None])
            mt[i], mb[i] = hit.face[0], hit.bary[0]
        return mt, mb

    return mirror


def mesh_midline(template: np.ndarray, tris: np.ndarray, tol: float = 1e-9):
    """Surface points moved onto the mesh's midline (its edges with both ends at x = 0), as a function
    ``snap(t (C,), bary (C, 3)) -> (t, bary)``: each point's nearest point on the midline edges (in
    the template), given in a triangle that holds the edge (the third weight zero)."""
    on = np.abs(template[:, 0]) <= tol
    half = triangle_edges(tris)
    keep = np.nonzero(on[half].all(axis=1))[0]
    if not len(keep):
        raise ValueError("the mesh has no edges on its midline (x = 0)")
    tri_of, slot = keep % len(tris), keep // len(tris)  # triangle_edges: corners (slot, slot + 1 mod 3)
    a, b = template[half[keep, 0]], template[half[keep, 1]]
    ab = b - a
    ab2 = np.maximum(np.einsum("ed,ed->e", ab, ab), 1e-300)

    def snap(t: np.ndarray, bary: np.ndarray):
        x = np.einsum("ck,ckd->cd", bary, template[tris[t]])
        s = np.clip(np.einsum("ced,ed->ce", x[:, None] - a[None], ab) / ab2, 0.0, 1.0)  # (C, E)
        d = np.linalg.norm(x[:, None] - (a[None] + s[..., None] * ab[None]), axis=-1)
        e = np.argmin(d, axis=1)
        w = np.zeros((len(t), 3))
        rows = np.arange(len(t))
        w[rows, slot[e]] = 1.0 - s[rows, e]
        w[rows, (slot[e] + 1) % 3] = s[rows, e]
        return tri_of[e], w

    return snap
