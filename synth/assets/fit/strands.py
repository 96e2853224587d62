"""Strand geometry in numpy (hair, beard, eyebrows, eyelashes): the head surface the strands
grow on and the shapes they take. No bpy; the Blender side is ``blender_scripts/assets/strands.py``.

Pipeline of a strand groom (``synth.assets.fit.hair`` and the other groom modules)::

    surface = Surface(ctx)                              # head triangles, normals, push-out query
    tri, bary = surface.sample(tris, n, rng)            # roots by area (the rig's generator only)
    pts = grow(...) / interpolate(...)                  # (N, P, 3) strands, outside the head
    groom = Groom(...)                                  # synth.assets.fit.groom: what the rig builds

:class:`Surface` is the *current* head surface: area sampling of roots, root points, normals
and triangle frames (attachment), and a fast collision push-out (tangent planes of the
nearest vertices) with an exact variant (closest point on the triangles).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from synth.geometry.normals import face_normals, normalize, vertex_normals
from synth.geometry.rotations import rotate_between
from synth.geometry.sdf import SignedDistance

UP = np.array([0.0, 0.0, 1.0])
DOWN = -UP
FORWARD = np.array([0.0, -1.0, 0.0])  # the face looks toward -Y
BACK = -FORWARD
LEFT = np.array([1.0, 0.0, 0.0])  # subject's left

#: regions whose vertices are inside the head (never pushed against)
_INTERIOR = ("mouth_interior", "teeth", "lash_helper_l_upper", "lash_helper_l_lower", "lash_helper_r_upper",
             "lash_helper_r_lower")


def scale_count(resolution: int, per_px: float, lo: int, hi: int) -> int:
    """A strand count proportional to the render resolution, clipped to [lo, hi]."""
    return int(np.clip(round(per_px * float(resolution)), lo, hi))


# --------------------------------------------------------------------------- surface


class Surface:
    """The current head surface: triangles, normals, area sampling, frames, push-out."""

    def __init__(self, ctx, vertices: np.ndarray | None = None):
        self.data = ctx.data
        self.T = np.asarray(ctx.data.triangles, np.int64)
        self.V = np.asarray(ctx.vertices if vertices is None else vertices, np.float64)
        self._compute()
        keep = np.ones(len(self.V), bool)
        for r in _INTERIOR:
            if r in self.data.regions:
                keep[self.data.regions[r]] = False
        used = np.zeros(len(self.V), bool)
        used[self.T.ravel()] = True
        self.ext = np.flatnonzero(keep & used)
        self.tree = cKDTree(self.V[self.ext])
        self.ext_tris = np.flatnonzero(keep[self.T].all(1) & (self.area > 1e-14))
        self._exact = None

    def _compute(self):
        self.area = 0.5 * np.linalg.norm(face_normals(self.V, self.T, unit=False), axis=1)
        self.vn = vertex_normals(self.V, self.T)

    # -- regions
    def mask(self, region: str) -> np.ndarray:
        m = np.zeros(len(self.V), bool)
        if region in self.data.regions:
            m[self.data.regions[region]] = True
        return m

    def region_triangles(self, regions, mode: str = "all", exclude=()) -> np.ndarray:
        m = np.zeros(len(self.V), bool)
        for r in ([regions] if isinstance(regions, str) else regions):
            m |= self.mask(r)
        inside = m[self.T]
        sel = inside.all(1) if mode == "all" else inside.any(1)
        for r in ([exclude] if isinstance(exclude, str) else exclude):
            sel &= ~self.mask(r)[self.T].any(1)
        return np.flatnonzero(sel & (self.area > 1e-12))

    # -- sampling and evaluation
    def sample(self, tris: np.ndarray, n: int, rng: np.random.Generator, weight=None):
        """n roots on the triangles ``tris`` with probability proportional to area (x weight)."""
        w = self.area[tris] * (1.0 if weight is None else np.asarray(weight, np.float64))
        cdf = np.cumsum(w)
        cdf /= cdf[-1]
        pick = tris[np.minimum(np.searchsorted(cdf, rng.random(n), side="right"), len(tris) - 1)]
        u = rng.random((n, 2))
        su = np.sqrt(u[:, 0])
        bary = np.stack([1.0 - su, su * (1.0 - u[:, 1]), su * u[:, 1]], 1)
        return pick.astype(np.int64), bary

    def points(self, tri, bary, V=None) -> np.ndarray:
        V = self.V if V is None else V
        C = V[self.T[tri]]  # (n, 3 corners, 3); summed corner by corner in order (the same bits anywhere)
        return (bary[:, 0, None] * C[:, 0] + bary[:, 1, None] * C[:, 1]) + bary[:, 2, None] * C[:, 2]

    def normals(self, tri, bary) -> np.ndarray:
        """Smooth (vertex-interpolated) normals at the roots."""
        return normalize(np.einsum("nk,nkd->nd", bary, self.vn[self.T[tri]]))

    def frames(self, tri, V=None) -> np.ndarray:
        """(n, 3, 3) orthonormal frames of triangles (columns: edge, binormal, normal)."""
        V = self.V if V is None else V
        p = V[self.T[tri]]
        e1 = normalize(p[:, 1] - p[:, 0])
        n = normalize(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
        e2 = np.cross(n, e1)
        return np.stack([e1, e2, n], axis=2)

    # -- collisions
    def signed_offset(self, P: np.ndarray, k: int = 4) -> tuple[np.ndarray, np.ndarray]:
        """Height of points above the tangent planes of their k nearest head vertices (the
        lowest one, so that concave spots such as under the chin are not missed) and that
        vertex's normal: a fast signed-distance approximation, negative = inside."""
        flat = P.reshape(-1, 3)
        _, idx = self.tree.query(flat, k=k, workers=-1)
        vi = self.ext[idx]
        n = self.vn[vi]
        d = np.einsum("nkd,nkd->nk", flat[:, None] - self.V[vi], n)
        j = d.argmin(1)
        r = np.arange(len(flat))
        return d[r, j].reshape(P.shape[:-1]), n[r, j].reshape(P.shape)

    def closest(self, P: np.ndarray):
        """Closest points on the exterior head triangles (the 16 with the nearest centroids
        tried), the height above the closest face's plane and that face's unit normal."""
        if self._exact is None:
            self._exact = SignedDistance(self.V, self.T, faces=self.ext_tris, sign="face", k=16, by="distance")
        h = self._exact.query(P.reshape(-1, 3))
        return h.point, h.signed, h.normal

    def push_out_exact(self, P: np.ndarray, clearance, iterations: int = 3, chunk: int = 25000, margin: float = 0.002) -> np.ndarray:
        """Like :meth:`push_out`, with exact closest points on the head triangles. Only points
        the fast test finds within ``margin`` of their clearance are checked exactly (in chunks)."""
        P = np.array(P, np.float64)
        shape = P.shape
        c = np.broadcast_to(np.asarray(clearance, np.float64), shape[:-1]).reshape(-1)
        flat = P.reshape(-1, 3)
        d_fast, _ = self.signed_offset(flat)
        cand = np.flatnonzero(d_fast < c + margin)
        for a in range(0, len(cand), chunk):
            idx = cand[a:a + chunk]
            q = flat[idx]
            for _ in range(iterations):
                _, sd, n = self.closest(q)
                deficit = np.maximum(c[idx] - sd, 0.0)
                if not np.any(deficit > 0):
                    break
                q = q + deficit[:, None] * n
            flat[idx] = q
        return flat.reshape(shape)

    def push_out(self, P: np.ndarray, clearance, iterations: int = 2) -> np.ndarray:
        """Move points below ``clearance`` (broadcastable to P.shape[:-1]) out along the normal."""
        return _push_along(P, clearance, self.signed_offset, iterations)


def _push_along(P: np.ndarray, clearance, query, iterations: int) -> np.ndarray:
    """Move points whose height ``query(P) -> (height, unit normal)`` is below ``clearance`` out
    along that normal, ``iterations`` times at most."""
    P = np.array(P, np.float64)
    c = np.broadcast_to(np.asarray(clearance, np.float64), P.shape[:-1])
    for _ in range(iterations):
        d, n = query(P)
        deficit = np.maximum(c - d, 0.0)
        if not np.any(deficit > 0):
            break
        P += deficit[..., None] * n
    return P


# --------------------------------------------------------------------------- strand shapes


def exit_directions(normals: np.ndarray, field: np.ndarray, angle: float, floor: float = 0.05) -> np.ndarray:
    """Unit directions leaving the surface at ``angle`` (radians) above its tangent plane, toward
    the tangential part of ``field`` (N, 3): how a hair leaves its follicle, slanted in the
    direction it is combed. Where the field is nearly along the normal (tangential part below
    ``floor`` of its length) the direction turns continuously toward the normal (no tie to break)."""
    f = normalize(field)
    tan = f - np.einsum("nd,nd->n", f, normals)[:, None] * normals
    tn = np.linalg.norm(tan, axis=1, keepdims=True)
    return normalize(tan + np.tan(angle) * np.maximum(tn, floor) * normals)


def grow(surface: Surface, roots: np.ndarray, normals: np.ndarray, lengths: np.ndarray, n_points: int,
         direction, lift: np.ndarray | float, clearance: np.ndarray | float, bend: float = 1.0,
         collide: bool = True, root_angle: float | None = None) -> np.ndarray:
    """Grow strands step by step: each segment blends the root direction (weight decaying over
    ``lift`` metres of arc length) with the style direction field ``direction(P, s, k)``
    ((N,3) points, (N,) arc length, step) -> (N,3), and points are pushed out of the head to
    their ``clearance`` (capped near the root so strands can leave the skin at an angle). The
    root direction is the normal, or with ``root_angle`` (radians) the :func:`exit_directions`
    toward the field at the roots (a strand slanted the way it is combed from its root on)."""
    N = len(roots)
    L = np.broadcast_to(np.asarray(lengths, np.float64), (N,))
    seg = L / (n_points - 1)
    lift = np.broadcast_to(np.asarray(lift, np.float64), (N,))
    clr = np.broadcast_to(np.asarray(clearance, np.float64), (N,))
    out = np.empty((N, n_points, 3))
    out[:, 0] = roots
    prev = normals.copy()
    start = normals if root_angle is None else exit_directions(normals, direction(roots, np.zeros(N), 0), root_angle)
    for k in range(1, n_points):
        s = seg * (k - 1)
        a = np.exp(-s / np.maximum(lift, 1e-6))[:, None]
        tgt = normalize(direction(out[:, k - 1], s, k))
        d = normalize(a * start + (1.0 - a) * tgt)
        d = normalize((1.0 - bend) * prev + bend * d) if bend < 1.0 else d
        p = out[:, k - 1] + seg[:, None] * d
        if collide:
            c = np.minimum(clr, 0.6 * seg * k)
            p = surface.push_out(p, c, iterations=1)
            p = out[:, k - 1] + seg[:, None] * normalize(p - out[:, k - 1])
            p = surface.push_out(p, c, iterations=1)
        prev = normalize(p - out[:, k - 1])
        out[:, k] = p
    return out


def settle(surface: Surface, P: np.ndarray, clearance, tol: float = 1e-4) -> np.ndarray:
    """Strands (N, P, 3) that dip below their ``clearance`` ((N, P) or broadcastable) laid over the
    surface instead: from the root on, each point keeps its segment's direction from the settled
    point before it, is pushed out, given back its segment's length and pushed out again (as
    :func:`grow` does; the second push lengthens segments that lie along the skin a little).
    A strand that runs through a shoulder drapes over it; pushing its points out one by one along
    the normal would fold it (points deep inside go to the far side's surface: hooks). Only strands
    with a point below its clearance less ``tol`` are walked; walking one that stays above it
    changes nothing but rounding, so which strands are walked is not a discrete choice."""
    P = np.array(P, np.float64)
    clr = np.broadcast_to(np.asarray(clearance, np.float64), P.shape[:-1])
    d, _ = surface.signed_offset(P[:, 1:])
    rows = np.flatnonzero((d < clr[:, 1:] - tol).any(1))
    if not len(rows):
        return P
    Q = P[rows]
    c = clr[rows]
    seg = np.diff(Q, axis=1)
    length = np.linalg.norm(seg, axis=2)
    out = Q.copy()
    for k in range(1, Q.shape[1]):
        prev = out[:, k - 1]
        p = surface.push_out(prev + seg[:, k - 1], c[:, k], iterations=1)
        p = prev + length[:, k - 1, None] * normalize(p - prev)
        out[:, k] = surface.push_out(p, c[:, k], iterations=1)
    P[rows] = out
    return P


def push_out_strands(surface: Surface, P: np.ndarray, layer, exact: bool = False) -> np.ndarray:
    """Push all but the root points out of the head to min(layer, 0.6 x arc length)."""
    P = np.array(P, np.float64)
    clr = np.minimum(np.asarray(layer, np.float64).reshape(-1, 1), 0.6 * arc_length(P))
    if exact:
        P[:, 1:] = surface.push_out_exact(P[:, 1:], clr[:, 1:])
    else:
        P[:, 1:] = surface.push_out(P[:, 1:], clr[:, 1:], iterations=2)
    return P


def transport_frames(P: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangents and a parallel-transported normal/binormal along (N, P, 3) strands."""
    t = np.empty_like(P)
    t[:, :-1] = P[:, 1:] - P[:, :-1]
    t[:, -1] = t[:, -2]
    t = normalize(t)
    b1 = np.empty_like(P)
    b = normalize(np.cross(t[:, 0], ref))
    bad = np.linalg.norm(np.cross(t[:, 0], ref), axis=1) < 1e-6
    if np.any(bad):
        b[bad] = normalize(np.cross(t[bad, 0], LEFT))
    for k in range(P.shape[1]):
        b = normalize(b - np.einsum("nd,nd->n", b, t[:, k])[:, None] * t[:, k])
        b1[:, k] = b
    b2 = np.cross(t, b1)
    return t, b1, b2


def arc_length(P: np.ndarray) -> np.ndarray:
    s = np.zeros(P.shape[:2])
    s[:, 1:] = np.cumsum(np.linalg.norm(np.diff(P, axis=1), axis=2), axis=1)
    return s


def add_curl(P: np.ndarray, ref: np.ndarray, radius, period, phase, start: float = 0.01,
             planar: bool = False) -> np.ndarray:
    """Helical curls (or planar waves) around the strands' centre lines. ``radius``,
    ``period`` (m of arc length) and ``phase`` are per strand; the amplitude ramps up over
    ``start`` metres from the root so roots stay put."""
    N = P.shape[0]
    s = arc_length(P)
    _, b1, b2 = transport_frames(P, ref)
    r = np.broadcast_to(np.asarray(radius, np.float64), (N,))[:, None]
    per = np.maximum(np.broadcast_to(np.asarray(period, np.float64), (N,)), 1e-4)[:, None]
    ph = np.broadcast_to(np.asarray(phase, np.float64), (N,))[:, None]
    ang = 2.0 * np.pi * s / per + ph
    ramp = np.clip(s / max(start, 1e-6), 0.0, 1.0) * r
    if planar:
        off = (ramp * np.sin(ang))[..., None] * b1
    else:
        off = (ramp * np.cos(ang))[..., None] * b1 + (ramp * np.sin(ang))[..., None] * b2
    return P + off


def resample_fast(P: np.ndarray, lengths: np.ndarray, n_points: int | None = None) -> np.ndarray:
    """Resample strands uniformly by arc length over their first ``lengths`` metres."""
    N, K, _ = P.shape
    n_points = n_points or K
    s = arc_length(P)
    L = np.clip(np.asarray(lengths, np.float64), 1e-6, s[:, -1])
    q = np.linspace(0.0, 1.0, n_points)[None, :] * L[:, None]
    j = np.empty((N, n_points), np.int64)
    for i in range(n_points):
        j[:, i] = (s <= q[:, i:i + 1]).sum(1) - 1
    j = np.clip(j, 0, K - 2)
    s0 = np.take_along_axis(s, j, 1)
    s1 = np.take_along_axis(s, j + 1, 1)
    w = np.clip((q - s0) / np.maximum(s1 - s0, 1e-12), 0.0, 1.0)[..., None]
    p0 = np.take_along_axis(P, j[..., None], 1)
    p1 = np.take_along_axis(P, j[..., None] + 1, 1)
    return p0 + w * (p1 - p0)


def trim_below(P: np.ndarray, z_cut: np.ndarray, min_len: float = 0.005) -> np.ndarray:
    """Cut strands where they first go below ``z_cut`` (per strand) and resample."""
    s = arc_length(P)
    below = P[..., 2] < np.asarray(z_cut, np.float64)[:, None]
    below[:, 0] = False
    first = np.where(below.any(1), below.argmax(1), P.shape[1] - 1)
    L = s[np.arange(len(P)), first]
    return resample_fast(P, np.maximum(L, min_len))


def trim_at_plane(P: np.ndarray, origin: np.ndarray, normal: np.ndarray, min_len: float = 0.005):
    """Cut strands (N, K, 3) where they first cross to the ``normal`` side of the plane through
    ``origin`` (the crossing found on the segment, not at a point) and resample them over what
    is left. Returns (strands, keep): ``keep`` is False for strands whose root lies on that side
    or that would be shorter than ``min_len``; their rows are returned unchanged (drop them)."""
    P = np.asarray(P, np.float64)
    g = (P - np.asarray(origin, np.float64)) @ np.asarray(normal, np.float64)  # (N, K) signed height
    s = arc_length(P)
    over = g > 0.0
    over[:, 0] = False
    crosses = over.any(1)
    k = np.where(crosses, over.argmax(1), P.shape[1] - 1)
    rows = np.arange(len(P))
    k0 = np.maximum(k - 1, 0)
    g0, g1 = g[rows, k0], g[rows, k]
    t = np.where(crosses, np.clip(-g0 / np.maximum(g1 - g0, 1e-12), 0.0, 1.0), 1.0)
    L = np.where(crosses, s[rows, k0] + t * (s[rows, k] - s[rows, k0]), s[:, -1])
    keep = (g[:, 0] <= 0.0) & (L >= min_len)
    out = P.copy()
    cut = keep & crosses
    if cut.any():
        out[cut] = resample_fast(P[cut], L[cut])
    return out, keep


def interpolate(surface: Surface, g_tri, g_bary, g_pts, c_tri, c_bary, k: int = 3, rng=None,
                jitter: float = 0.0):
    """Children from guides: the guides' root offsets, each turned by the minimal rotation from
    its root normal to the child's, blended by inverse distance over the k nearest guides."""
    g_root = surface.points(g_tri, g_bary)
    g_n = surface.normals(g_tri, g_bary)
    g_off = g_pts - g_root[:, None]
    c_root = surface.points(c_tri, c_bary)
    c_n = surface.normals(c_tri, c_bary)
    kk = min(k, len(g_root))
    dist, idx = cKDTree(g_root).query(c_root, k=kk)
    if kk == 1:
        dist, idx = dist[:, None], idx[:, None]
    w = 1.0 / np.maximum(dist, 1e-4) ** 2
    w /= w.sum(1, keepdims=True)
    off = np.zeros((len(c_root),) + g_off.shape[1:])
    for j in range(kk):
        gi = idx[:, j]
        off += w[:, j, None, None] * rotate_between(g_n[gi], c_n, g_off[gi])
    if rng is not None and jitter > 0:
        off *= 1.0 + jitter * rng.uniform(-1.0, 1.0, (len(c_root), 1, 1))
    return c_root[:, None] + off, idx[:, 0]
