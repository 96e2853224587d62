"""The sRGB transfer function (IEC 61966-2-1), the project's one copy: linear <-> encoded values,
and 8-bit images."""

from __future__ import annotations

import numpy as np


def linear_to_srgb(x) -> np.ndarray:
    """Encode linear values (clipped to [0, 1] first)."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_to_linear(x) -> np.ndarray:
    """Decode sRGB values in [0, 1] to linear."""
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def srgb8(linear) -> np.ndarray:
    """Linear values -> 8-bit sRGB (rounded to nearest)."""
    return (linear_to_srgb(linear) * 255 + 0.5).astype(np.uint8)
