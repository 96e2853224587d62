"""Model fitting (Cafca Sec. 3.3, Eq. 7; supplementary "Optimization" and "Losses").

Every network parameter (proposal and NeRF MLPs) and the latent ``w`` are optimised; the codes
(beta, per-image psi) and the cameras stay fixed. Each step draws ``rays_per_step`` random
rays over the pixels of all input views at their own resolution (no patches): a share
``face_fraction`` of them uniformly among the pixels of the views' face regions (the hull of each
image's landmarks, :func:`prior.fit.views.face_region`), the others uniformly over every pixel;
and minimises

    L1(rgb, target) + proposal_weight * L_prop + normal_weight * L_normal
                    + view_weight * L_view + distortion_weight * L_dist

(:mod:`prior.losses`): the target is the input colour multiplied by its foreground mask, so the
model learns empty space over the background. Adam and the learning-rate schedule are the
prior's (:mod:`prior.train.optim`), with per-group gradient clipping (proposal, NeRF, w).

Step ``s`` draws its rays from ``numpy.random.default_rng([FINETUNE_STREAM, seed, s])`` and its
stratified jitter from a torch generator seeded the same way.
"""

from __future__ import annotations

import contextlib

import numpy as np
import torch

from prior import losses
from prior.fit.config import FinetuneConfig
from prior.fit.invert import step_seed
from prior.fit.views import ViewSet
from prior.precision import resolve_bf16
from prior.train.optim import clip_per_group, learning_rate, set_learning_rate
from synth.errors import SynthError

FINETUNE_STREAM = 0xF17E


def draw_rays(views: ViewSet, step: int, seed: int, n: int, face_fraction: float = 0.0,
              face_pixels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(view, flat pixel) of ``n`` rays: ``round(face_fraction * n)`` of them uniform over the face
    regions' pixels (``face_pixels``: their flat indices over all views, :func:`face_pixels`), the
    rest uniform over every pixel of every view (one size). Without a face region every ray is
    uniform (the draws of ``face_fraction = 0``)."""
    H, W = views.size
    rng = np.random.default_rng([FINETUNE_STREAM, seed, step])
    k = 0 if face_pixels is None or face_pixels.size == 0 else int(round(face_fraction * n))
    flat = rng.integers(0, len(views) * H * W, n - k)
    if k:
        flat = np.concatenate([flat, face_pixels[rng.integers(0, face_pixels.size, k)]])
    return np.divmod(flat, H * W)


def face_pixels(views: ViewSet) -> np.ndarray | None:
    """Flat indices (over all views) of the views' face-region pixels; None without a region."""
    return None if views.face is None else np.flatnonzero(views.face.reshape(-1))


def fit_loss(model, out: dict, target: torch.Tensor, valid: torch.Tensor, cfg: FinetuneConfig) -> dict:
    """The terms of Eq. 7 (unweighted) and their weighted sum under ``loss``."""
    terms = {"l1": losses.l1_loss(out["rgb"], target, valid), "proposal": losses.proposal_loss(out["history"]),
             "distortion": losses.distortion_loss(out["s"], out["weights"]),
             "view": losses.view_l2_loss(model.view_branch_parameters())}
    if "sample_normals_analytic" in out:
        terms["normal"] = losses.normal_consistency_loss(out["weights"], out["sample_normals_analytic"],
                                                         out["sample_normals_pred"])
    weights = {"l1": 1.0, "proposal": cfg.proposal_weight, "distortion": cfg.distortion_weight,
               "view": cfg.view_weight, "normal": cfg.normal_weight}
    terms["loss"] = sum(weights[k] * v for k, v in terms.items())
    return terms


def finetune(model, views: ViewSet, w0: torch.Tensor, cfg: FinetuneConfig, *, seed: int = 0, device="cpu",
             progress=None, log_every: int = 10) -> tuple[torch.Tensor, list[dict]]:
    """Fine-tune ``model`` in place and ``w`` from ``w0``; returns ``w`` and the losses of every
    ``log_every``-th step (and the last)."""
    dev = torch.device(device)
    w = torch.nn.Parameter(w0.detach().clone().to(dev))
    if cfg.steps == 0:
        return w.detach(), []
    groups = [{"params": list(model.proposal.parameters()), "name": "proposal"},
              {"params": list(model.nerf.parameters()), "name": "nerf"}, {"params": [w], "name": "latent"}]
    for g in groups:
        for p in g["params"]:
            p.requires_grad_(True)
    opt = torch.optim.Adam(groups, lr=cfg.lr_init, betas=(cfg.adam_beta1, cfg.adam_beta2), eps=cfg.adam_eps)
    normals = cfg.normal_weight > 0
    bf16, _ = resolve_bf16(cfg.bf16, dev, "finetune.bf16")
    history = []
    faces = face_pixels(views) if cfg.face_fraction > 0 else None
    model.train()
    for step in range(cfg.steps):
        set_learning_rate(opt, learning_rate(step, cfg))
        vi, pix = draw_rays(views, step, seed, cfg.rays_per_step, cfg.face_fraction, faces)
        b = views.rays(vi, pix, dev)
        gen = torch.Generator(device=dev).manual_seed(step_seed(FINETUNE_STREAM, seed, step))
        amp = torch.autocast(dev.type, dtype=torch.bfloat16) if bf16 else contextlib.nullcontext()
        with amp:
            out = model(b.rays.with_latent(w), randomized=True, generator=gen, compute_normals=normals)
        terms = fit_loss(model, out, b.target, b.valid, cfg)
        opt.zero_grad(set_to_none=True)
        terms["loss"].backward()
        norms = clip_per_group(opt, cfg.grad_clip)
        if not torch.isfinite(terms["loss"]) or not all(torch.isfinite(torch.as_tensor(v)) for v in norms.values()):
            raise SynthError(f"fine-tuning loss or gradient is not finite at step {step}", "synth prior fit",
                             "lower finetune.lr_init")
        opt.step()
        done = step + 1
        if done % log_every == 0 or done == cfg.steps or step == 0:
            with torch.no_grad():
                mse = (((out["rgb"] - b.target) ** 2).mean(-1) * b.valid).sum() / b.valid.sum().clamp_min(1)
            rec = {"step": done, **{k: float(v.detach()) for k, v in terms.items()},
                   "psnr": float(-10 * torch.log10(mse.clamp_min(1e-12))), "lr": opt.param_groups[0]["lr"]}
            history.append(rec)
            if progress is not None:
                progress("finetune", done, cfg.steps, rec)
    model.eval()
    return w.detach(), history
