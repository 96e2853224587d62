"""Warm-up by latent inversion (Cafca Sec. 3.3, Eq. 6; supplementary "Warm-up by Inversion").

Only the latent ``w`` moves: the network, the codes (beta, psi) and the cameras are frozen.
The inputs are downscaled to the prior's resolution (:meth:`ViewSet.resized`); each step
renders ``patches`` random square patches of ``patch_size`` pixels (paper: 4 x 32 x 32 = 4,096
rays) and minimises ``L1 + lpips_weight * LPIPS`` between rendered and target patches (LPIPS
on the sRGB encoding of colour over black, VGG by default; :mod:`prior.lpips`). Adam, learning
rate log-linear from ``lr_init`` to ``lr_final``.

Step ``s`` draws its patches (view, top, left) from ``numpy.random.default_rng([INVERT_STREAM,
seed, s])`` and its stratified jitter from a torch generator seeded the same way: the result
depends only on the seed, not on earlier runs or other processes.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import torch

from prior import losses
from prior.fit.config import InversionConfig
from prior.fit.views import ViewSet
from prior.train.optim import learning_rate
from synth.errors import SynthError

#: first word of the inversion's seeds (other streams of a fit use other words)
INVERT_STREAM = 0x1417
#: smallest patch side each LPIPS backbone accepts (its pooling stages)
MIN_LPIPS_PATCH = {"vgg": 16, "alex": 32}


def srgb_encode(x: torch.Tensor) -> torch.Tensor:
    """Differentiable sRGB encoding of linear colour in [0, 1] (the pow branch is clamped away
    from 0, where its gradient is infinite)."""
    x = x.clamp(0.0, 1.0)
    return torch.where(x <= 0.0031308, 12.92 * x, 1.055 * x.clamp_min(0.0031308) ** (1 / 2.4) - 0.055)


def step_seed(stream: int, seed: int, step: int) -> int:
    return int(np.random.SeedSequence([stream, seed, step]).generate_state(1, np.uint64)[0])


def check_patch_size(cfg: InversionConfig, size_hw: tuple[int, int]) -> None:
    """Patches (shrunk to images smaller than them) must be large enough for the LPIPS backbone."""
    side = min(cfg.patch_size, *size_hw)
    if cfg.lpips_weight > 0 and side < MIN_LPIPS_PATCH[cfg.lpips_net]:
        raise SynthError(f"LPIPS ({cfg.lpips_net}) needs patches of at least {MIN_LPIPS_PATCH[cfg.lpips_net]} px, "
                         f"the inversion's are {side} px", "inversion config",
                         "raise inversion.patch_size or inversion.resolution_factor, or set inversion.lpips_weight=0")


def draw_patches(views: ViewSet, step: int, seed: int, patches: int, size: int) -> tuple[np.ndarray, np.ndarray, int]:
    """(view per ray, flat pixel per ray, patch side) of one step's patches; the side shrinks to
    the image when the image is smaller than a patch."""
    H, W = views.size
    p = min(size, H, W)
    rng = np.random.default_rng([INVERT_STREAM, seed, step])
    v = rng.integers(0, len(views), patches)
    top, left = rng.integers(0, H - p + 1, patches), rng.integers(0, W - p + 1, patches)
    pix = np.concatenate([views.patch_pixels(int(a), int(t), int(l), p) for a, t, l in zip(v, top, left)])
    return np.repeat(v, p * p), pix, p


@torch.no_grad()
def whole_l1(model, views: ViewSet, w: torch.Tensor, *, device="cpu", chunk: int = 4096) -> float:
    """L1 between the rendered and target colours over every pixel of every view whose ray meets the
    bounds (no jitter): one fixed measure of how well ``w`` explains the inputs, comparable before and
    after the inversion (each step's own loss is that of its random patches)."""
    dev = torch.device(device)
    H, W = views.size
    total, count = 0.0, 0.0
    was_training = model.training
    model.eval()
    try:
        for v in range(len(views)):
            for s in range(0, H * W, chunk):
                pix = np.arange(s, min(s + chunk, H * W))
                b = views.rays(np.full(pix.size, v), pix, dev)
                out = model(b.rays.with_latent(w.to(dev).reshape(1, -1)), randomized=False)
                err = (out["rgb"].float() - b.target).abs().mean(-1)
                total += float((err * b.valid).sum())
                count += float(b.valid.sum())
    finally:
        model.train(was_training)
    return total / max(count, 1.0)


def invert_latent(model, views: ViewSet, w0: torch.Tensor, cfg: InversionConfig, *, seed: int = 0,
                  device="cpu", lpips_net=None, progress=None) -> tuple[torch.Tensor, list[dict]]:
    """Optimise ``w`` (latent_dim,) from ``w0``; returns it and the per-step losses.
    ``lpips_net``: a :class:`prior.lpips.LPIPS` (built from ``cfg.lpips_net`` when None and needed)."""
    dev = torch.device(device)
    w = w0.detach().clone().to(dev).requires_grad_(True)
    if cfg.steps == 0:
        return w.detach(), []
    check_patch_size(cfg, views.size)
    if cfg.lpips_weight > 0 and lpips_net is None:
        from prior.lpips import LPIPS

        lpips_net = LPIPS(cfg.lpips_net).to(dev)
    opt = torch.optim.Adam([w], lr=cfg.lr_init)
    schedule = SimpleNamespace(steps=cfg.steps, lr_init=cfg.lr_init, lr_final=cfg.lr_final, warmup_steps=0,
                               warmup_start=1.0)
    frozen = [(p, p.requires_grad) for p in model.parameters()]
    for p, _ in frozen:
        p.requires_grad_(False)
    history = []
    try:
        for step in range(cfg.steps):
            for g in opt.param_groups:
                g["lr"] = learning_rate(step, schedule)
            vi, pix, p = draw_patches(views, step, seed, cfg.patches, cfg.patch_size)
            b = views.rays(vi, pix, dev)
            gen = torch.Generator(device=dev).manual_seed(step_seed(INVERT_STREAM, seed, step))
            out = model(b.rays.with_latent(w), randomized=True, generator=gen)
            l1 = losses.l1_loss(out["rgb"], b.target, b.valid)
            loss = l1
            lp = torch.zeros(())
            if cfg.lpips_weight > 0:
                to_img = lambda x: srgb_encode(x.reshape(-1, p, p, 3).permute(0, 3, 1, 2))  # noqa: E731
                lp = lpips_net(to_img(out["rgb"]), to_img(b.target)).mean()
                loss = l1 + cfg.lpips_weight * lp
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if not torch.isfinite(loss) or not torch.isfinite(w.grad).all():
                raise SynthError(f"inversion loss or gradient is not finite at step {step}", "synth prior fit",
                                 "lower inversion.lr_init")
            opt.step()
            history.append({"step": step + 1, "loss": float(loss.detach()), "l1": float(l1.detach()), "lpips": float(lp.detach())})
            if progress is not None:
                progress("inversion", step + 1, cfg.steps, history[-1])
    finally:
        for p, req in frozen:
            p.requires_grad_(req)
    return w.detach(), history
