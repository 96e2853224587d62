"""Positional encodings of the prior: mip-NeRF's integrated positional encoding (IPE) of
conical frustums for positions, and the plain sinusoidal encoding for directions.

A ray ``o + t d`` (``d`` a unit vector) through a pixel is a cone whose radius grows as
``radius * t``. The interval ``[t0, t1]`` of that cone (a conical frustum) is
approximated by the Gaussian of its first two moments (mip-NeRF, Eq. 7, the numerically
stable form in ``t_mu = (t0 + t1)/2`` and ``t_delta = (t1 - t0)/2``), and the encoding is
the expectation of ``sin``/``cos`` of the scaled position under that Gaussian:
``E[sin(a x)] = sin(a mu) exp(-a^2 var / 2)`` per coordinate (diagonal covariance).

Everything here runs in float32 (callers cast before; autocast does not touch these ops).
"""

from __future__ import annotations

import math

import torch

_EPS = 1e-10


def conical_frustum_moments(t0: torch.Tensor, t1: torch.Tensor, radius: torch.Tensor):
    """Moments of the frustum ``[t0, t1]`` of a cone of radius ``radius * t``.

    Returns ``(mean_t, var_t, var_r)``: the mean and variance of the distance along the
    ray and the variance of each of the two perpendicular coordinates, for a point drawn
    uniformly from the frustum's volume. ``radius`` broadcasts against ``t0``. Zero-length
    intervals give the point ``t0`` with ``var_t = 0``; ``t0 = t1 = 0`` gives zeros.
    """
    mu = (t0 + t1) / 2
    hw = (t1 - t0) / 2
    mu2, hw2 = mu * mu, hw * hw
    denom = (3 * mu2 + hw2).clamp_min(_EPS)
    mean_t = mu + 2 * mu * hw2 / denom
    var_t = hw2 / 3 - (4 / 15) * hw2 * hw2 * (12 * mu2 - hw2) / (denom * denom)
    var_r = radius * radius * (mu2 / 4 + (5 / 12) * hw2 - (4 / 15) * hw2 * hw2 / denom)
    return mean_t, var_t.clamp_min(0), var_r.clamp_min(0)


def frustum_gaussians(origins, directions, t, radii):
    """Gaussians (means, diagonal covariances) of the intervals ``t`` of each ray.

    origins, directions: (N, 3), directions of unit length; t: (N, S+1) sorted interval
    edges along the ray; radii: (N,) cone radius at unit distance (0 = a thin ray, which
    reduces the IPE to the plain positional encoding). Returns means (N, S, 3) and
    diagonal variances (N, S, 3).
    """
    mean_t, var_t, var_r = conical_frustum_moments(t[:, :-1], t[:, 1:], radii[:, None])
    d = directions[:, None, :]
    means = origins[:, None, :] + mean_t[..., None] * d
    d2 = d * d
    variances = var_t[..., None] * d2 + var_r[..., None] * (1 - d2)
    return means, variances.clamp_min(0)


def _scales(levels: int, like: torch.Tensor) -> torch.Tensor:
    return torch.pow(2.0, torch.arange(levels, dtype=like.dtype, device=like.device))


def integrated_pos_enc(means: torch.Tensor, variances: torch.Tensor, levels: int) -> torch.Tensor:
    """(..., 3) Gaussian means and diagonal variances -> (..., 6 * levels) features
    ``[sin(2^l x_k) e^(-4^l v_k / 2)]_{l,k}`` followed by the same with ``cos``."""
    scales = _scales(levels, means)
    y = (means[..., None, :] * scales[:, None]).flatten(-2)
    v = (variances[..., None, :] * (scales * scales)[:, None]).flatten(-2)
    damp = torch.exp(-0.5 * v)
    return torch.cat([torch.sin(y) * damp, torch.sin(y + 0.5 * math.pi) * damp], dim=-1)


def pos_enc(x: torch.Tensor, levels: int, include_input: bool = True) -> torch.Tensor:
    """(..., D) -> sinusoidal encoding ``[x, sin(2^l x), cos(2^l x)]`` (levels 0..levels-1)."""
    parts = [x] if include_input else []
    if levels > 0:
        y = (x[..., None, :] * _scales(levels, x)[:, None]).flatten(-2)
        parts += [torch.sin(y), torch.sin(y + 0.5 * math.pi)]
    return torch.cat(parts, dim=-1)


def ipe_dim(levels: int) -> int:
    """Width of :func:`integrated_pos_enc` for 3-d positions."""
    return 6 * levels


def dir_enc_dim(levels: int) -> int:
    """Width of :func:`pos_enc` for 3-d directions with the raw direction included."""
    return 3 + 6 * levels
