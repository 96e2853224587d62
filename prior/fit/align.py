"""Aligning a fit's frame to a ground-truth frame for evaluation.

A fit lives in its own frame: the head model at rest, the cameras placed around it; its
scale follows the fitted head's size and the fitted focal length (images fix the cameras only
up to one similarity). Before novel views are compared with ground truth, the fit's frame is
mapped onto the ground truth's by the similarity transform (scale s, rotation R, translation t)
that best aligns the *input* views' fitted cameras with their true cameras, the standard
protocol for novel-view evaluation when the reconstruction's frame is arbitrary. Held-out
ground-truth cameras are then taken into the fit's frame with its inverse.

Each input camera contributes four points in each frame: its centre ``c`` and the points
``c + D x``, ``c + D y``, ``c + D z`` along its axes, with ``D`` the camera's distance to the
face centre in that frame (fit: the fitted ibug68 landmarks' centroid; truth: the frame JSON's
``landmarks_3d`` centroid). So even one view fixes the transform: its orientation gives R, its
distance to the face gives s. The points are aligned in the least-squares sense (Umeyama 1991,
closed form by SVD).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.errors import SynthError


@dataclass
class Similarity:
    scale: float
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)
    rms: float = 0.0  # residual of the alignment (metres, in the target frame)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Points (..., 3) of the source frame in the target frame."""
        return self.scale * np.asarray(x) @ self.rotation.T + self.translation

    def camera_to_source(self, c2w_target: np.ndarray) -> np.ndarray:
        """A camera_to_world (..., 4, 4) of the target frame expressed in the source frame (rigid:
        the rotation is R^T R_c, the centre R^T (c - t) / s)."""
        c2w = np.array(c2w_target, np.float64, copy=True)
        Rt = self.rotation.T
        c2w[..., :3, :3] = Rt @ c2w[..., :3, :3]
        c2w[..., :3, 3] = (c2w[..., :3, 3] - self.translation) @ Rt.T / self.scale
        return c2w

    def to_dict(self) -> dict:
        return {"scale": self.scale, "rotation": self.rotation.tolist(), "translation": self.translation.tolist(),
                "rms_m": self.rms}


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> Similarity:
    """The similarity minimising sum |dst_i - (s R src_i + t)|^2 (proper rotation)."""
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 3:
        raise SynthError(f"alignment needs two (N >= 3, 3) point sets, got {src.shape} and {dst.shape}",
                         "camera alignment", "pass at least one camera per frame")
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    cov = b.T @ a / len(src)
    U, S, Vt = np.linalg.svd(cov)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
    R = U @ D @ Vt
    var = (a * a).sum() / len(src)
    if with_scale and not var > 0:
        raise SynthError("alignment points are all equal", "camera alignment", "check the cameras")
    s = float((S * np.diag(D)).sum() / var) if with_scale else 1.0
    t = md - s * R @ ms
    res = dst - (s * src @ R.T + t)
    return Similarity(s, R, t, float(np.sqrt((res * res).sum(1).mean())))


def camera_points(c2w: np.ndarray, face_centre: np.ndarray) -> np.ndarray:
    """(4V, 3): each camera's centre and the points at its distance to the face along its x, y, z axes."""
    c2w = np.asarray(c2w, np.float64)
    c = c2w[:, :3, 3]
    D = np.linalg.norm(np.asarray(face_centre, np.float64) - c, axis=1)
    axes = [c + D[:, None] * c2w[:, :3, k] for k in range(3)]
    return np.concatenate([c, *axes])


def align_cameras(c2w_fit, face_fit, c2w_true, face_true) -> Similarity:
    """The similarity from the fit's frame to the truth's (see the module docstring)."""
    return umeyama(camera_points(c2w_fit, face_fit), camera_points(c2w_true, face_true))
