"""Adam over the model's parameter groups, the learning-rate schedule, per-group clipping."""

from __future__ import annotations

import math

import torch

from prior.train.config import TrainConfig


def build_optimizer(model, cfg: TrainConfig) -> torch.optim.Adam:
    """Adam(beta1, beta2, eps) with one parameter group per MLP (``model.param_groups()``)."""
    groups = [{"params": ps, "name": name} for name, ps in model.param_groups().items() if ps]
    return torch.optim.Adam(groups, lr=cfg.lr_init, betas=(cfg.adam_beta1, cfg.adam_beta2), eps=cfg.adam_eps)


def learning_rate(step: int, cfg: TrainConfig) -> float:
    """Exponential decay from lr_init (step 0) to lr_final (step ``steps``), log-linear, times a
    linear warm-up from ``warmup_start`` to 1 over the first ``warmup_steps`` steps."""
    frac = min(max(step / max(cfg.steps, 1), 0.0), 1.0)
    lr = math.exp(math.log(cfg.lr_init) * (1 - frac) + math.log(cfg.lr_final) * frac)
    if cfg.warmup_steps > 0 and step < cfg.warmup_steps:
        lr *= cfg.warmup_start + (1 - cfg.warmup_start) * step / cfg.warmup_steps
    return lr


def set_learning_rate(opt: torch.optim.Optimizer, lr: float) -> None:
    for g in opt.param_groups:
        g["lr"] = lr


def clip_per_group(opt: torch.optim.Optimizer, max_norm: float) -> dict[str, float]:
    """Clip each parameter group's gradient to ``max_norm`` (0 = no clipping); returns the
    norms before clipping (tensors stay on the device until read)."""
    norms = {}
    for g in opt.param_groups:
        ps = [p for p in g["params"] if p.grad is not None]
        if not ps:
            continue
        if max_norm > 0:
            norms[g["name"]] = torch.nn.utils.clip_grad_norm_(ps, max_norm)
        else:
            norms[g["name"]] = torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(p.grad) for p in ps]))
    return norms
