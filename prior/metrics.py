"""Image metrics for evaluation: PSNR, SSIM and LPIPS, optionally on a foreground mask.

Images are (H, W, 3) or (B, 3, H, W) tensors in [0, 1] (numpy arrays are accepted); a single
image gives a 0-d result, a batch a (B,) one. Masks are (H, W), (H, W, 1), (B, H, W) or
(B, 1, H, W) with values in [0, 1] (binary, or soft weights).

Without a mask the definitions are the standard ones:

- PSNR = 10 log10(1 / MSE) over all pixels and channels (data range 1);
- SSIM: Wang et al. 2004 with an 11-tap Gaussian window (sigma 1.5), K1 = 0.01, K2 = 0.03,
  data range 1, per channel over the window positions that fit inside the image ("valid"),
  averaged over positions and channels (as pytorch-msssim and scikit-image's
  ``structural_similarity(gaussian_weights=True, use_sample_covariance=False)``);
- LPIPS: :class:`prior.lpips.LPIPS` (v0.1, VGG16 by default).

Masking rule (the foreground evaluation): both images are first composited over black
(``a * m``, ``b * m``), so background content never differs; then each score is averaged
over the mask instead of over the whole image: PSNR's MSE over the masked pixels, SSIM's map
over the window centres weighted by the mask there, LPIPS's per-layer distance maps over the
mask resized to each layer's grid (area averaging). Soft masks act as weights. A mask that
selects nothing is an error.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from synth.errors import SynthError

_lpips_nets: dict[str, torch.nn.Module] = {}


def _images(a, b) -> tuple[torch.Tensor, torch.Tensor, bool]:
    a, b = torch.as_tensor(np.asarray(a) if not torch.is_tensor(a) else a), \
        torch.as_tensor(np.asarray(b) if not torch.is_tensor(b) else b)
    if a.shape != b.shape:
        raise SynthError(f"images differ in shape: {tuple(a.shape)} vs {tuple(b.shape)}", "metrics",
                         "compare images of the same size")
    single = a.dim() == 3
    if single:
        if a.shape[-1] != 3:
            raise SynthError(f"a single image must be (H, W, 3), got {tuple(a.shape)}", "metrics", "pass RGB images")
        a, b = a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None]
    if a.dim() != 4 or a.shape[1] != 3:
        raise SynthError(f"images must be (H, W, 3) or (B, 3, H, W), got {tuple(a.shape)}", "metrics",
                         "pass RGB images")
    dt = a.dtype if a.is_floating_point() else torch.float32
    return a.to(dt), b.to(dt), single


def _mask(mask, a: torch.Tensor) -> torch.Tensor | None:
    if mask is None:
        return None
    m = torch.as_tensor(np.asarray(mask) if not torch.is_tensor(mask) else mask).to(a.dtype)
    if m.dim() == 3 and m.shape[-1] == 1 and m.shape[:2] == a.shape[-2:]:
        m = m[..., 0]
    if m.dim() == 2:
        m = m[None, None]
    elif m.dim() == 3:
        m = m[:, None]
    if m.dim() != 4 or m.shape[1] != 1 or m.shape[-2:] != a.shape[-2:] or m.shape[0] not in (1, a.shape[0]):
        raise SynthError(f"mask of shape {tuple(torch.as_tensor(mask).shape)} does not fit images "
                         f"{tuple(a.shape)}", "metrics", "pass (H, W) or (B, 1, H, W) masks")
    m = m.expand(a.shape[0], 1, *a.shape[-2:])
    if torch.any(m.flatten(1).sum(1) <= 0):
        raise SynthError("the mask selects no pixel", "metrics", "evaluate images whose mask is not empty")
    return m


def _out(x: torch.Tensor, single: bool) -> torch.Tensor:
    return x[0] if single else x


def psnr(a, b, mask=None) -> torch.Tensor:
    a, b, single = _images(a, b)
    m = _mask(mask, a)
    se = (a - b).square()
    if m is None:
        mse = se.mean(dim=(1, 2, 3))
    else:
        mse = (se * m).sum(dim=(1, 2, 3)) / (3.0 * m.sum(dim=(1, 2, 3)))
    return _out(10.0 * torch.log10(1.0 / mse), single)


def gaussian_window(size: int = 11, sigma: float = 1.5, dtype=torch.float64) -> torch.Tensor:
    x = torch.arange(size, dtype=dtype) - (size - 1) / 2.0
    g = torch.exp(-x.square() / (2.0 * sigma * sigma))
    return g / g.sum()


def ssim_map(a: torch.Tensor, b: torch.Tensor, size: int = 11, sigma: float = 1.5, k1: float = 0.01,
             k2: float = 0.03) -> torch.Tensor:
    """(B, C, H - size + 1, W - size + 1) SSIM at every window position inside the image."""
    if min(a.shape[-2:]) < size:
        raise SynthError(f"images of {a.shape[-1]}x{a.shape[-2]} are smaller than the {size}-pixel SSIM window",
                         "metrics", "evaluate larger images")
    g = gaussian_window(size, sigma, a.dtype).to(a.device)
    C = a.shape[1]
    gx, gy = g.view(1, 1, 1, size).repeat(C, 1, 1, 1), g.view(1, 1, size, 1).repeat(C, 1, 1, 1)

    def blur(x):
        return F.conv2d(F.conv2d(x, gx, groups=C), gy, groups=C)

    mu_a, mu_b = blur(a), blur(b)
    saa = blur(a * a) - mu_a.square()
    sbb = blur(b * b) - mu_b.square()
    sab = blur(a * b) - mu_a * mu_b
    c1, c2 = k1 ** 2, k2 ** 2
    return ((2 * mu_a * mu_b + c1) * (2 * sab + c2)) / ((mu_a.square() + mu_b.square() + c1) * (saa + sbb + c2))


def ssim(a, b, mask=None) -> torch.Tensor:
    a, b, single = _images(a, b)
    m = _mask(mask, a)
    if m is None:
        return _out(ssim_map(a, b).mean(dim=(1, 2, 3)), single)
    s = ssim_map(a * m, b * m).mean(1, keepdim=True)
    r = 5  # (11 - 1) / 2: the mask at the window centres
    mc = m[..., r:m.shape[-2] - r, r:m.shape[-1] - r]
    if torch.any(mc.flatten(1).sum(1) <= 0):
        raise SynthError("the mask covers no SSIM window centre (it lies within 5 px of the border)", "metrics",
                         "evaluate a larger foreground")
    return _out((s * mc).sum(dim=(1, 2, 3)) / mc.sum(dim=(1, 2, 3)), single)


def lpips(a, b, net: str = "vgg", mask=None) -> torch.Tensor:
    from prior.lpips import LPIPS

    a, b, single = _images(a, b)
    m = _mask(mask, a)
    if net not in _lpips_nets:
        _lpips_nets[net] = LPIPS(net)
    model = _lpips_nets[net].to(a.device)
    if a.dtype != torch.float32:
        a, b, m = a.float(), b.float(), None if m is None else m.float()
    with torch.no_grad():
        if m is None:
            return _out(model(a, b), single)
        total = 0.0
        for d in model.layer_distances(a * m, b * m):
            ml = F.adaptive_avg_pool2d(m, d.shape[-2:])
            total = total + (d * ml).sum(dim=(1, 2, 3)) / ml.sum(dim=(1, 2, 3)).clamp_min(1e-12)
        return _out(total, single)
