"""Per-frame labels computed from the camera and the rendered depth (plain numpy).

Pixel convention: OpenCV camera (x right, y down, z forward), continuous pixel coordinates
with pixel centres at integer + 0.5 (pixel (i, j) covers [i, i+1) x [j, j+1)).
"""

from __future__ import annotations

import numpy as np


def visibility(uv: np.ndarray, z: np.ndarray, depth: np.ndarray, alpha: np.ndarray,
               rel_tol: float = 0.01, abs_tol: float = 0.004, neighbourhood: int = 1) -> np.ndarray:
    """A point is visible when it projects inside the image, in front of the camera, onto a
    covered pixel (alpha > 0.5), and the rendered depth there is not in front of it by more
    than the tolerance. Depth is compared over a (2n+1)^2 pixel neighbourhood (the closest
    match counts), because at low resolution one pixel spans a depth range on sloped skin."""
    H, W = depth.shape
    vis = np.zeros(len(z), bool)
    col = np.floor(uv[:, 0]).astype(np.int64)
    row = np.floor(uv[:, 1]).astype(np.int64)
    inside = (z > 0) & (col >= 0) & (col < W) & (row >= 0) & (row < H)
    for i in np.nonzero(inside)[0]:
        r0, r1 = max(0, row[i] - neighbourhood), min(H, row[i] + neighbourhood + 1)
        c0, c1 = max(0, col[i] - neighbourhood), min(W, col[i] + neighbourhood + 1)
        if alpha[row[i], col[i]] <= 0.5:
            continue
        d = depth[r0:r1, c0:c1]
        a = alpha[r0:r1, c0:c1]
        ok = (a > 0.5) & np.isfinite(d)
        if not ok.any():
            continue
        tol = max(abs_tol, rel_tol * z[i])
        # occluded if the surface at this pixel is clearly in front of the point
        vis[i] = np.min(np.abs(d[ok] - z[i])) <= tol
    return vis
