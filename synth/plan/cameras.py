"""Viewpoints: spherical-cap packing bound, and vectorised rejection sampling of views
whose viewing directions are pairwise at least ``min_separation_deg`` apart.

Every expression gets its own candidate sequence: candidate ``k`` of expression (i, e) is
word ``k % 4`` of the Philox block ``seeds.blocks(seed, CAMERA, i, e, view=NA, draw=k // 4 + 1)``
(three 21-bit uniforms: azimuth, elevation, radius). Candidates are accepted greedily in
order (the paper's "discard and re-sample"), in lockstep across all expressions so numpy
does the work; the views of one expression depend only on (run seed, i, e) and the camera
config, never on which other expressions are sampled alongside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth import seeds
from synth.conventions import spherical_offset
from synth.errors import SynthError
from synth.geometry import exact

_COS_MARGIN = 2e-6  # float32 cosines: accepted pairs are >= the angle in float64 too
_F32_MIN_DEG = 2.0  # below this separation the check runs in float64 without a margin
_MIN_SEP_DEG = 1e-6  # separations below this count as 0 (no constraint)
_CHUNK = 2048  # expressions per pass of the distance check (keeps temporaries in cache)
_BATCH = 16  # candidates per expression in the first round (a multiple of 4)


# --------------------------------------------------------------------------- packing bound


def cap_area(r: float) -> float:
    """Area (sr) of a spherical cap of angular radius r (radians); 2 pi (1 - cos r), stably."""
    return 4.0 * np.pi * exact.sin(0.5 * r) ** 2


def _point_halfwidth(e: float, ep: np.ndarray, r: float) -> np.ndarray:
    """Azimuth half-width at latitudes ``ep`` of the cap of radius r around latitude e."""
    ce = exact.cos(e) * exact.cos(ep)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = (exact.cos(r) - exact.sin(e) * exact.sin(ep)) / ce
    w = np.where(c <= -1.0, np.pi, exact.acos(np.clip(c, -1.0, 1.0)))
    w = np.where(c > 1.0, -np.inf, w)
    at_pole = ce < 1e-15
    return np.where(at_pole, np.where(np.abs(e - ep) <= r + 1e-15, np.pi, -np.inf), w)


def expanded_area(az_deg, el_deg, r: float, slices: int = 20000) -> float:
    """Area (sr) of the set of directions within angular distance r (radians) of the patch
    azimuth in az_deg x elevation in el_deg. Exact slice widths, midpoint quadrature in
    latitude (relative error ~1e-8 at the default slice count)."""
    a0, a1 = np.deg2rad(az_deg)
    e0, e1 = np.deg2rad(el_deg)
    lo, hi = max(e0 - r, -np.pi / 2), min(e1 + r, np.pi / 2)
    if a1 - a0 >= 2.0 * np.pi - 1e-12:
        return float(2.0 * np.pi * (exact.sin(hi) - exact.sin(lo)))
    ep = lo + (np.arange(slices) + 0.5) * (hi - lo) / slices
    cep = exact.cos(ep)
    # The half-width W(ep) reached by one meridian segment [e0, e1] is the max over its points
    # of their caps' half-widths: the stationary (tangent) point if its foot lies inside the
    # segment, else an endpoint.
    with np.errstate(divide="ignore", invalid="ignore"):
        full = exact.asin(np.clip(exact.sin(r) / cep, 0.0, 1.0))
        foot = exact.atan2(exact.sin(ep), cep * exact.cos(full))
    interior = (cep > exact.sin(r)) & (foot >= e0) & (foot <= e1)
    w_end = np.maximum(_point_halfwidth(e0, ep, r), _point_halfwidth(e1, ep, r))
    w = np.where(interior, full, w_end)
    extent = np.where(w >= 0, np.minimum(2.0 * np.pi, (a1 - a0) + 2.0 * np.maximum(w, 0.0)), 0.0)
    return float(np.sum(extent * cep) * (hi - lo) / slices)


def effective_separation(min_separation_deg: float) -> float:
    """The separation the sampler enforces: values below 1e-6 degrees count as 0."""
    return float(min_separation_deg) if min_separation_deg >= _MIN_SEP_DEG else 0.0


def max_views(az_deg, el_deg, min_separation_deg: float) -> int | None:
    """Upper bound on how many directions in the patch can be pairwise >= the angle apart:
    caps of radius angle/2 around them are disjoint and lie in the patch grown by angle/2.
    ``None`` means no bound (angle below 1e-6 degrees)."""
    if effective_separation(min_separation_deg) <= 0:
        return None
    r = np.deg2rad(min_separation_deg) / 2.0
    cap = cap_area(r)
    bound = expanded_area(az_deg, el_deg, r) * (1.0 + 1e-6) / cap
    return max(1, int(np.floor(bound + 1e-9)))


def check_feasible(camera, n_views: int) -> None:
    """Refuse (SynthError) a view count that cannot satisfy the minimum separation."""
    n_max = max_views(camera.azimuth_deg, camera.elevation_deg, camera.min_separation_deg)
    if n_max is not None and n_views > n_max:
        raise SynthError(
            f"{n_views} views per expression cannot be {camera.min_separation_deg:g} degrees apart inside "
            f"azimuth {list(camera.azimuth_deg)} x elevation {list(camera.elevation_deg)}: at most {n_max} fit "
            "(spherical-cap packing bound)", "dataset.views_per_expression",
            f"use at most {n_max} views, a smaller camera.min_separation_deg, or wider camera ranges")


# --------------------------------------------------------------------------- sampling


def uniforms_to_spherical(u: np.ndarray, camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 3) uniforms -> azimuth_deg, elevation_deg, radius_m."""
    a0, a1 = camera.azimuth_deg
    e0, e1 = camera.elevation_deg
    r0, r1 = camera.radius_m
    az = a0 + u[..., 0] * (a1 - a0)
    if camera.elevation_sampling == "area":
        s0, s1 = exact.sin(np.deg2rad([e0, e1]))
        el = np.degrees(exact.asin(np.clip(s0 + u[..., 1] * (s1 - s0), -1.0, 1.0)))
        el = np.clip(el, e0, e1)
    else:
        el = e0 + u[..., 1] * (e1 - e0)
    radius = r0 + u[..., 2] * (r1 - r0)
    return az, el, radius


@dataclass
class Views:
    azimuth_deg: np.ndarray  # (P, V)
    elevation_deg: np.ndarray
    radius_m: np.ndarray
    radius_u: np.ndarray  # (P, V) the uniform behind radius_m (camera.distance = 'fit' maps it to a fill)
    candidates: np.ndarray  # (P,) candidates drawn, all tries
    restarts: np.ndarray  # (P,)
    filled: np.ndarray | None = None  # (P,) bool, only with strict=False: the expression got all views


def candidate_uniforms(seed: int, identity: np.ndarray, expression: np.ndarray, first: np.ndarray,
                       count: int) -> np.ndarray:
    """(P, count, 3) uniforms of candidates first[p] .. first[p] + count - 1.

    Candidate k is word k % 4 of CAMERA block k // 4 + 1; the word's three 21-bit fields are the
    azimuth, elevation and radius uniforms (resolution 2**-21: 1.7e-4 degrees over 360)."""
    first = np.asarray(first, np.int64)
    nb = count // 4 + 1
    draws = first[:, None] // 4 + 1 + np.arange(nb)[None, :]
    words = seeds.blocks(seed, seeds.Stream.CAMERA, identity[:, None], expression[:, None], None, draw=draws)
    words = np.take_along_axis(words.reshape(len(first), nb * 4), (first % 4)[:, None] + np.arange(count), axis=1)
    shifts = np.array([43, 22, 1], np.uint64)
    fields = (words[..., None] >> shifts) & np.uint64((1 << 21) - 1)
    return (fields.astype(np.float64) + 0.5) * (1.0 / (1 << 21))


def _clear_of(c: np.ndarray, dx, dy, dz, count, cos_chk, mask: bool) -> tuple[np.ndarray, np.ndarray]:
    """Distance checks of a batch of candidates c (A, B, 3) against the accepted views
    d* (V, A) (slot-major, so the max over slots reduces contiguous slabs). Returns
    ok_old (A, B): clear of every accepted view (slots >= count[a] are ignored: masked when
    ``mask``, else they hold zero vectors); and conflict (A, B, B): pairs within the batch
    closer than the angle."""
    A, B, _ = c.shape
    V = dx.shape[0]
    ok_old = np.empty((A, B), bool)
    conflict = np.empty((A, B, B), bool)
    for s in range(0, A, _CHUNK):
        e = min(A, s + _CHUNK)
        # contiguous copies (the same values): the products below then stream through memory
        x, y, z = (np.ascontiguousarray(c[s:e, :, j]) for j in range(3))
        n = min(V, int(count[s:e].max()))  # only the filled slots
        if n == 0:
            ok_old[s:e] = True
        else:
            t = dx[:n, s:e, None] * x[None]
            t += dy[:n, s:e, None] * y[None]
            t += dz[:n, s:e, None] * z[None]
            if mask:
                t[np.broadcast_to(np.arange(n)[:, None, None] >= count[None, s:e, None], t.shape)] = -2.0
            ok_old[s:e] = t.max(axis=0) <= cos_chk
        u = x[:, :, None] * x[:, None, :]
        u += y[:, :, None] * y[:, None, :]
        u += z[:, :, None] * z[:, None, :]
        conflict[s:e] = u > cos_chk
    return ok_old, conflict


def sample_views(seed: int, identity: np.ndarray, expression: np.ndarray, n_views: int, camera,
                 strict: bool = True) -> Views:
    """Views for the expressions (identity[p], expression[p]), p = 0..P-1. Bounded: raises
    SynthError when an expression cannot be filled within ``camera.max_candidates``
    (``strict=False``: gives up on it instead and reports it in ``Views.filled``)."""
    identity = np.asarray(identity, np.int64).reshape(-1)
    expression = np.asarray(expression, np.int64).reshape(-1)
    P, V = identity.size, int(n_views)
    sep = effective_separation(camera.min_separation_deg)
    cos_min = float(exact.cos(np.deg2rad(sep)))
    check = V > 1 and sep > 0
    # float32 cosines with a margin that covers their rounding are fast and exact enough for
    # wide angles; small angles need float64 (the margin alone would reject up to ~0.1 deg)
    dt = np.float32 if sep >= _F32_MIN_DEG else np.float64
    # unused slots hold the zero vector (dot 0 passes when the angle is <= 90 deg); else mask
    mask_slots = cos_min < 0.0
    per_try = max(1, camera.max_candidates // (camera.restarts + 1))
    az, el, rad, ru = np.zeros((P, V)), np.zeros((P, V)), np.zeros((P, V)), np.zeros((P, V))
    # accepted directions, float32: cosines are compared with a margin that covers its rounding
    dx, dy, dz = (np.zeros((V, P), dt) for _ in range(3))
    cos_chk = dt(cos_min - _COS_MARGIN) if dt is np.float32 else cos_min
    count = np.zeros(P, np.int64)
    drawn = np.zeros(P, np.int64)  # candidates consumed
    try_start = np.zeros(P, np.int64)
    restarts = np.zeros(P, np.int64)
    active = np.arange(P)
    failed = np.zeros(P, bool)
    batch = _BATCH
    while active.size:
        A = active.size
        u = candidate_uniforms(seed, identity[active], expression[active], drawn[active], batch)
        c_az, c_el, c_r = uniforms_to_spherical(u, camera)
        c = spherical_offset(c_az, c_el)  # (A, B, 3)
        cx, cy, cz = c[..., 0], c[..., 1], c[..., 2]
        cnt0 = count[active]
        budget = np.minimum(per_try - (drawn[active] - try_start[active]), batch)
        room = V - cnt0
        if check:
            ok_old, d_new = _clear_of(c.astype(dt, copy=False), dx[:, active], dy[:, active], dz[:, active],
                                      cnt0, cos_chk, mask_slots)
            blocked = np.zeros((A, batch), bool)
        acc = np.zeros((A, batch), bool)
        n_acc = np.zeros(A, np.int64)
        for b in range(batch):
            ok = (n_acc < room) & (b < budget)
            if check:
                ok &= ok_old[:, b] & ~blocked[:, b]
                blocked |= ok[:, None] & d_new[:, b, :]
            acc[:, b] = ok
            n_acc += ok
        rows, cols = np.nonzero(acc)  # row-major: accepted candidates in draw order
        slot = cnt0[rows] + (np.cumsum(acc, axis=1)[rows, cols] - 1)
        p = active[rows]
        az[p, slot], el[p, slot], rad[p, slot] = c_az[rows, cols], c_el[rows, cols], c_r[rows, cols]
        ru[p, slot] = u[rows, cols, 2]
        dx[slot, p], dy[slot, p], dz[slot, p] = cx[rows, cols], cy[rows, cols], cz[rows, cols]
        # candidates consumed: up to the one that completed the set, else all considered, so
        # the counts (and where a restart begins) never depend on the batch size
        last = batch - 1 - np.argmax(acc[:, ::-1], axis=1)
        done = cnt0 + n_acc >= V
        drawn[active] += np.where(done, last + 1, budget)
        count[active] += n_acc
        # jammed tries restart; exhausted expressions fail
        jam = (count[active] < V) & (drawn[active] - try_start[active] >= per_try)
        if jam.any():
            j = active[jam]
            worn = (restarts[j] >= camera.restarts) | (drawn[j] >= camera.max_candidates)
            if worn.any() and not strict:
                failed[j[worn]] = True
                j = j[~worn]
            elif worn.any():
                q = int(j[np.argmax(worn)])
                raise SynthError(
                    f"could not place {V} views {camera.min_separation_deg:g} degrees apart for identity "
                    f"{identity[q]} expression {expression[q]} within {camera.max_candidates} candidates "
                    f"({camera.restarts} restarts; the last try placed {int(count[q])})", "camera sampling",
                    "lower dataset.views_per_expression or camera.min_separation_deg, widen the camera ranges, "
                    "or raise camera.max_candidates / camera.restarts")
            restarts[j] += 1
            count[j] = 0
            dx[:, j], dy[:, j], dz[:, j] = 0.0, 0.0, 0.0
            try_start[j] = drawn[j]
        active = active[(count[active] < V) & ~failed[active]]
        batch = _BATCH if active.size > P // 8 else 4 * _BATCH
    return Views(az, el, rad, ru, drawn, restarts, None if strict else ~failed)


def fit_distances(head_radius: np.ndarray, u: np.ndarray, camera, fov_deg: float, resolution) -> np.ndarray:
    """Camera distances at which spheres of ``head_radius`` (metres) centred on the look-at point
    have the angular radius ``fill * half_fov``, with ``fill = head_fill[0] + u * (head_fill[1] -
    head_fill[0])`` and half_fov the half field of view of the shorter image side. Raises
    SynthError when a distance falls outside (near_m, far_m)."""
    W, H = resolution
    half_h = np.deg2rad(fov_deg) / 2.0
    half = min(half_h, float(exact.atan(exact.tan(half_h) * H / W)))
    f0, f1 = camera.head_fill
    d = head_radius / exact.sin((f0 + np.asarray(u) * (f1 - f0)) * half)
    if d.size and not (d.min() > camera.near_m and d.max() < camera.far_m):
        raise SynthError(f"fitting the head into the frame needs camera distances {d.min():.3g}-{d.max():.3g} m, "
                         f"outside near_m {camera.near_m} .. far_m {camera.far_m}", "camera.distance = 'fit'",
                         "change camera.head_fill, the field of view, near_m / far_m, or use distance = 'range'")
    return d


def min_pairwise_angle_deg(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """(P,) smallest angle between the viewing directions of each row of views."""
    d = spherical_offset(azimuth_deg, elevation_deg)
    g = (d[:, :, None, 0] * d[:, None, :, 0] + d[:, :, None, 1] * d[:, None, :, 1]) + d[:, :, None, 2] * d[:, None, :, 2]
    V = d.shape[1]
    g[:, np.arange(V), np.arange(V)] = -1.0
    return np.degrees(exact.acos(np.clip(g.max(axis=(1, 2)), -1.0, 1.0)))
