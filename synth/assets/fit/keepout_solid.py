"""Solids short strands stay out of (the lashes: the eyeballs and the skin of the lids).

:class:`KeepOut` is a union of solids: closed meshes (the eyeballs) and, optionally, the head's
skin near the strands' roots (an open patch of the skin sheet, which near the eyes wraps round
the lid margins into the eye sockets). Each is queried with its own signed distance, the sign
from the angle-weighted pseudo-normal (exact for a closed mesh, well behaved on an open sheet
away from its border), and the union's signed distance is the smaller of the two: a point is
inside when it is inside either. The head's own exact push-out (``Surface.closest``: one mesh of
skin and eyes, the nearest face's sign, the 16 triangles with the nearest centroids) misreads
both places a closing lid carries its lashes to: a point between a closed lid and the eye is
nearer the eye's many small triangles than the centroid of the large lid triangle it is behind,
and a point inside the thin fold of the opposite lid is pushed out of one face of the fold into
the other.

Remedies, all rotations about points of the strand (segment lengths kept, roots fixed):

- :meth:`KeepOut.pivot` turns a whole strand rigidly about its root, by the smallest angle that
  clears every point (the shape kept);
- :meth:`KeepOut.bend` walks a strand from the root: where point ``k`` is short of its
  clearance, the rest of the strand (points ``k`` onward) turns rigidly about point ``k - 1``
  by the smallest angle that clears point ``k``: the strand bends at that joint, as a lash
  pressed against the opposite lid does, and keeps its shape beyond it;
- :meth:`KeepOut.project` moves single points out along the normal (the residue).

The turns go toward the union's outward normal at the point to clear (the root for
``pivot``): searched in ``steps`` up to the normal, then bisected ``refine`` times; a point not
cleared even along the normal is turned onto it. Deterministic and vectorised over strands.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from synth.assets.fit.strands import _push_along
from synth.geometry.normals import normalize
from synth.geometry.rotations import axis_angle_to_matrix
from synth.geometry.sdf import SignedDistance

#: candidate triangles per skin query (the nearest centroids): the skin near the eyes mixes
#: sub-millimetre lid triangles with 4-8 mm socket ones
SKIN_K = 48


def _sdf(V: np.ndarray, tris: np.ndarray, k: int = 16) -> SignedDistance | None:
    if not len(tris):
        return None
    used, inv = np.unique(tris, return_inverse=True)
    return SignedDistance(V[used], inv.reshape(-1, 3), sign="pseudo", k=k)


def _smallest_turn(full: np.ndarray, clear, steps: int, refine: int) -> np.ndarray:
    """The smallest angle in [0, full] (per strand) for which ``clear(angles) -> bool`` holds
    (``angles`` (n, m), one column per trial): the first of ``steps`` equal steps (all tried in
    one call), then ``refine`` bisections below it; ``full`` where none holds."""
    t = full[:, None] * (np.arange(1, steps + 1) / steps)[None, :]
    ok = clear(t)
    first = np.where(ok.any(1), ok.argmax(1), steps - 1)
    r = np.arange(len(full))
    hi = t[r, first]
    lo = np.where(ok.any(1), np.where(first > 0, t[r, np.maximum(first - 1, 0)], 0.0), hi)  # never cleared: onto the normal
    for _ in range(refine):
        mid = 0.5 * (lo + hi)
        ok = clear(mid[:, None])[:, 0]
        hi = np.where(ok, mid, hi)
        lo = np.where(ok, lo, mid)
    return hi


def _turn_setup(d: np.ndarray, n: np.ndarray):
    """Unit axes turning unit directions ``d`` toward normals ``n``, the full angles, and the
    rows where that turn is defined (d not along n; elsewhere some axis perpendicular to d)."""
    axis = np.cross(d, n)
    ok = np.linalg.norm(axis, axis=1) > 1e-9
    other = np.where((np.abs(d[:, :1]) < 0.9), np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    axis = np.where(ok[:, None], axis, np.cross(d, other))
    full = np.arccos(np.clip(np.einsum("nd,nd->n", d, n), -1.0, 1.0))
    return normalize(axis), full, ok


class KeepOut:
    """The union of the closed meshes ``regions`` of ``surface`` (disjoint; queried as one mesh)
    and, with ``skin_radius``, the head's exterior skin (interior parts and ``regions`` left
    out) within ``skin_radius`` of the points ``roots``."""

    def __init__(self, surface, regions, roots: np.ndarray | None = None, skin_radius: float = 0.0):
        m = np.zeros(len(surface.V), bool)
        for r in regions:
            m |= surface.mask(r)
        self.closed = _sdf(surface.V, surface.T[m[surface.T].all(1)])
        self.skin = None
        if roots is not None and skin_radius > 0.0 and len(roots):
            tris = surface.ext_tris[~m[surface.T[surface.ext_tris]].any(1)]
            near = np.zeros(len(surface.V), bool)
            vids = np.unique(surface.T[tris])
            dist, _ = cKDTree(np.asarray(roots, np.float64)).query(surface.V[vids], distance_upper_bound=skin_radius)
            near[vids[np.isfinite(dist)]] = True
            self.skin = _sdf(surface.V, surface.T[tris[near[surface.T[tris]].any(1)]], SKIN_K)

    @property
    def empty(self) -> bool:
        return self.closed is None and self.skin is None

    def query(self, P: np.ndarray, skin: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance of points (..., 3) to the union (the closed meshes alone without
        ``skin``; negative inside) and the unit normal that signed it."""
        flat = P.reshape(-1, 3)
        sd, n = np.full(len(flat), np.inf), np.zeros((len(flat), 3))
        for sdf in (self.closed, self.skin if skin else None):
            if sdf is None:
                continue
            h = sdf.query(flat)
            nearer = h.signed < sd
            sd = np.where(nearer, h.signed, sd)
            n = np.where(nearer[:, None], h.normal, n)
        return sd.reshape(P.shape[:-1]), n.reshape(P.shape)

    def _short(self, P, c):
        """(N,) largest clearance deficit of each strand's non-root points to the closed meshes
        (<= 0: clear)."""
        sd, _ = self.query(P[:, 1:], skin=False)
        return np.max(c[:, 1:] - sd, axis=1)

    def pivot(self, P: np.ndarray, clearance, steps: int = 12, refine: int = 6) -> np.ndarray:
        """Turn each strand with a point closer than its clearance (broadcastable to P.shape[:-1];
        -inf: ignored) to the closed meshes rigidly about its root, its mean direction toward
        their outward normal at the root, by the smallest angle that clears every point (see the
        module doc). Strands already clear are not touched."""
        P = np.array(P, np.float64)
        if self.closed is None:
            return P
        c = np.broadcast_to(np.asarray(clearance, np.float64), P.shape[:-1])
        bad = np.flatnonzero(self._short(P, c) > 0.0)
        if not len(bad):
            return P
        _, n = self.query(P[bad, 0], skin=False)
        axis, full, ok = _turn_setup(normalize((P[bad, 1:] - P[bad, :1]).sum(1)), n)
        bad, axis, full = bad[ok], axis[ok], full[ok]
        root = P[bad, 0]
        rel = P[bad, 1:] - root[:, None]

        def turned(t):  # (n, m) angles -> (n, m, P - 1, 3) turned non-root points
            R = axis_angle_to_matrix(axis[:, None] * t[..., None])
            return root[:, None, None] + np.einsum("nmij,npj->nmpi", R, rel)

        def clear(t):
            sd, _ = self.query(turned(t), skin=False)
            return np.max(c[bad, None, 1:] - sd, axis=2) <= 0.0

        P[bad, 1:] = turned(_smallest_turn(full, clear, steps, refine)[:, None])[:, 0]
        return P

    def bend(self, P: np.ndarray, clearance, steps: int = 6, refine: int = 5, rings: int = 6,
             azimuths: int = 6, widest: float = np.radians(150.0)) -> np.ndarray:
        """Walk the strands from the root: where point k is closer than its clearance
        (broadcastable to P.shape[:-1]; -inf: ignored), turn points k onward rigidly about point
        k - 1 by the smallest angle that clears point k: first toward the outward normal at
        point k (``steps``, then ``refine`` bisections); where that fails (two sheets of skin
        overlap, as the lids of a closed eye do, and the normal of one points into the other),
        on cones about the segment's direction (``rings`` opening angles up to ``widest``,
        ``azimuths`` directions each: the narrowest cone with a clear direction, the clearest
        of those, then bisected); where nothing clears, the clearest of all directions tried
        if it is clearer than the point was. Strands already clear are not touched."""
        P = np.array(P, np.float64)
        if self.empty:
            return P
        c = np.broadcast_to(np.asarray(clearance, np.float64), P.shape[:-1])
        for k in range(1, P.shape[1]):
            sd, n = self.query(P[:, k])
            bad = np.flatnonzero(c[:, k] - sd > 0.0)
            if not len(bad):
                continue
            joint = P[bad, k - 1]
            rel = P[bad, k:] - joint[:, None]
            R = self._joint_turn(joint, rel[:, 0], n[bad], c[bad, k], sd[bad], steps, refine, rings, azimuths, widest)
            P[bad, k:] = joint[:, None] + np.einsum("nij,npj->npi", R, rel)
        return P

    def _joint_turn(self, joint, seg, n, ck, sd0, steps, refine, rings, azimuths, widest) -> np.ndarray:
        """(n, 3, 3) rotations about ``joint`` for the segments ``seg`` (see :meth:`bend`)."""
        d = normalize(seg)
        axis, full, _ = _turn_setup(d, n)

        def margin(i, ax, t):  # rows i, (n, m, 3) axes, (n, m) angles -> (n, m) margins of the turned point
            R = axis_angle_to_matrix(ax * t[..., None])
            return self.query(joint[i, None] + np.einsum("nmij,nj->nmi", R, seg[i]))[0] - ck[i, None]

        def bisect(i, ax, lo, hi):
            for _ in range(refine):
                mid = 0.5 * (lo + hi)
                ok = margin(i, ax[:, None], mid[:, None])[:, 0] >= 0.0
                hi, lo = np.where(ok, mid, hi), np.where(ok, lo, mid)
            return hi

        t = full[:, None] * (np.arange(1, steps + 1) / steps)[None, :]
        ok = margin(slice(None), np.repeat(axis[:, None], steps, 1), t) >= 0.0
        first = ok.argmax(1)
        angle = np.zeros(len(d))
        done = ok.any(1)
        if done.any():
            i = np.flatnonzero(done)
            lo = np.where(first[i] > 0, t[i, np.maximum(first[i] - 1, 0)], 0.0)
            angle[i] = bisect(i, axis[i], lo, t[i, first[i]])
        rest = np.flatnonzero(~done)
        if len(rest):
            # axes perpendicular to the segment, ``azimuths`` of them, the first the normal's
            phi = 2.0 * np.pi * np.arange(azimuths) / azimuths
            a0, a1 = axis[rest], np.cross(d[rest], axis[rest])
            ax = np.cos(phi)[None, :, None] * a0[:, None] + np.sin(phi)[None, :, None] * a1[:, None]
            th = widest * np.arange(1, rings + 1) / rings
            axs = np.repeat(ax[:, None], rings, 1).reshape(len(rest), -1, 3)
            m = margin(rest, axs, np.broadcast_to(th[None, :, None], (len(rest), rings, azimuths)).reshape(len(rest), -1))
            m = m.reshape(len(rest), rings, azimuths)
            clear = m >= 0.0
            hit = clear.any((1, 2))
            ring = np.where(hit, clear.any(2).argmax(1), 0)
            rr = np.arange(len(rest))
            best_az = np.where(clear[rr, ring], m[rr, ring], -np.inf).argmax(1)
            flat = m.reshape(len(rest), -1).argmax(1)
            ring = np.where(hit, ring, flat // azimuths)
            az = np.where(hit, best_az, flat % azimuths)
            axis[rest] = ax[rr, az]
            angle[rest] = np.where(hit | (m[rr, ring, az] > sd0[rest] - ck[rest]), th[ring], 0.0)
            h = np.flatnonzero(hit)
            if len(h):
                angle[rest[h]] = bisect(rest[h], axis[rest[h]], np.where(ring[h] > 0, th[np.maximum(ring[h] - 1, 0)], 0.0),
                                        th[ring[h]])
        return axis_angle_to_matrix(axis * angle[:, None])

    def project(self, P: np.ndarray, clearance, iterations: int = 3) -> np.ndarray:
        """Move points closer than their clearance (-inf: ignored) out along the normal; a point
        that ends up deeper than it was (pushed out of one of two overlapping sheets into the
        other) stays where it was."""
        P = np.array(P, np.float64)
        if self.empty:
            return P
        c = np.broadcast_to(np.asarray(clearance, np.float64), P.shape[:-1])
        sd0, _ = self.query(P)
        idx = np.flatnonzero((c - sd0 > 0.0).reshape(-1))
        if not len(idx):
            return P
        flat, cf = P.reshape(-1, 3), c.reshape(-1)
        q = _push_along(flat[idx], cf[idx], self.query, iterations)
        better = self.query(q)[0] > sd0.reshape(-1)[idx]
        flat[idx[better]] = q[better]
        return flat.reshape(P.shape)
