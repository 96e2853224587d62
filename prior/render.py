"""Volume rendering of the prior: hierarchical resampling of a ray's intervals, alpha
compositing, opacity, depth and normals. Always float32 (autocast is switched off here).

Conventions:

- Rays are ``o + t d`` with unit ``d``, bounded per ray by ``[near, far]`` (the head's
  bounding sphere; no scene contraction: the head lives in a bounded ball). Sampling
  works in the normalised distance ``s = (t - near) / (far - near)`` in [0, 1], so every
  ray has the same sampling domain and the distortion loss uses ``s`` as in the paper.
  A ray with ``far <= near`` (it misses the sphere) has zero-length intervals in ``t``:
  zero opacity, its colour is the background, its depth ``far``.
- ``depth`` is the expected distance along the ray, ``sum_i w_i t_mid_i / acc``. The
  dataset stores planar camera z; convert with :func:`planar_depth`.
- Normals point out of the surface (towards the camera on visible surfaces): analytic
  normals are the normalised negative gradient of the density (density grows inwards).
"""

from __future__ import annotations

import torch

from . import stepfun
from .config import SamplingConfig

#: densities are clamped to this before multiplying by interval lengths (inf * 0 = NaN)
MAX_DENSITY = 1e10
_EPS = 1e-10


def alpha_weights(density: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Compositing weights ``w_i = T_i (1 - exp(-sigma_i delta_i))`` with transmittance
    ``T_i = exp(-sum_{j<i} sigma_j delta_j)``; density (N, S), edges t (N, S+1)."""
    density = density.float()
    delta = t[:, 1:] - t[:, :-1]
    sd = torch.where(delta > 0, density.clamp(0, MAX_DENSITY) * delta, torch.zeros_like(density))
    excl = torch.cat([torch.zeros_like(sd[:, :1]), torch.cumsum(sd, dim=-1)[:, :-1]], dim=-1)
    return -torch.expm1(-sd) * torch.exp(-excl)


def composite(weights: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """sum_i w_i v_i: weights (N, S), values (N, S, C) -> (N, C)."""
    return (weights[..., None] * values.float()).sum(dim=-2)


def expected_depth(weights: torch.Tensor, t: torch.Tensor, acc: torch.Tensor) -> torch.Tensor:
    """Expected distance along the ray given that it hit, clipped to the ray's bounds;
    ``t[:, -1]`` (far) where the opacity is 0."""
    mid = (t[:, 1:] + t[:, :-1]) / 2
    depth = (weights * mid).sum(dim=-1) / acc.clamp_min(_EPS)
    depth = torch.minimum(torch.maximum(depth, t[:, 0]), t[:, -1])
    return torch.where(acc > _EPS, depth, t[:, -1])


def planar_depth(depth: torch.Tensor, direction_z_cam: torch.Tensor) -> torch.Tensor:
    """Distance along a unit ray -> camera z (the dataset's depth): multiply by the
    z-component of the ray's direction in camera coordinates (OpenCV, z forward)."""
    return depth * direction_z_cam


def analytic_normals(raw_density: torch.Tensor, positions: torch.Tensor,
                     create_graph: bool) -> torch.Tensor:
    """Outward normals ``-grad(raw density) / |.|`` at ``positions`` (N, S, 3), which must
    require grad and have produced ``raw_density`` (N, S). The pre-activation density has
    the same gradient direction as the density and does not underflow."""
    (grad,) = torch.autograd.grad(raw_density.float().sum(), positions, create_graph=create_graph)
    return -grad / grad.norm(dim=-1, keepdim=True).clamp_min(_EPS)


def normalize(v: torch.Tensor) -> torch.Tensor:
    """Unit vectors along the last axis (zero stays zero)."""
    return v / v.norm(dim=-1, keepdim=True).clamp_min(_EPS)


def initial_intervals(num_rays: int, device) -> tuple[torch.Tensor, torch.Tensor]:
    """Level 0's histogram: the whole ray [0, 1] in s with weight 1."""
    s = torch.tensor([0.0, 1.0], device=device).expand(num_rays, 2)
    return s, torch.ones(num_rays, 1, device=device)


def dilation_for_level(level: int, cfg: SamplingConfig) -> float:
    """Dilation (in s) of the histogram of level ``level - 1`` before resampling level
    ``level``: bias + multiplier / (product of the sample counts of the levels so far)."""
    prod = 1
    for n in cfg.samples_per_level[:level]:
        prod *= int(n)
    return cfg.dilation_bias + cfg.dilation_multiplier / prod


def jitter_widths(cfg: SamplingConfig) -> tuple[int, ...]:
    """Uniforms per ray that each level's stratified sampling consumes."""
    return tuple(1 if cfg.single_jitter else n for n in cfg.samples_per_level)


@torch.compiler.disable
def draw_jitter(num_rays: int, cfg: SamplingConfig, generator: torch.Generator | None,
                device) -> list[torch.Tensor]:
    """All the stratification noise of a batch in one draw from ``generator``: one
    (num_rays, width) tensor per level. Kept out of torch.compile graphs (generators
    break them), so a compiled forward has a single break here."""
    widths = jitter_widths(cfg)
    noise = torch.rand((num_rays, sum(widths)), generator=generator, dtype=torch.float32, device=device)
    return list(torch.split(noise, widths, dim=-1))


def resample(level: int, s: torch.Tensor, w: torch.Tensor, cfg: SamplingConfig, *,
             train_frac: float | torch.Tensor, jitter: torch.Tensor | None = None) -> torch.Tensor:
    """Edges in s (N, n+1) of level ``level`` from the previous level's histogram
    ``(s, w)``: dilate (levels > 0), anneal, pad, then sample (stratified with
    ``jitter``, deterministic without). No gradient flows."""
    s, w = s.detach().float(), w.detach().float()
    if level > 0:
        dilation = dilation_for_level(level, cfg)
        if dilation > 0:
            s, w = stepfun.max_dilate_weights(s, w, dilation, (0.0, 1.0))
        exponent = stepfun.anneal_exponent(train_frac, cfg.anneal_slope)
        w = torch.pow(w + cfg.resample_padding, exponent)
        w = torch.where(s[:, 1:] > s[:, :-1], w, torch.zeros_like(w))
    return stepfun.sample_intervals(s, w, cfg.samples_per_level[level], jitter, (0.0, 1.0))


def ray_bounds(near: torch.Tensor, far: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Sanitised bounds: near >= 0, far >= near (a ray that misses gets far = near)."""
    near = near.float().clamp_min(0)
    return near, torch.maximum(far.float(), near)


def s_to_t(s: torch.Tensor, near: torch.Tensor, far: torch.Tensor) -> torch.Tensor:
    return near[:, None] + s * (far - near)[:, None]
