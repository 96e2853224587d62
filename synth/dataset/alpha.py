"""The denoised alpha of a render (pure numpy; blender_scripts/passes.py applies it).

Cycles' denoisers (OpenImageDenoise, OptiX) denoise the colour of the film, not its alpha. With a
transparent film the stored colour is premultiplied and denoised while the alpha is the raw
Monte Carlo estimate of the pixel's coverage: at 16 samples a hair fringe's coverage has a
standard deviation up to 0.125 per pixel, so composited over any background the fringe is
salt-and-pepper noise (the colour says one coverage, the alpha another). The render therefore
also denoises the alpha, with OpenImageDenoise (the colour's denoiser on the CPU; a GPU render
may denoise its colour with OptiX) and the colour's albedo and normal guides (a compositor
Denoise node on the alpha, blender_scripts/scene.py), and :func:`merge_denoised_alpha`
takes it where the coverage changes: on and next to pixels whose raw alpha is neither 0 nor
1 or whose 3 x 3 neighbourhood is not constant. Elsewhere (the solid interior, the empty
background) the raw alpha is exact and kept.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def coverage_edges(alpha: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels whose alpha is fractional or differs anywhere in their 3 x 3
    neighbourhood (the image border counts as a copy of the edge pixel)."""
    a = np.asarray(alpha, np.float64)
    changes = ndimage.maximum_filter(a, 3, mode="nearest") > ndimage.minimum_filter(a, 3, mode="nearest")
    return changes | ((a > 0.0) & (a < 1.0))


def merge_denoised_alpha(raw: np.ndarray, denoised: np.ndarray) -> np.ndarray:
    """(H, W) float32 alpha: the denoised alpha (clipped to [0, 1]) on :func:`coverage_edges`
    of the raw alpha, the raw alpha elsewhere."""
    raw = np.asarray(raw, np.float32)
    dn = np.clip(np.nan_to_num(np.asarray(denoised, np.float32), nan=0.0), 0.0, 1.0)
    return np.where(coverage_edges(raw), dn, raw).astype(np.float32)
