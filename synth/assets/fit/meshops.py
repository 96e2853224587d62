"""Mesh operations for the fitted shells (garments, headwear), pure numpy.

* ``smoothstep``, ``smooth_max`` / ``smooth_min`` (rounded corners of fields; unit vectors and normals come from :mod:`synth.geometry.normals`);
* :func:`clip_by_field` cuts a triangle set at the zero level of a per-vertex scalar field
  (neckline, cap plane...) exactly, returning new vertices as sparse linear combinations of
  body vertices (``W``, a scipy CSR matrix), so a shell is ``W @ V + offset * normal``;
  :func:`subdivide` refines such a combination mesh;
* boundary loops, Laplacian smoothing, face removal, grid faces, swept tubes, an icosphere,
  loop resampling and level-set points.

Conventions: float64 world metres, Z up, the face looks toward -Y.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from synth.geometry.normals import normalize


def smooth_max(a, b, k: float):
    """max(a, b) with the corner rounded over about ``k`` (same units): a hyperbola that is
    never below the maximum and at most k/2 above it (where a == b)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return 0.5 * (a + b + np.sqrt((a - b) ** 2 + k * k))


def smooth_min(a, b, k: float):
    """min(a, b) rounded over about ``k`` (:func:`smooth_max` mirrored)."""
    return -smooth_max(-np.asarray(a, np.float64), -np.asarray(b, np.float64), k)


def clip_by_field(F: np.ndarray, f: np.ndarray, n_vertices: int):
    """Keep the part of triangles ``F`` where the per-vertex field ``f >= 0``, cut exactly at
    ``f == 0`` (linear along edges).

    Returns ``(W, faces, is_cut)``: ``W`` (M, n_vertices) CSR matrix whose rows give each new
    vertex as a combination of original vertices (one entry for kept vertices, two for cut
    points on edges), the new triangles (T', 3) indexing rows of ``W`` (orientation kept), and
    a bool (M,) marking points created on the cut."""
    F = np.asarray(F, np.int64)
    f = np.asarray(f, np.float64)
    pos = f[F] >= 0.0
    npos = pos.sum(1)
    keys: dict[tuple, int] = {}
    rows: list[tuple] = []

    def vid(i: int) -> int:
        key = (i, i)
        if key not in keys:
            keys[key] = len(rows)
            rows.append((i, i, 0.0))
        return keys[key]

    def eid(i: int, j: int) -> int:
        a, b = (i, j) if i < j else (j, i)
        key = (a, b)
        if key not in keys:
            fa, fb = f[a], f[b]
            t = fa / (fa - fb) if fa != fb else 0.5
            keys[key] = len(rows)
            rows.append((a, b, float(np.clip(t, 0.0, 1.0))))
        return keys[key]

    out = []
    for tri, p, c in zip(F.tolist(), pos.tolist(), npos.tolist()):
        if c == 0:
            continue
        if c == 3:
            out.append((vid(tri[0]), vid(tri[1]), vid(tri[2])))
            continue
        # rotate so the odd vertex is first
        odd = p.index(True) if c == 1 else p.index(False)
        a, b, d = tri[odd], tri[(odd + 1) % 3], tri[(odd + 2) % 3]
        if c == 1:  # keep the corner at a
            out.append((vid(a), eid(a, b), eid(a, d)))
        else:  # drop corner a: quad b, d, (d,a), (a,b)
            ab, ad = eid(a, b), eid(a, d)
            out.append((ab, vid(b), vid(d)))
            out.append((ab, vid(d), ad))
    M = len(rows)
    r = np.array(rows, np.float64).reshape(-1, 3)
    i, j, t = r[:, 0].astype(np.int64), r[:, 1].astype(np.int64), r[:, 2]
    cut = i != j
    ri = np.concatenate([np.arange(M), np.arange(M)[cut]])
    ci = np.concatenate([i, j[cut]])
    vals = np.concatenate([np.where(cut, 1.0 - t, 1.0), t[cut]])
    W = sparse.csr_matrix((vals, (ri, ci)), shape=(M, n_vertices))
    faces = np.array(out, np.int64).reshape(-1, 3)
    return W, faces, cut


def negative_regions(F: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(V,) label of the connected region of ``f < 0`` (over the edges of ``F``) of every vertex
    (a vertex with ``f >= 0`` is a region of its own)."""
    from scipy.sparse.csgraph import connected_components

    F = np.asarray(F, np.int64)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    neg = np.asarray(f) < 0
    E = E[neg[E[:, 0]] & neg[E[:, 1]]]
    n = len(neg)
    A = sparse.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    return connected_components(A, directed=False)[1]


def subdivide(W, faces: np.ndarray, is_cut: np.ndarray | None = None):
    """1-to-4 midpoint subdivision of a combination mesh (rows of W are averaged)."""
    faces = np.asarray(faces, np.int64)
    M = W.shape[0]
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    inv = inv.ravel()
    T = len(faces)
    m01, m12, m20 = (M + inv[:T], M + inv[T:2 * T], M + inv[2 * T:])
    a, b, c = faces.T
    nf = np.concatenate([np.stack([a, m01, m20], 1), np.stack([m01, b, m12], 1),
                         np.stack([m20, m12, c], 1), np.stack([m01, m12, m20], 1)])
    W2, cut2 = _with_midpoints(W, is_cut, uniq)
    return W2, nf, cut2


def _with_midpoints(W, is_cut: np.ndarray | None, edges: np.ndarray):
    """``W`` with one row more per edge (the mean of its two vertices' rows), and the cut flags
    extended (a midpoint is cut where both its ends are)."""
    E, M = len(edges), W.shape[0]
    avg = sparse.csr_matrix((np.full(2 * E, 0.5), (np.repeat(np.arange(E), 2), edges.ravel())), shape=(E, M))
    W2 = sparse.vstack([W, avg @ W]).tocsr()
    cut2 = None if is_cut is None else np.concatenate([is_cut, is_cut[edges[:, 0]] & is_cut[edges[:, 1]]])
    return W2, cut2


def subdivide_where(W, faces: np.ndarray, is_cut: np.ndarray | None, refine: np.ndarray):
    """Midpoint subdivision of the faces marked in ``refine`` only (1-to-4), kept conforming: a face
    with two or three of its edges split is refined too (repeated until none is left), and a face
    with one split edge is halved through it (1-to-2). With every face marked this is
    :func:`subdivide`'s mesh (its vertices in another order)."""
    faces = np.asarray(faces, np.int64)
    refine = np.array(refine, bool, copy=True)
    M = W.shape[0]
    T = len(faces)
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    inv = inv.ravel().reshape(3, T)  # edge of (a, b), (b, c), (c, a) per face
    split = np.zeros(len(uniq), bool)
    while True:
        split[inv[:, refine].ravel()] = True
        grow = ~refine & (split[inv].sum(0) >= 2)
        if not grow.any():
            break
        refine |= grow
    ids = np.full(len(uniq), -1, np.int64)
    ids[split] = M + np.arange(int(split.sum()))
    a, b, c = faces.T
    m01, m12, m20 = ids[inv[0]], ids[inv[1]], ids[inv[2]]
    cnt = split[inv].sum(0)
    out = [faces[cnt == 0]]
    r = refine
    out += [np.stack([a[r], m01[r], m20[r]], 1), np.stack([m01[r], b[r], m12[r]], 1),
            np.stack([m20[r], m12[r], c[r]], 1), np.stack([m01[r], m12[r], m20[r]], 1)]
    one = cnt == 1
    for k, (x, y, z, m) in enumerate(((a, b, c, m01), (b, c, a, m12), (c, a, b, m20))):
        h = one & split[inv[k]]
        out += [np.stack([x[h], m[h], z[h]], 1), np.stack([m[h], y[h], z[h]], 1)]
    nf = np.concatenate(out)
    W2, cut2 = _with_midpoints(W, is_cut, uniq[split])
    return W2, nf, cut2


def oriented_boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary vertex loops of a triangle mesh (manifold boundaries), each in the direction of its
    half-edges (so a loop's order says which side the mesh is on). :func:`synth.model.meshutil.boundary_loops`
    is the unoriented one (non-manifold boundaries split, longest first)."""
    faces = np.asarray(faces, np.int64)
    he = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = he[:, 0] * (he.max() + 1) + he[:, 1]
    rkey = he[:, 1] * (he.max() + 1) + he[:, 0]
    bd = he[~np.isin(key, rkey)]
    nxt: dict[int, int] = {}
    for a, b in bd.tolist():
        nxt.setdefault(a, b)
    loops, seen = [], set()
    for start in sorted(nxt):
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen and v in nxt:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        if len(loop) >= 3:
            loops.append(np.array(loop, np.int64))
    return loops


def laplacian_smooth(P: np.ndarray, faces: np.ndarray, iterations: int = 5, lam: float = 0.5,
                     pinned: np.ndarray | None = None) -> np.ndarray:
    """Uniform Laplacian smoothing (umbrella operator); ``pinned`` vertices do not move."""
    P = np.array(P, np.float64, copy=True)
    n = len(P)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, 1), axis=0)
    A = sparse.csr_matrix((np.ones(2 * len(e)), (np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]]))),
                          shape=(n, n))
    deg = np.asarray(A.sum(1)).ravel()
    deg[deg == 0] = 1.0
    move = np.ones(n, bool) if pinned is None else ~np.asarray(pinned, bool)
    for _ in range(iterations):
        avg = (A @ P) / deg[:, None]
        P[move] += lam * (avg[move] - P[move])
    return P


def remove_faces(P: np.ndarray, faces: np.ndarray, keep_face: np.ndarray):
    """Drop faces; compact the vertices. Returns (P', faces', old index of each kept vertex)."""
    f = faces[keep_face]
    used = np.unique(f)
    remap = np.full(len(P), -1, np.int64)
    remap[used] = np.arange(len(used))
    return P[used], remap[f], used


def grid_faces(nu: int, nv: int, closed_u: bool = False) -> np.ndarray:
    """Triangles of an (nu x nv) vertex grid indexed u * nv + v (u may wrap around)."""
    us = nu if closed_u else nu - 1
    u = np.arange(us)[:, None]
    v = np.arange(nv - 1)[None, :]
    a = u * nv + v
    b = ((u + 1) % nu) * nv + v
    quads = np.stack([a, b, b + 1, a + 1], -1).reshape(-1, 4)
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def sweep_tube(path: np.ndarray, radius, n_sides: int = 10, closed: bool = False, flatten: float = 1.0,
               up_hint: np.ndarray | None = None):
    """Tube along a polyline. ``radius`` scalar or per-point; ``flatten`` scales the section
    along ``tangent x up_hint`` (horizontal for a horizontal path: the radial thickness of a
    scarf or a flat tail), giving an elliptical section.
    Returns (vertices (N*n_sides, 3), faces); open tubes get capped ends."""
    path = np.asarray(path, np.float64)
    N = len(path)
    r = np.broadcast_to(np.asarray(radius, np.float64), (N,))
    if closed:
        tan = normalize(np.roll(path, -1, 0) - np.roll(path, 1, 0))
    else:
        tan = normalize(np.gradient(path, axis=0))
    up = np.array([0.0, 0.0, 1.0]) if up_hint is None else np.asarray(up_hint, np.float64)
    # parallel-ish frames from a fixed hint, with a fallback where the tangent is parallel to it
    nrm = np.cross(tan, up)
    bad = np.linalg.norm(nrm, axis=1) < 1e-6
    nrm[bad] = np.cross(tan[bad], [1.0, 0.0, 0.0])
    nrm = normalize(nrm)
    bin_ = normalize(np.cross(nrm, tan))
    ang = np.linspace(0.0, 2.0 * np.pi, n_sides, endpoint=False)
    ring = (flatten * np.cos(ang)[None, :, None] * nrm[:, None, :] + np.sin(ang)[None, :, None] * bin_[:, None, :])
    Vt = (path[:, None, :] + r[:, None, None] * ring).reshape(-1, 3)
    faces = grid_faces(n_sides, N, closed_u=True)  # u = side, v = along path
    # grid_faces indexes u * nv + v; our layout is v * n_sides + u -> remap
    u, v = np.divmod(faces, N)
    faces = v * n_sides + u
    if closed:
        extra = np.stack([(N - 1) * n_sides + np.arange(n_sides), (N - 1) * n_sides + (np.arange(n_sides) + 1) % n_sides,
                          (np.arange(n_sides) + 1) % n_sides, np.arange(n_sides)], 1)
        faces = np.concatenate([faces, extra[:, [0, 1, 2]], extra[:, [0, 2, 3]]])
    else:
        c0, c1 = len(Vt), len(Vt) + 1
        Vt = np.concatenate([Vt, path[:1], path[-1:]])
        k = np.arange(n_sides)
        cap0 = np.stack([np.full(n_sides, c0), (k + 1) % n_sides, k], 1)
        cap1 = np.stack([np.full(n_sides, c1), (N - 1) * n_sides + k, (N - 1) * n_sides + (k + 1) % n_sides], 1)
        faces = np.concatenate([faces, cap0, cap1])
    return Vt, faces.astype(np.int64)


def icosphere(subdivisions: int = 2):
    """Unit icosphere (vertices, faces)."""
    t = (1.0 + 5 ** 0.5) / 2.0
    V = normalize(np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
                            [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], np.float64))
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], np.int64)
    for _ in range(subdivisions):
        W = sparse.identity(len(V), format="csr")
        W, F, _ = subdivide(W, F)
        V = normalize(np.asarray(W @ V))
    return V, F


def resample_loop(P: np.ndarray, center: np.ndarray, n: int, angle0: float = 0.0):
    """Resample a closed loop around a vertical axis through ``center`` at ``n`` equal angles
    (angle measured from -Y toward +X, as ``atan2(x, -y)``). Returns (n, 3)."""
    d = P - center
    th = np.arctan2(d[:, 0], -d[:, 1])
    o = np.argsort(th)
    th, Q = th[o], P[o]
    th_ext = np.concatenate([th - 2 * np.pi, th, th + 2 * np.pi])
    Q_ext = np.concatenate([Q, Q, Q])
    want = angle0 + np.linspace(-np.pi, np.pi, n, endpoint=False)
    want = (want + np.pi) % (2 * np.pi) - np.pi
    return np.stack([np.interp(want, th_ext, Q_ext[:, k]) for k in range(3)], 1)


def level_points(V: np.ndarray, F: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Points where the per-vertex field crosses zero on the edges of ``F`` (unordered)."""
    e = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)
    fa, fb = f[e[:, 0]], f[e[:, 1]]
    s = (fa < 0) != (fb < 0)
    t = (fa[s] / (fa[s] - fb[s]))[:, None]
    return V[e[s, 0]] * (1 - t) + V[e[s, 1]] * t
