"""Per-vertex masks (numpy) from head regions and landmarks: the shader-layer rigs (makeup,
skin detail) and the body of fitted shells use them.

All masks are floats in [0, 1] per head vertex, computed on the current vertices at build
time; they are attached to vertices, so they follow every later expression.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def region_mask(regions: dict, names, n: int) -> np.ndarray:
    """True on the ``n`` vertices of any of the named regions (absent regions: none)."""
    m = np.zeros(n, bool)
    for name in names:
        r = regions.get(name)
        if r is not None:
            m[np.asarray(r, np.int64)] = True
    return m


def distance_to(V: np.ndarray, pts: np.ndarray) -> np.ndarray:
    if len(pts) == 0:
        return np.full(len(V), np.inf)
    return cKDTree(pts).query(V)[0]


def feather(d: np.ndarray, inner: float, outer: float) -> np.ndarray:
    """1 within ``inner``, smooth falloff to 0 at ``outer``."""
    t = np.clip((d - inner) / max(outer - inner, 1e-9), 0.0, 1.0)
    return 1.0 - t * t * (3 - 2 * t)


def segment_distance(V, a, b):
    ab = b - a
    t = np.clip(((V - a) @ ab) / max(ab @ ab, 1e-12), 0, 1)
    return np.linalg.norm(V - (a + t[:, None] * ab), axis=1)


def skin_only(data, n):
    """Vertices that are skin (not eyes, teeth, mouth interior)."""
    return ~region_mask(data.regions, ("eyes", "teeth", "mouth_interior"), n)
