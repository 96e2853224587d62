"""The input views of a fit as rays: masked target colours, fitted cameras, per-image codes, and
the ray bounds (the prior's scene sphere).

Rays go through pixel centres (:func:`synth.dataset.reader.camera_rays`) and carry mip-NeRF
cone radii from their own image's ``K`` (:func:`prior.data.sampler.pixel_radius`), so images
of any resolution are rendered with the right footprint; :meth:`ViewSet.resized` gives the
same views at another resolution (inputs downscaled to the prior's for the inversion).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from prior.data.bounds import intersect_sphere
from prior.data.sampler import pixel_radius
from prior.rays import RayBundle
from synth.dataset.reader import camera_rays


@dataclass
class RayBatch:
    rays: RayBundle  # conditioned on the codes of their images, without a latent
    target: torch.Tensor  # (N, 3) masked linear colour

    @property
    def valid(self) -> torch.Tensor:
        """1 for rays that cross the bounding sphere."""
        return self.rays.valid


@dataclass
class ViewSet:
    target: np.ndarray  # (V, H, W, 3) float32: linear colour times the foreground mask
    K: np.ndarray  # (V, 3, 3) fitted intrinsics of this resolution
    c2w: np.ndarray  # (V, 4, 4) fitted camera_to_world (OpenCV)
    codes: np.ndarray  # (V, C) float32 conditioning codes (beta || psi) per image
    centre: np.ndarray  # (3,) ray bounds: sphere centre
    radius: float
    face: np.ndarray | None = None  # (V, H, W) bool: each image's face region (face_region); None = unknown

    @property
    def size(self) -> tuple[int, int]:
        """(height, width)."""
        return int(self.target.shape[1]), int(self.target.shape[2])

    def __len__(self) -> int:
        return int(self.target.shape[0])

    def rays(self, views: np.ndarray, pixels: np.ndarray, device="cpu") -> RayBatch:
        """Rays of flat pixel indices ``pixels`` (N,) of views ``views`` (N,)."""
        H, W = self.size
        views, pixels = np.asarray(views, np.int64), np.asarray(pixels, np.int64)
        n = views.size
        o, d = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32)
        for v in np.unique(views).tolist():
            sel = views == v
            rows, cols = np.divmod(pixels[sel], W)
            r = camera_rays(self.K[v], self.c2w[v], W, H, pixels=(rows, cols))
            o[sel], d[sel] = r.origins, r.directions
        near, far = intersect_sphere(o, d, self.centre, self.radius)
        rgb = self.target.reshape(len(self), H * W, 3)[views, pixels]
        rays = RayBundle.from_numpy(o, d, near, far, self.codes[views], radii=pixel_radius(self.K[views]),
                                    device=device)
        return RayBatch(rays, torch.as_tensor(rgb, dtype=torch.float32, device=device))

    def resized(self, width: int, height: int) -> "ViewSet":
        """The same views at ``width`` x ``height`` (area-averaged when shrinking, bilinear when
        growing); ``K`` scaled per axis so every pixel still sees the same part of the scene."""
        H, W = self.size
        if (width, height) == (W, H):
            return self
        S = np.diag([width / W, height / H, 1.0])
        face = None if self.face is None else \
            resample(self.face[..., None].astype(np.float32), width, height)[..., 0] >= 0.5
        return ViewSet(resample(self.target, width, height), S @ self.K, self.c2w, self.codes, self.centre,
                       self.radius, face)

    def patch_pixels(self, view: int, top: int, left: int, size: int) -> np.ndarray:
        """Flat pixel indices (size * size,) of a square patch, row-major."""
        H, W = self.size
        r, c = np.mgrid[top:top + size, left:left + size]
        return (r * W + c).reshape(-1)


def face_region(points: np.ndarray, width: int, height: int, grow: float = 0.0) -> np.ndarray:
    """(height, width) bool: the pixels whose centres lie inside the convex hull of the landmark
    positions ``points`` (P, 2) (pixels, finite ones only), the hull scaled by ``1 + grow`` about its
    centroid. With mediapipe's 478 face-mesh points that is the face from the chin to the forehead."""
    from matplotlib.path import Path as MplPath
    from scipy.spatial import ConvexHull, QhullError

    p = np.asarray(points, np.float64).reshape(-1, 2)
    p = p[np.isfinite(p).all(1)]
    out = np.zeros((height, width), bool)
    if len(p) < 3:
        return out
    try:
        hull = p[ConvexHull(p).vertices]
    except QhullError:  # collinear points: no area
        return out
    c = hull.mean(0)
    hull = c + (hull - c) * (1.0 + grow)
    x0, y0 = np.floor(np.clip(hull.min(0), 0, [width, height])).astype(int)
    x1, y1 = np.ceil(np.clip(hull.max(0), 0, [width, height])).astype(int)
    if x1 <= x0 or y1 <= y0:
        return out
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = MplPath(hull).contains_points(np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5], 1))
    out[y0:y1, x0:x1] = inside.reshape(yy.shape)
    return out


def resample(images: np.ndarray, width: int, height: int) -> np.ndarray:
    """(N, H, W, C) float images at ``width`` x ``height``: area-averaged (antialiased bilinear)
    when shrinking, bilinear when growing; pixel corners stay on pixel corners."""
    N, H, W, C = images.shape
    if (width, height) == (W, H):
        return np.asarray(images, np.float32)
    x = torch.from_numpy(np.ascontiguousarray(images, np.float32)).permute(0, 3, 1, 2)
    shrink = width <= W and height <= H
    y = F.interpolate(x, size=(height, width), mode="bilinear", antialias=shrink, align_corners=False)
    return y.permute(0, 2, 3, 1).numpy().astype(np.float32)


def prior_resolution(width: int, height: int, prior_size: tuple[int, int], factor: float = 1.0) -> tuple[int, int]:
    """Input size scaled so that its longer side is ``factor`` times the prior's longer side
    (never enlarged)."""
    s = min(1.0, factor * max(prior_size) / max(width, height))
    return max(1, round(width * s)), max(1, round(height * s))
