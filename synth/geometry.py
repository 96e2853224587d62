"""Small, numerically careful geometry helpers (numpy, batched)."""

from __future__ import annotations

import numpy as np


def axis_angle_to_matrix(r: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for (..., 3) axis-angle vectors -> (..., 3, 3) rotation matrices.

    Stable at 0 (Taylor series for sin(t)/t and (1-cos t)/t^2) and exact at pi.
    Computed in float64 and returned in the input's float dtype.
    """
    r = np.asarray(r)
    out_dtype = r.dtype if r.dtype.kind == "f" else np.float64
    r64 = r.astype(np.float64, copy=False)
    t2 = np.sum(r64 * r64, axis=-1)
    t = np.sqrt(t2)
    small = t2 < 1e-8
    safe_t = np.where(small, 1.0, t)
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(safe_t) / safe_t)  # sin t / t
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(safe_t)) / (safe_t * safe_t))  # (1-cos t)/t^2
    x, y, z = r64[..., 0], r64[..., 1], r64[..., 2]
    zero = np.zeros_like(x)
    K = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], axis=-1).reshape(r64.shape[:-1] + (3, 3))
    eye = np.broadcast_to(np.eye(3), K.shape)
    R = eye + a[..., None, None] * K + b[..., None, None] * (K @ K)
    return R.astype(out_dtype, copy=False)


def matrix_to_axis_angle(R: np.ndarray) -> np.ndarray:
    """Inverse of axis_angle_to_matrix (angle in [0, pi]); stable near 0 and pi."""
    R = np.asarray(R, dtype=np.float64)
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    sin = np.sin(angle)
    out = np.empty(R.shape[:-2] + (3,))
    near_pi = angle > np.pi - 1e-3
    small = sin < 1e-6
    regular = ~near_pi & ~small
    out[regular] = (v[regular] * (angle[regular] / (2.0 * sin[regular]))[..., None])
    out[small & ~near_pi] = v[small & ~near_pi] * 0.5
    if np.any(near_pi):
        Rp = R[near_pi]
        # axis from the largest diagonal of (R + I)/2 = n n^T (for angle ~ pi)
        B = (Rp + np.eye(3)) / 2.0
        i = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
        col = B[np.arange(len(i)), :, i]
        n = col / np.linalg.norm(col, axis=-1, keepdims=True)
        # fix sign with the antisymmetric part when it carries information
        s = np.sign(np.sum(n * v[near_pi], -1))
        s[s == 0] = 1.0
        out[near_pi] = n * (s * angle[near_pi])[..., None]
    return out


def normalize(v: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, eps)
