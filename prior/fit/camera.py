"""Pinhole cameras for the fitting: projection (torch), a closed-form initial pose from 2D-3D
correspondences (numpy), and pose errors.

Cameras follow synth's OpenCV convention (synth/conventions.py): ``world_to_camera`` maps
world points to camera coordinates (x right, y down, z forward) and ``K`` maps those to
pixels with the top-left image corner at (0, 0) (pixel centres at +0.5).
"""

from __future__ import annotations

import numpy as np
import torch

from synth.conventions import invert_rigid
from synth.errors import SynthError


def project(points: torch.Tensor, R: torch.Tensor, t: torch.Tensor, K: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """World points (N, L, 3) seen by cameras R (N, 3, 3), t (N, 3), K (N, 3, 3):
    pixels (N, L, 2) and depth along +z (N, L)."""
    Xc = torch.einsum("nij,nlj->nli", R, points) + t.unsqueeze(1)
    z = Xc[..., 2]
    h = torch.cat([Xc[..., :2] / z.unsqueeze(-1), torch.ones_like(z).unsqueeze(-1)], -1)
    return torch.einsum("nij,nlj->nli", K[:, :2], h), z


def weak_perspective_pose(X: np.ndarray, x: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form camera pose (R, t) that maps 3D points X (L, 3) near pixels x (L, 2).

    Under weak perspective about the centroid c of X, the normalised image coordinates
    K^-1 [x, 1] are an affine function s R2 (X - c) + m of the points. The 2x3 matrix s R2
    and the offset m follow by linear least squares; R2's rows are the nearest orthonormal
    pair (SVD), the third row their cross product (a proper rotation), s the mean singular
    value, and the centroid lies at depth 1 / s on the ray through m. Needs >= 4 points
    not all in one plane; accurate to the depth spread of the points over their distance
    (a few per cent for a face at arm's length), which the full perspective fit then removes.
    """
    X = np.asarray(X, np.float64)
    x = np.asarray(x, np.float64)
    if X.shape[0] < 4:
        raise SynthError(f"only {X.shape[0]} landmarks to place a camera", "camera initialisation",
                         "at least 4 visible landmarks are needed per image")
    xn = np.linalg.solve(np.asarray(K, np.float64), np.c_[x, np.ones(len(x))].T).T[:, :2]
    c = X.mean(0)
    A = np.c_[X - c, np.ones(len(X))]
    coef, *_ = np.linalg.lstsq(A, xn, rcond=None)  # (4, 2)
    M, m = coef[:3].T, coef[3]  # (2, 3), (2,)
    U, S, Vt = np.linalg.svd(M, full_matrices=False)
    if S[1] <= 1e-12 * max(S[0], 1e-300):
        raise SynthError("landmarks are degenerate (collinear) for a camera estimate", "camera initialisation",
                         "check the landmarks of this image")
    R2 = U @ Vt
    R = np.vstack([R2, np.cross(R2[0], R2[1])])
    s = float(S.mean())
    t = np.array([m[0] / s, m[1] / s, 1.0 / s]) - R @ c
    return R, t


def camera_centres(world_to_camera: np.ndarray) -> np.ndarray:
    """(..., 3) camera positions in world coordinates."""
    return invert_rigid(world_to_camera)[..., :3, 3]


def relative_pose_errors(w2c_fit, w2c_true, head_fit=None, head_true=None) -> tuple[np.ndarray, np.ndarray]:
    """Camera errors measured in the head's frame: rotation (degrees) and position (metres) of
    camera_to_head = head^-1 @ camera_to_world, fitted vs true, per camera.

    Cameras and the head's rigid placement are not separately observable from images (moving
    the head and every camera by one rigid motion changes no pixel), so only the cameras
    relative to the head are compared. ``head_*`` are 4x4 head-to-world transforms (None =
    identity: the head at rest in the model frame, as in synth renders and in fits with free
    cameras)."""
    w2c_fit, w2c_true = np.asarray(w2c_fit, np.float64), np.asarray(w2c_true, np.float64)
    H_fit = np.eye(4) if head_fit is None else np.asarray(head_fit, np.float64)
    H_true = np.eye(4) if head_true is None else np.asarray(head_true, np.float64)
    rel_fit = invert_rigid(H_fit) @ invert_rigid(w2c_fit)
    rel_true = invert_rigid(H_true) @ invert_rigid(w2c_true)
    Rd = rel_fit[..., :3, :3] @ np.swapaxes(rel_true[..., :3, :3], -1, -2)
    cos = np.clip((np.trace(Rd, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    return np.degrees(np.arccos(cos)), np.linalg.norm(rel_fit[..., :3, 3] - rel_true[..., :3, 3], axis=-1)


def scale_free_position_errors(w2c_fit, w2c_true, points_fit, points_true) -> np.ndarray:
    """(N,) camera position errors (metres) with the head's size taken from the truth.

    Scaling the head and every camera distance by one factor changes no pixel either, so
    images fix the cameras only relative to the head's size, which only the model's shape
    prior pins down. Here the fitted camera centres are taken relative to the centroid of
    ``points_fit`` (e.g. the fitted 3D landmarks, head frame = world frame as with free
    cameras) and rescaled by the ratio of the RMS radii of ``points_true`` and
    ``points_fit``, then compared with the true centres relative to the true centroid."""
    pf, pt = np.asarray(points_fit, np.float64), np.asarray(points_true, np.float64)
    size = lambda p: np.sqrt(((p - p.mean(0)) ** 2).sum(1).mean())  # noqa: E731
    cf = (camera_centres(w2c_fit) - pf.mean(0)) * (size(pt) / size(pf))
    return np.linalg.norm(cf - (camera_centres(w2c_true) - pt.mean(0)), axis=-1)
