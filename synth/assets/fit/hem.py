"""The bust's cut, hidden by the garment (pure numpy; the rig is ``blender_scripts/assets/garment.py``).

The default bust ends in an open boundary cut along mesh edges: a zig-zag (median turning angle
~80 degrees between consecutive edges) across the chest, the back and the arm stumps. A garment
that simply followed the bust's skin ended on that zig-zag (sawtooth arm cuts), and from below
(cameras go down to -45 degrees elevation) one looked past its edge at the bust's skin.

Every garment now ends on a **hem**: the level set ``cut_distance == HEM_MARGIN`` of a smooth
field on the body, the distance from the bust's open boundary (Euclidean, to the boundary
polyline, but never under :data:`GEODESIC_SHARE` of the distance along the mesh's edges: an elbow
hanging beside the waist is near the cut in space, not on the body) smoothed on the mesh with the
cut held at 0, so the hem runs parallel to the cut, ``HEM_MARGIN`` above it, without its zig-zag.
Under the hem:

* the bust's skin faces (any vertex closer to the cut than the hem) are hidden at render time
  (:func:`hidden_polygons`; the rig gives them a transparent material outside every pass), and
* a **cap** of cloth closes the garment's hem loop (:func:`cap`), so that from below one sees
  the garment's underside, never the inside of the bust.
"""

from __future__ import annotations

import numpy as np

from synth.assets.fit.meshops import oriented_boundary_loops
from synth.geometry.normals import normalize

#: distance (m) from the bust's cut at which every garment ends
HEM_MARGIN = 0.025
#: smoothing passes of the distance field on the mesh (each averages a vertex with its neighbours)
FIELD_SMOOTHING = 12
#: smoothing passes of the hem polyline itself (along the loop, after the clip)
LOOP_SMOOTHING = 8
#: averaging passes between two respacings of a neckline loop (:func:`relax_loop`)
RELAX_ROUND = 4
#: the garment is kept this far (m of the hem field) above the hem whatever the neckline
HEM_BAND = 0.02
#: how far (m) the cap's rim sits inside the garment's hem edge (no coincident edges)
CAP_INSET = 0.0005
#: the cut distance is at least this share of the distance along the mesh's edges from the cut
#: (Dijkstra): on the torso the two agree to about 20 %, so the Euclidean distance rules there; an
#: elbow that hangs 1-3 cm beside the waist's cut is 30 cm and more from it along the body
GEODESIC_SHARE = 0.5


def cut_loop(F: np.ndarray, V: np.ndarray) -> np.ndarray:
    """The bust's open boundary: the lowest of the mesh's boundary loops (eyes and mouth leave
    smaller loops higher up). Vertex indices, in order."""
    loops = oriented_boundary_loops(F)
    if not loops:
        raise ValueError("the head mesh has no open boundary (no bust cut)")
    return min(loops, key=lambda lo: float(np.asarray(V)[lo, 2].mean()))


def _segment_distance(P: np.ndarray, A: np.ndarray, B: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """Distance from each point of P to the closest of the segments A[i]-B[i]."""
    out = np.empty(len(P))
    AB = B - A
    L2 = np.maximum((AB ** 2).sum(1), 1e-30)
    for s in range(0, len(P), chunk):
        p = P[s:s + chunk, None, :]
        t = np.clip(((p - A) * AB).sum(-1) / L2, 0.0, 1.0)
        d = p - (A + t[..., None] * AB)
        out[s:s + chunk] = np.sqrt((d ** 2).sum(-1).min(1))
    return out


def neighbour_mean_matrix(F: np.ndarray, n: int):
    """(n, n) sparse matrix averaging every vertex with its mesh neighbours (edges of F)."""
    import scipy.sparse as sp

    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    E = np.unique(np.sort(E, 1), axis=0)
    r = np.concatenate([E[:, 0], E[:, 1], np.arange(n)])
    c = np.concatenate([E[:, 1], E[:, 0], np.arange(n)])
    A = sp.csr_matrix((np.ones(len(r)), (r, c)), shape=(n, n))
    deg = np.asarray(A.sum(1)).ravel()
    return sp.diags(1.0 / deg) @ A


def edge_distance(V: np.ndarray, F: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """(V,) the shortest distance (m) along the mesh's edges from any of the ``sources`` vertices
    (Dijkstra; inf where no path leads)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    E = np.unique(np.sort(E, 1), axis=0)
    w = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    w = np.maximum(w, 1e-12)  # a zero-length edge stays an edge
    G = sp.csr_matrix((w, (E[:, 0], E[:, 1])), shape=(len(V), len(V)))
    return dijkstra(G, directed=False, indices=np.asarray(sources, np.int64), min_only=True)


def cut_distance(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(V,) smooth distance (m) of every vertex from the bust's cut (see the module docstring)."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    loop = cut_loop(F, V)
    g = edge_distance(V, F, loop)
    g = np.where(np.isfinite(g), g, 0.0)  # parts not joined to the cut (eyeballs, teeth): Euclidean
    d = np.maximum(_segment_distance(V, V[loop], V[np.roll(loop, -1)]), GEODESIC_SHARE * g)
    M = neighbour_mean_matrix(F, len(V))
    for _ in range(FIELD_SMOOTHING):
        d = M @ d
        d[loop] = 0.0  # the cut itself stays at distance 0
    return d


def hem_field(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Per-vertex field, >= 0 where a garment may be (above the hem)."""
    return cut_distance(V, F) - HEM_MARGIN


def hidden_polygons(V: np.ndarray, F: np.ndarray, poly_offsets: np.ndarray, poly_indices: np.ndarray) -> np.ndarray:
    """(P,) bool: the head polygons (CSR ``offsets``/``indices``) under the hem (any corner
    closer to the cut than ``HEM_MARGIN``); hidden at render time under a garment."""
    below = cut_distance(V, F) < HEM_MARGIN
    off = np.asarray(poly_offsets, np.int64)
    hit = below[np.asarray(poly_indices, np.int64)].astype(np.int64)
    return np.add.reduceat(hit, off[:-1]) > 0


def smooth_loops(P: np.ndarray, F: np.ndarray, on_cut: np.ndarray, iterations: int = LOOP_SMOOTHING,
                 min_fraction: float = 0.8, resample: bool = False) -> np.ndarray:
    """Smooth, along itself, every boundary loop of (P, F) that lies on a cut (at least
    ``min_fraction`` of its vertices marked in ``on_cut``; the hem: mostly true on the loop): the
    clip of a triangle mesh leaves tiny edges where the level set passes near a vertex, and a
    union of two clips (a neckline and a trim) meets at a corner; averaging along the loop removes
    the kinks they make. ``resample``: then spread the loop's vertices evenly along it
    (:func:`relax_loop`)."""
    P = np.array(P, np.float64, copy=True)
    for loop in oriented_boundary_loops(F):
        if on_cut[loop].mean() < min_fraction or not on_cut[loop].any():
            continue
        if resample:
            P[loop] = relax_loop(P[loop], iterations)
        else:
            for _ in range(iterations):
                P[loop] = 0.5 * P[loop] + 0.25 * (P[np.roll(loop, 1)] + P[np.roll(loop, -1)])
    return P


def relax_loop(Q: np.ndarray, iterations: int) -> np.ndarray:
    """A closed polyline smoothed along itself: its vertices spread at equal arc length, then
    rounds of :data:`RELAX_ROUND` averaging passes (each vertex with its two neighbours, 1/4 1/2
    1/4), each followed by a respacing, ``iterations`` passes in all. The first respacing makes
    the averaging act over arc length, not vertex indices: the clip leaves clusters of tiny
    edges where its level set passes near a vertex or two clips meet, and averaging over them
    alone leaves a corner that a later respacing turns into one sharp vertex."""
    Q = _respace(np.array(Q, np.float64, copy=True))
    done = 0
    while done < iterations:
        for _ in range(min(RELAX_ROUND, iterations - done)):
            Q = 0.5 * Q + 0.25 * (np.roll(Q, 1, 0) + np.roll(Q, -1, 0))
        done += RELAX_ROUND
        Q = _respace(Q)
    return Q


def _respace(Q: np.ndarray) -> np.ndarray:
    """The closed polyline's vertices spread at equal arc length along it (in order, the start
    chosen to move them least)."""
    n = len(Q)
    ext = np.vstack([Q, Q[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ext, axis=0), axis=1))])
    L = s[-1]
    if L <= 0:
        return Q
    step = np.arange(n) * (L / n)
    t = np.mod(step + np.mean(s[:-1] - step), L)
    return np.stack([np.interp(t, s, ext[:, k]) for k in range(3)], 1)


def hem_loops(F: np.ndarray, on_hem: np.ndarray) -> list[np.ndarray]:
    return [lo for lo in oriented_boundary_loops(F) if on_hem[lo].mean() >= 0.8 and len(lo) >= 8]


def cap(P: np.ndarray, loop: np.ndarray, inset: float) -> tuple[np.ndarray, np.ndarray]:
    """A fan of triangles closing the loop ``P[loop]`` from underneath: its rim ``inset`` inside
    the loop (toward the loop's axis, so it tucks under the garment's edge), its centre at the
    loop's centroid. Faces point down/outward (seen from below). Returns (vertices, faces)."""
    Q = np.asarray(P, np.float64)[loop]
    c = Q.mean(0)
    radial = Q - c
    radial[:, 2] = 0.0
    rim = Q - normalize(radial) * float(inset)
    n = len(rim)
    verts = np.vstack([rim, c[None]])
    i = np.arange(n)
    faces = np.stack([i, (i + 1) % n, np.full(n, n)], 1)
    # orient so the face normals point down (the side a camera below sees)
    tri = verts[faces]
    nz = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2].sum()
    if nz > 0:
        faces = faces[:, ::-1]
    return verts, faces


def turning_angles(P: np.ndarray, closed: bool = True) -> np.ndarray:
    """Degrees between consecutive edges of a polyline (closed: also across the seam)."""
    P = np.asarray(P, np.float64)
    e = np.diff(np.vstack([P, P[:1]]) if closed else P, axis=0)
    e = e / np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-15)
    nxt = np.roll(e, -1, 0) if closed else e[1:]
    cur = e if closed else e[:-1]
    return np.degrees(np.arccos(np.clip((cur * nxt).sum(1), -1.0, 1.0)))
