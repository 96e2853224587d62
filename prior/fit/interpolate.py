"""Expression codes for novel views (paper Eq. 8): inverse squared distance weighting of the
input images' codes by the distance between the target camera and each input camera,

    psi_t = sum_i w_i psi_i,   w_i = Z / (eps + |l_t - l_i|^2),   sum_i w_i = 1,

with l the camera positions (metres, in the head's frame). A target at an input camera gets
(almost exactly) that image's code; far from all inputs the weights tend to equal ones.
``eps`` (m^2) keeps the weights finite at an input camera.
"""

from __future__ import annotations

import numpy as np

from prior.fit.camera import camera_centres
from synth.errors import SynthError

EPS_M2 = 1e-6


def interpolation_weights(target_positions, input_positions, eps: float = EPS_M2) -> np.ndarray:
    """(T, N) weights (rows sum to 1) for targets (T, 3) or (3,) and input cameras (N, 3)."""
    t = np.atleast_2d(np.asarray(target_positions, np.float64))
    c = np.asarray(input_positions, np.float64)
    if c.ndim != 2 or c.shape[1] != 3 or t.shape[1] != 3 or len(c) == 0:
        raise SynthError(f"camera positions must be (N, 3) with N >= 1, got {c.shape} and {t.shape}",
                         "expression interpolation", "pass camera centres in metres")
    if not eps > 0:
        raise SynthError(f"eps must be positive, got {eps}", "expression interpolation", "use e.g. 1e-6 m^2")
    d2 = ((t[:, None, :] - c[None, :, :]) ** 2).sum(-1)
    w = 1.0 / (eps + d2)
    return w / w.sum(1, keepdims=True)


def interpolate_codes(target_positions, input_positions, codes, eps: float = EPS_M2) -> np.ndarray:
    """(T, ...) interpolated codes from per-input codes (N, ...): expression codes, or any
    per-image array (e.g. small joint rotations)."""
    codes = np.asarray(codes, np.float64)
    w = interpolation_weights(target_positions, input_positions, eps)
    if codes.shape[0] != w.shape[1]:
        raise SynthError(f"{codes.shape[0]} codes for {w.shape[1]} input cameras", "expression interpolation",
                         "pass one code per input image")
    return np.tensordot(w, codes, axes=(1, 0))


def interpolate_for_cameras(target_world_to_camera, input_world_to_camera, codes, eps: float = EPS_M2) -> np.ndarray:
    """:func:`interpolate_codes` with cameras given as world_to_camera matrices ((T,) 4x4 and (N, 4, 4))."""
    return interpolate_codes(camera_centres(np.asarray(target_world_to_camera, np.float64)).reshape(-1, 3),
                             camera_centres(np.asarray(input_world_to_camera, np.float64)), codes, eps)
