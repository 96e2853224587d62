"""A face keep-out for scalp hair: strands do not hang in front of the inner face.

The keep-out is a wedge around a vertical axis through the head centre (``head_frame``'s
``centre``): in cylindrical coordinates about that axis (angle ``theta`` from straight ahead,
-Y, positive toward the subject's left, +X, the camera azimuth convention of
``synth.conventions``), a point at height ``z`` is inside when ``|theta| < limit(z)``. The
limit is the widest angle of the inner face (``occlusion.inner_face_triangles``: the ``face``
region below the brows) at that height, widened by a margin and by a parallax term for points
standing off the face, and tapered to zero above the brows (a fringe over the forehead stays)
and below the chin.

Strands that enter the wedge are turned around the axis, sideways and backwards, to its edge
on their own side (the side where most of their points near the wedge lie): each point needs
a turn (a C1 ``soft max`` of its angle and the edge plus ``width``, so points just outside move
a little and no corner appears at the edge); these turns are spread along the strand with
smoothstep bumps, ``ahead`` metres toward the root (it starts turning before it reaches the
wedge) and ``behind`` metres toward the tip (it eases back below the chin instead of snapping
back), faded in over the first ``root`` metres (roots stay put); every point is rotated about
the axis by its turn, and the strand is rebuilt point by point with its original segment
lengths (follow the leader: every segment keeps its length and points toward its turned
target); twice. Rotation about the axis keeps the distance from it, and the head is narrower
at the sides than in front, so turned points stay outside the head; the grooms' push-out runs
afterwards anyway. A strand that would need a turn of more than ``trim_deg`` (one hanging
straight down in front of the face) cannot make it without a sharp bend: it is cut at its last
point before the wedge instead (the last resort; above the brows that reads as a fringe).

Deterministic (no random numbers) and vectorised over strands; loops run over the points of a
strand only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.assets.fit.occlusion import inner_face_triangles
from synth.assets.fit.strands import arc_length, resample_fast
from synth.model.meshutil import smoothstep


@dataclass
class FaceKeepOut:
    """The wedge: ``limit(z)`` (radians) sampled on ``z`` (ascending), about the axis ``(x, y)``."""

    axis: np.ndarray  # (2,) x, y of the vertical axis
    z: np.ndarray  # (K,) heights, ascending
    limit: np.ndarray  # (K,) half-angle of the wedge at those heights (radians)
    radius: np.ndarray  # (K,) outermost distance of the inner face from the axis at those heights
    brow_z: float  # top of the inner face
    parallax: float = 0.6  # extra half-angle per unit of relative stand-off (r / radius - 1)

    def limits(self, z: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Half-angle of the wedge at heights ``z`` for points ``r`` from the axis."""
        lim = np.interp(z, self.z, self.limit, left=0.0, right=0.0)
        rad = np.interp(z, self.z, self.radius)
        off = np.clip(r / np.maximum(rad, 1e-6) - 1.0, 0.0, 0.5)
        return np.where(lim > 0.0, lim + self.parallax * off, 0.0)

    def cylindrical(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(theta, r) of points about the axis."""
        dx, dy = pts[..., 0] - self.axis[0], pts[..., 1] - self.axis[1]
        return np.arctan2(dx, -dy), np.hypot(dx, dy)

    def inside(self, pts: np.ndarray) -> np.ndarray:
        th, r = self.cylindrical(pts)
        return np.abs(th) < self.limits(pts[..., 2], r)


def face_keep_out(data, vertices: np.ndarray, landmarks68: np.ndarray, centre, margin_deg: float = 6.0,
                  above: float = 0.02, below: float = 0.03, step: float = 0.004) -> FaceKeepOut:
    """The wedge of a head: the inner face's angular half-width per ``step`` of height (the
    widest of each bin and its neighbours, plus ``margin_deg``), tapered (smoothstep) to zero
    over ``above`` metres above the brows and ``below`` metres under the lowest face point."""
    V = np.asarray(vertices, np.float64)
    axis = np.asarray(centre, np.float64)[:2]
    fv = V[np.unique(inner_face_triangles(data, V, landmarks68))]
    dx, dy = fv[:, 0] - axis[0], fv[:, 1] - axis[1]
    th, r, z = np.abs(np.arctan2(dx, -dy)), np.hypot(dx, dy), fv[:, 2]
    z0, z1 = float(z.min()), float(z.max())
    edges = np.arange(z0, z1 + step, step)
    b = np.clip(np.searchsorted(edges, z, side="right") - 1, 0, len(edges) - 1)
    w = np.zeros(len(edges))
    rad = np.zeros(len(edges))
    np.maximum.at(w, b, th)
    np.maximum.at(rad, b, r)
    # widest of each bin and its neighbours (a face edge between two bins is not missed)
    w = np.maximum(w, np.maximum(np.r_[w[1:], 0.0], np.r_[0.0, w[:-1]]))
    rad = np.maximum(rad, np.maximum(np.r_[rad[1:], 0.0], np.r_[0.0, rad[:-1]]))
    zc = edges + 0.5 * step
    lim = w + np.radians(margin_deg)
    # tapers: below the chin and above the brows the wedge closes smoothly
    zb = np.linspace(zc[0] - below, zc[0], 9)[:-1]
    za = np.linspace(zc[-1], zc[-1] + above, 9)[1:]
    zs = np.concatenate([zb, zc, za])
    lims = np.concatenate([lim[0] * smoothstep((zb - zb[0]) / below), lim, lim[-1] * smoothstep((za[-1] - za) / above)])
    rads = np.concatenate([np.full(len(zb), rad[0]), rad, np.full(len(za), rad[-1])])
    return FaceKeepOut(axis, zs, lims, rads, z1)


def _soft_max(u: np.ndarray, lim: np.ndarray, width: float) -> np.ndarray:
    """max(u, lim), C1: equal to ``lim`` below ``lim - width``, to ``u`` above ``lim + width``,
    a quadratic in between."""
    t = (u - lim) / width
    q = np.where(t >= 1.0, t, np.where(t <= -1.0, 0.0, 0.25 * (t + 1.0) ** 2))
    return lim + width * q


def follow_the_leader(targets: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Strands through ``targets`` (N, P, 3) rebuilt with segment ``lengths`` (N, P-1): every
    point lies at its segment's length from the previous one, toward its target (roots kept)."""
    out = np.array(targets, np.float64)
    for k in range(1, out.shape[1]):
        d = out[:, k] - out[:, k - 1]
        n = np.linalg.norm(d, axis=1, keepdims=True)
        fallback = out[:, k - 1] - out[:, max(k - 2, 0)] if k > 1 else d
        d = np.where(n > 1e-12, d, fallback)
        n = np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        out[:, k] = out[:, k - 1] + lengths[:, k - 1, None] * d / n
    return out


def envelope(F: np.ndarray, s: np.ndarray, ahead: float, behind: float) -> np.ndarray:
    """Upper envelope over a strand of the values ``F`` (N, P) (0: none), each spread along
    the arc length ``s`` with a smoothstep bump: ``ahead`` metres toward the root (the strand
    starts turning before it reaches the wedge) and ``behind`` metres toward the tip (it eases
    back after leaving it). The bumps are flat at their peaks, so the envelope has no corner
    there."""
    d = s[:, None, :] - s[:, :, None]  # [n, k, j]: s_j - s_k
    K = np.where(d >= 0.0, smoothstep(1.0 - d / ahead), smoothstep(1.0 + d / behind))
    return (F[:, None, :] * K).max(2)


def _turn(ko: FaceKeepOut, pts: np.ndarray, side: np.ndarray | None, width: float, ahead: float,
          behind: float, root: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    th, r = ko.cylindrical(pts)
    lim = ko.limits(pts[..., 2], r)
    near = (lim > 0.0) & (np.abs(th) < lim + 2.0 * width)
    near[:, 0] = False
    if side is None:
        # the side of each strand: where most of its (weighted) points near the wedge lie
        wgt = np.where(near, lim + 2.0 * width - np.abs(th), 0.0)
        side = np.sign((wgt * th).sum(1))
        side = np.where(side == 0.0, np.where(pts[:, -1, 0] >= ko.axis[0], 1.0, -1.0), side)
    u = side[:, None] * th
    s = np.zeros(u.shape)
    s[:, 1:] = np.cumsum(np.linalg.norm(np.diff(pts, axis=1), axis=2), axis=1)
    # the turn each point needs (a C1 soft max of its angle and the edge), spread along the
    # strand so that it starts turning before the wedge and eases back after it
    need = np.where(near & (u > -lim - 2.0 * width), np.maximum(_soft_max(u, lim + width, width) - u, 0.0), 0.0)
    # roots stay put: the turn fades in over the first ``root`` metres of a strand
    move = envelope(need, s, ahead, behind) * smoothstep(s / root)
    a = th + side[:, None] * move
    out = np.stack([ko.axis[0] + r * np.sin(a), ko.axis[1] - r * np.cos(a), pts[..., 2]], -1)
    out[:, 0] = pts[:, 0]
    return out, side, move


def keep_out(ko: FaceKeepOut, pts: np.ndarray, width_deg: float = 6.0, ahead: float = 0.08, behind: float = 0.08,
             root: float = 0.03, passes: int = 2, trim_deg: float = 30.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Strands (N, P, 3) kept out of the wedge (see the module doc); returns the strands and
    the (N,) masks of the strands turned and of those trimmed. A strand that would have to
    turn by more than ``trim_deg`` somewhere (one hanging straight down in front of the
    face, say) cannot do so without a sharp bend: it is cut instead at its last point before
    the wedge (resampled to the same number of points). Other strands are returned as given."""
    P = np.asarray(pts, np.float64)
    hit = ko.inside(P[:, 1:]).any(1)
    out = P.copy()
    turned, trimmed = np.zeros(len(P), bool), np.zeros(len(P), bool)
    if not hit.any():
        return out, turned, trimmed
    S = P[hit]
    seg = np.linalg.norm(np.diff(S, axis=1), axis=2)
    width = np.radians(width_deg)
    side, Q, worst = None, S, np.zeros(len(S))
    for k in range(passes):
        T, side, move = _turn(ko, Q, side, width, ahead, behind, root)
        if k == 0:
            worst = move.max(1)
        Q = follow_the_leader(T, seg)
    cut = worst > np.radians(trim_deg)
    if cut.any():
        inside = ko.inside(S[cut])
        inside[:, 0] = False
        first = inside.argmax(1)
        Q[cut] = resample_fast(S[cut], np.maximum(arc_length(S[cut])[np.arange(int(cut.sum())), first - 1], 1e-3))
    idx = np.flatnonzero(hit)
    out[idx] = Q
    turned[idx[~cut]] = True
    trimmed[idx[cut]] = True
    return out, turned, trimmed
