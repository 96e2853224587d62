"""Ray bounds from each identity's bounding sphere.

The frames record no bounding volume, so it is computed from the data: every foreground depth
pixel (depth > 0, alpha > 0) of an identity's frames is back-projected along its ray (planar
depth z = t * cos_z), and the sphere around those points (centre: the middle of their
axis-aligned box; radius: the farthest point) is grown by ``margin`` (relative). Rays are cut
to their intersection with that sphere; rays that miss it get ``near = far`` and are left out
of the loss.
"""

from __future__ import annotations

import numpy as np

from synth.dataset.reader import camera_rays


def foreground_points(frame) -> np.ndarray:
    """(M, 3) float64 world points of a frame's foreground depth pixels."""
    return depth_points(frame.depth, frame.alpha, frame.K, frame.camera_to_world)


def depth_points(depth: np.ndarray, alpha: np.ndarray, K, camera_to_world) -> np.ndarray:
    """(M, 3) float64 world points of the foreground depth pixels (depth > 0, alpha > 0) of an
    (H, W) depth and alpha seen by camera ``K``, ``camera_to_world``."""
    fg = (depth > 0) & (alpha > 0) & np.isfinite(depth)
    rows, cols = np.nonzero(fg)
    if rows.size == 0:
        return np.zeros((0, 3))
    o, d, cos_z = camera_rays(K, camera_to_world, depth.shape[1], depth.shape[0], pixels=(rows, cols),
                              dtype=np.float64)
    t = depth[rows, cols].astype(np.float64) / cos_z
    return o + t[:, None] * d


def tight_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (middle of the axis-aligned box) and radius (farthest point) of the points."""
    p = np.asarray(points, np.float64)
    centre = 0.5 * (p.min(0) + p.max(0))
    return centre, float(np.sqrt(((p - centre) ** 2).sum(1).max()))


def grow(radius: float, margin: float) -> float:
    """A tight radius times 1 + margin, plus 1 micrometre (for float32 inputs)."""
    return radius * (1.0 + margin) + 1e-6


def bounding_sphere(points: np.ndarray, margin: float) -> tuple[np.ndarray, float]:
    """Centre (middle of the axis-aligned box) and radius (farthest point, times 1 + margin,
    plus 1 micrometre for float32 inputs) of a sphere holding every point."""
    centre, radius = tight_sphere(points)
    return centre, grow(radius, margin)


def intersect_sphere(origins: np.ndarray, directions: np.ndarray, centre: np.ndarray,
                     radius: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """near, far (N,) distances of unit rays through spheres (centre (N, 3) or (3,), radius (N,)
    or scalar); ``near >= 0`` (an origin inside starts at 0); rays that miss get near = far = 0."""
    oc = origins.astype(np.float64) - centre
    d = directions.astype(np.float64)
    b = (oc * d).sum(-1)
    c = (oc * oc).sum(-1) - np.asarray(radius, np.float64) ** 2
    disc = b * b - c
    hit = disc > 0
    s = np.sqrt(np.where(hit, disc, 0.0))
    near = np.maximum(-b - s, 0.0)
    far = np.maximum(-b + s, 0.0)
    hit &= far > near
    return np.where(hit, near, 0.0), np.where(hit, far, 0.0)
