"""Rotations: axis-angle <-> matrix (numerically careful, batched), rigid fits (Kabsch), the
screw axis of a rigid motion and the minimal rotation between two directions.

``axis_angle_to_matrix`` / ``matrix_to_axis_angle`` are this project's own (Rodrigues with
Taylor terms near 0, an exact branch near pi, dtype kept) because posing the head uses them
per frame and their output is part of the dataset; tests check them against
``scipy.spatial.transform.Rotation``. The rigid fit is scipy's Kabsch
(``Rotation.align_vectors``) after weighted centring.
"""

from __future__ import annotations

import numpy as np

from synth.geometry import exact


def axis_angle_to_matrix(r: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for (..., 3) axis-angle vectors -> (..., 3, 3) rotation matrices.

    Stable at 0 (Taylor series for sin(t)/t and (1-cos t)/t^2) and exact at pi.
    Computed in float64 with :mod:`synth.geometry.exact` (the same bits on every machine) and
    returned in the input's float dtype.
    """
    r = np.asarray(r)
    out_dtype = r.dtype if r.dtype.kind == "f" else np.float64
    r64 = r.astype(np.float64, copy=False)
    t2 = np.sum(r64 * r64, axis=-1)
    t = np.sqrt(t2)
    small = t2 < 1e-8
    safe_t = np.where(small, 1.0, t)
    a = np.where(small, 1.0 - t2 / 6.0, exact.sin(safe_t) / safe_t)  # sin t / t
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - exact.cos(safe_t)) / (safe_t * safe_t))  # (1-cos t)/t^2
    x, y, z = r64[..., 0], r64[..., 1], r64[..., 2]
    zero = np.zeros_like(x)
    K = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], axis=-1).reshape(r64.shape[:-1] + (3, 3))
    eye = np.broadcast_to(np.eye(3), K.shape)
    R = eye + a[..., None, None] * K + b[..., None, None] * exact.matmul3(K, K)
    return R.astype(out_dtype, copy=False)


def matrix_to_axis_angle(R: np.ndarray) -> np.ndarray:
    """Inverse of axis_angle_to_matrix (angle in [0, pi]); stable near 0 and pi."""
    R = np.asarray(R, dtype=np.float64)
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = exact.acos(cos)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    sin = exact.sin(angle)
    out = np.empty(R.shape[:-2] + (3,))
    near_pi = angle > np.pi - 1e-3
    small = sin < 1e-6
    regular = ~near_pi & ~small
    out[regular] = (v[regular] * (angle[regular] / (2.0 * sin[regular]))[..., None])
    out[small & ~near_pi] = v[small & ~near_pi] * 0.5
    if np.any(near_pi):
        Rp = R[near_pi]
        # axis from the largest diagonal of n n^T = (sym(R) - cos I) / (1 - cos), exact for every
        # angle (sym(R) = cos I + (1 - cos) n n^T); the antisymmetric part, O(pi - angle), stays out
        c = cos[near_pi][..., None, None]
        B = ((Rp + np.swapaxes(Rp, -1, -2)) / 2.0 - c * np.eye(3)) / (1.0 - c)
        i = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
        col = B[np.arange(len(i)), :, i]
        n = col / np.linalg.norm(col, axis=-1, keepdims=True)
        # fix sign with the antisymmetric part when it carries information
        s = np.sign(np.sum(n * v[near_pi], -1))
        s[s == 0] = 1.0
        out[near_pi] = n * (s * angle[near_pi])[..., None]
    return out


def fit_rigid(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Kabsch without scale: (R (3, 3), t (3,)) minimising sum_i w_i |R src_i + t - dst_i|^2.

    The centroids are the weighted means; the rotation of the centred points is scipy's
    Kabsch (``Rotation.align_vectors``), always a proper rotation (det +1). Points with zero
    weight are ignored. When the centred points do not fix the rotation (fewer than two
    independent directions, e.g. collinear points), scipy warns and returns one of the optimal
    rotations."""
    from scipy.spatial.transform import Rotation

    P = np.asarray(src, np.float64).reshape(-1, 3)
    Q = np.asarray(dst, np.float64).reshape(-1, 3)
    if P.shape != Q.shape or len(P) == 0:
        raise ValueError(f"fit_rigid needs two (N >= 1, 3) point sets of the same shape, got {P.shape} and {Q.shape}")
    w = np.ones(len(P)) if weights is None else np.asarray(weights, np.float64).reshape(-1)
    if w.shape != (len(P),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError("fit_rigid weights must be finite, non-negative, one per point, not all zero")
    w = w / w.sum()
    pc, qc = w @ P, w @ Q
    keep = w > 0
    if keep.sum() < 2:  # one point: any rotation fits; keep the identity
        return np.eye(3), qc - pc
    rot, _ = Rotation.align_vectors(Q[keep] - qc, P[keep] - pc, weights=w[keep])
    R = rot.as_matrix()
    return R, qc - R @ pc


def rotation_pivot(R: np.ndarray, t: np.ndarray, axis_point_coord: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """For a rigid motion x -> R x + t, the screw axis: (point on the axis, unit axis, slide).

    The point is the one whose coordinate ``axis_point_coord`` is 0 (e.g. 0 = the point on
    the midsagittal plane x = 0) when the axis is not parallel to that plane; ``slide`` is
    the translation along the axis (0 for a pure rotation)."""
    R = np.asarray(R, np.float64)
    t = np.asarray(t, np.float64)
    aa = matrix_to_axis_angle(R)
    ang = float(np.linalg.norm(aa))
    if ang < 1e-9:
        raise ValueError("rotation_pivot: the motion has no rotation")
    n = aa / ang
    slide = float(t @ n)
    c, *_ = np.linalg.lstsq(np.eye(3) - R, t - slide * n, rcond=None)
    if abs(n[axis_point_coord]) > 1e-6:
        c = c - (c[axis_point_coord] / n[axis_point_coord]) * n
    return c, n, slide


def rotate_between(a: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Apply the minimal rotation taking unit vectors ``a`` to ``b`` (both (..., 3)) to the
    points ``x`` (..., P, 3): Rodrigues with axis ``a x b`` in the form ``x + v x x +
    v x (v x x) / (1 + a.b)``, no trigonometry. Antiparallel ``a``, ``b`` (no unique minimal
    rotation) are not handled: ``1 + a.b`` is floored at 1e-6."""
    v = np.cross(a, b)
    c = np.einsum("...d,...d->...", a, b)
    k = 1.0 / np.maximum(1.0 + c, 1e-6)
    v = v[..., None, :]
    vx = np.cross(np.broadcast_to(v, x.shape), x)
    return x + vx + np.cross(np.broadcast_to(v, x.shape), vx) * k[..., None, None]
