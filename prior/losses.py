"""Losses of the prior (Cafca, Sec. 3.2 and the supplementary "Losses"), one function each,
every one a mean over rays of a per-ray quantity (float32; cast here).

- :func:`l1_loss`: mean absolute colour error (prior and fine-tuning);
- :func:`proposal_loss`: mip-NeRF 360's Eq. 13 on the model's ``history`` (prior and
  fine-tuning); the NeRF weights are a stop-gradient target;
- :func:`distortion_loss`: mip-NeRF 360's distortion on normalised distance s (fine-tuning);
- :func:`normal_consistency_loss`: predicted vs analytic normals (fine-tuning);
- :func:`orientation_loss`: Ref-NeRF's back-facing normal penalty (optional);
- :func:`view_l2_loss`: L2 of the view-branch weights (fine-tuning).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import torch

from . import stepfun

_EPS = 1e-10


def _masked_mean(per_ray: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    if weights is None:
        return per_ray.mean()
    weights = weights.float()
    return (per_ray * weights).sum() / weights.sum().clamp_min(_EPS)


def l1_loss(pred: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """Mean |pred - target| over rays and channels; ``weights`` (N,) (a mask, or
    importance weights) makes it a weighted mean over rays (0 when they sum to 0)."""
    per_ray = (pred.float() - target.float()).abs().mean(dim=-1)
    return _masked_mean(per_ray, weights)


def proposal_loss(history: Sequence[tuple[torch.Tensor, torch.Tensor]], eps: float = 1e-7) -> torch.Tensor:
    """Sum over proposal levels of the mean over rays of
    ``sum_i max(0, w_i - bound_i)^2 / (w_i + eps)``: the NeRF weights ``w`` (last entry
    of ``history``, gradient stopped) must lie under the envelope ``bound`` of each
    proposal level's weights. ``history``: [(edges, weights)] per level, the model's."""
    s_nerf, w_nerf = history[-1]
    s_nerf, w_nerf = s_nerf.detach().float(), w_nerf.detach().float()
    total = torch.zeros((), device=w_nerf.device)
    for s_prop, w_prop in history[:-1]:
        penalty = stepfun.proposal_penalty(s_nerf, w_nerf, s_prop.detach().float(), w_prop.float(), eps)
        total = total + penalty.sum(dim=-1).mean()
    return total


def distortion_loss(s: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Mean over rays of ``sum_ij w_i w_j |m_i - m_j| + 1/3 sum_i w_i^2 (s_{i+1} - s_i)``
    on interval edges ``s`` (N, n+1), normalised ray distance (the model's ``s``)."""
    return stepfun.distortion(s.float(), weights.float()).mean()


def normal_consistency_loss(weights: torch.Tensor, normals_analytic: torch.Tensor,
                            normals_pred: torch.Tensor, *, stop_weight_grad: bool = False) -> torch.Tensor:
    """Mean over rays of ``sum_i w_i (1 - n_i . n^_i)`` (per-sample normals (N, S, 3)).
    ``stop_weight_grad`` keeps the loss from moving the density through the weights."""
    w = weights.detach() if stop_weight_grad else weights
    cos = (normals_analytic.float() * normals_pred.float()).sum(dim=-1)
    return (w.float() * (1 - cos)).sum(dim=-1).mean()


def orientation_loss(weights: torch.Tensor, normals: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """Mean over rays of ``sum_i w_i max(0, n_i . d)^2``: penalises visible normals that
    face away from the camera (Ref-NeRF); normals (N, S, 3), unit directions (N, 3)."""
    facing = (normals.float() * directions.float()[:, None, :]).sum(dim=-1).clamp_min(0)
    return (weights.float() * facing * facing).sum(dim=-1).mean()


def view_l2_loss(params: Iterable[torch.Tensor]) -> torch.Tensor:
    """Sum of squares of the given parameters (``model.view_branch_parameters()``)."""
    squares = [(p.float() ** 2).sum() for p in params]
    return torch.stack(squares).sum() if squares else torch.zeros(())
