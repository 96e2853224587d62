"""Step functions along a ray: sorted interval edges ``t`` (N, n+1) with one value per
interval ``w`` (N, n). The maths of mip-NeRF 360's hierarchical sampling:

- :func:`sample_intervals`: draw new intervals from the histogram ``w`` through its
  inverse CDF (stratified or deterministic);
- :func:`max_dilate_weights`: widen every interval by ``dilation`` on both sides and take
  the maximum density over overlapping intervals (anti-aliases the proposal histogram);
- :func:`anneal_exponent`: the training-fraction schedule of the proposal weights;
- :func:`outer_envelope` and :func:`proposal_penalty`: the upper bound of a histogram on
  other intervals, and mip-NeRF 360's Eq. 13 built on it;
- :func:`distortion`: the distortion loss in O(n).

Each has a brute-force twin in ``tests/prior/test_stepfun.py``. All functions take 2-d
tensors (rays, intervals) and run in float32 with no data-dependent Python control flow.
"""

from __future__ import annotations

import torch

_EPS = 1e-10


def _pad0(x: torch.Tensor) -> torch.Tensor:
    return torch.cat([torch.zeros_like(x[:, :1]), x], dim=-1)


def normalize_weights(w: torch.Tensor) -> torch.Tensor:
    """Non-negative (N, n) -> rows summing to 1; an all-zero row becomes uniform."""
    total = w.sum(dim=-1, keepdim=True)
    return torch.where(total > 0, w / total.clamp_min(_EPS), torch.full_like(w, 1.0 / w.shape[-1]))


def integrate_weights(w: torch.Tensor) -> torch.Tensor:
    """Normalised weights (N, n) -> CDF at the edges (N, n+1), exactly 0 first and 1 last."""
    inner = torch.cumsum(w[:, :-1], dim=-1).clamp_max(1.0)
    return torch.cat([torch.zeros_like(w[:, :1]), inner, torch.ones_like(w[:, :1])], dim=-1)


def invert_cdf(u: torch.Tensor, t: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Points (N, m) of the piecewise-uniform density with interval masses ``w``
    (normalised, (N, n)) on edges ``t`` at the quantiles ``u`` in [0, 1) (N, m).
    Non-decreasing in ``u``; always inside ``[t[:, 0], t[:, -1]]``."""
    n = w.shape[-1]
    cdf = integrate_weights(w)
    idx = (torch.searchsorted(cdf, u.contiguous(), right=True) - 1).clamp(0, n - 1)
    c0, c1 = cdf.gather(1, idx), cdf.gather(1, idx + 1)
    t0, t1 = t.gather(1, idx), t.gather(1, idx + 1)
    frac = ((u - c0) / (c1 - c0).clamp_min(_EPS)).clamp(0.0, 1.0)
    return t0 + frac * (t1 - t0)


def quantiles(num_rays: int, num: int, jitter: torch.Tensor | None = None, device=None) -> torch.Tensor:
    """(num_rays, num) quantiles in [0, 1): bin centres, or ``(i + jitter) / num`` with
    ``jitter`` uniform in [0, 1) of shape (num_rays, num) (stratified) or (num_rays, 1)
    (one shared offset per ray)."""
    base = torch.arange(num, dtype=torch.float32, device=device)
    if jitter is None:
        jitter = torch.full((num_rays, 1), 0.5, dtype=torch.float32, device=device)
    u = (base + jitter.float()) / num
    return u.clamp(0.0, 1.0 - torch.finfo(torch.float32).eps)


def sample_intervals(t: torch.Tensor, w: torch.Tensor, num: int, jitter: torch.Tensor | None = None,
                     domain: tuple[float, float] = (0.0, 1.0)) -> torch.Tensor:
    """``num`` new intervals (edges (N, num+1), sorted, inside ``domain``) drawn from the
    histogram ``w`` (non-negative, normalised here) on edges ``t``: ``num`` points from
    the inverse CDF (at :func:`quantiles` with ``jitter``; None = deterministic) become
    the interval centres; the edges are their midpoints, the two outer edges mirrored
    about the first/last point and clipped to the domain."""
    u = quantiles(t.shape[0], num, jitter, device=t.device)
    c = invert_cdf(u, t, normalize_weights(w))
    mid = (c[:, 1:] + c[:, :-1]) / 2
    first = (2 * c[:, :1] - mid[:, :1]).clamp_min(domain[0])
    last = (2 * c[:, -1:] - mid[:, -1:]).clamp_max(domain[1])
    return torch.cat([first, mid, last], dim=-1)


def _floor_log2_table(n: int, device) -> torch.Tensor:
    return torch.tensor([max(i, 1).bit_length() - 1 for i in range(n + 1)], dtype=torch.long, device=device)


def range_max(v: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """max(v[r, lo:hi+1]) for each query (N, Q) over non-negative v (N, n), the range
    intersected with [0, n); 0 where that is empty. A sparse table: O(n log n) memory, two gathers per query."""
    n = v.shape[-1]
    table = [v]
    span = 1
    while 2 * span <= n:
        prev = table[-1]
        table.append(torch.maximum(prev[:, :-span], prev[:, span:]))
        span *= 2
    table = torch.stack([torch.nn.functional.pad(x, (0, n - x.shape[-1])) for x in table], dim=1)
    flat = table.flatten(1)  # (N, K * n): row k holds max(v[i : i + 2**k])
    lo, hi = lo.clamp_min(0), hi.clamp_max(n - 1)
    valid = lo <= hi
    lo_c, hi_c = lo.clamp_max(n - 1), hi.clamp_min(0)
    k = _floor_log2_table(n, v.device)[(hi_c - lo_c).clamp_min(0) + 1]
    a = flat.gather(1, k * n + lo_c)
    b = flat.gather(1, k * n + (hi_c - torch.bitwise_left_shift(torch.ones_like(k), k) + 1).clamp(0, n - 1))
    return torch.where(valid, torch.maximum(a, b), torch.zeros_like(a))


def max_dilate(t: torch.Tensor, w: torch.Tensor, dilation: float,
               domain: tuple[float, float] = (0.0, 1.0)):
    """Dilate a step function: interval i of ``t`` becomes ``[t_i - d, t_{i+1} + d)`` and
    the new function is, at each point, the maximum ``w`` of the dilated intervals that
    cover it (0 where none). Returns edges (N, 3n+3) clipped to ``domain`` and values
    (N, 3n+2); a point x is covered by interval i when ``t_i <= x + d`` and
    ``t_{i+1} > x - d``. Every breakpoint of the result is among the new edges, so the
    value at each new interval's midpoint is its value everywhere inside it."""
    t_new = torch.sort(torch.cat([t, t - dilation, t + dilation], dim=-1), dim=-1).values
    t_new = t_new.clamp(domain[0], domain[1])
    mid = (t_new[:, 1:] + t_new[:, :-1]) / 2
    lo = torch.searchsorted(t[:, 1:].contiguous(), (mid - dilation).contiguous(), right=True)
    hi = torch.searchsorted(t[:, :-1].contiguous(), (mid + dilation).contiguous(), right=True) - 1
    return t_new, range_max(w, lo, hi)


def max_dilate_weights(t: torch.Tensor, w: torch.Tensor, dilation: float,
                       domain: tuple[float, float] = (0.0, 1.0)):
    """:func:`max_dilate` applied to the density ``w / (t_{i+1} - t_i)`` of interval
    weights ``w``; returns new edges and the new intervals' weights (not normalised)."""
    dt = t[:, 1:] - t[:, :-1]
    pdf = torch.where(dt > 0, w / dt.clamp_min(_EPS), torch.zeros_like(w))
    t_new, pdf_new = max_dilate(t, pdf, dilation, domain)
    return t_new, pdf_new * (t_new[:, 1:] - t_new[:, :-1])


def anneal_exponent(train_frac: float | torch.Tensor, slope: float) -> float | torch.Tensor:
    """mip-NeRF 360's schedule of the exponent on the proposal weights: Schlick's bias
    ``s x / ((s - 1) x + 1)`` of the training fraction x in [0, 1] with slope s: 0 at the
    start (uniform resampling), 1 at the end. ``slope = 0`` turns annealing off (1).
    A 0-d tensor ``train_frac`` gives a tensor (no recompiles under torch.compile)."""
    if slope <= 0:
        return 1.0
    if isinstance(train_frac, torch.Tensor):
        x = train_frac.float().clamp(0.0, 1.0)
    else:
        x = min(max(float(train_frac), 0.0), 1.0)
    return slope * x / ((slope - 1) * x + 1)


def outer_envelope(t: torch.Tensor, t_env: torch.Tensor, w_env: torch.Tensor) -> torch.Tensor:
    """For each interval ``[t_i, t_{i+1})`` of ``t`` (N, n+1), the total weight of the
    intervals of ``(t_env, w_env)`` that overlap it: ``t_env_j < t_{i+1}`` and
    ``t_env_{j+1} > t_i`` (mip-NeRF 360's "bound"). Returns (N, n)."""
    cw = _pad0(torch.cumsum(w_env, dim=-1))
    j_lo = torch.searchsorted(t_env[:, 1:].contiguous(), t[:, :-1].contiguous(), right=True)
    j_hi = torch.searchsorted(t_env[:, :-1].contiguous(), t[:, 1:].contiguous(), right=False)
    return (cw.gather(1, j_hi) - cw.gather(1, j_lo)).clamp_min(0)


def proposal_penalty(t: torch.Tensor, w: torch.Tensor, t_env: torch.Tensor, w_env: torch.Tensor,
                     eps: float = 1e-7) -> torch.Tensor:
    """Per-interval ``max(0, w - bound)^2 / (w + eps)`` (mip-NeRF 360, Eq. 13): how much
    the weights ``w`` exceed the envelope of the proposal ``(t_env, w_env)``. (N, n).
    Callers stop the gradient of ``w``."""
    return (w - outer_envelope(t, t_env, w_env)).clamp_min(0) ** 2 / (w + eps)


def distortion(t: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Per ray (N,): ``sum_ij w_i w_j |m_i - m_j| + 1/3 sum_i w_i^2 (t_{i+1} - t_i)``
    with midpoints m, in O(n) (sorted t): the pairwise term is
    ``2 sum_i w_i (m_i W_{<i} - (w m)_{<i})`` with exclusive prefix sums."""
    m = (t[:, 1:] + t[:, :-1]) / 2
    dt = t[:, 1:] - t[:, :-1]
    wm = w * m
    w_before = _pad0(torch.cumsum(w, dim=-1)[:, :-1])
    wm_before = _pad0(torch.cumsum(wm, dim=-1)[:, :-1])
    inter = 2 * (w * (m * w_before - wm_before)).sum(dim=-1)
    intra = (w * w * dt).sum(dim=-1) / 3
    return inter + intra
