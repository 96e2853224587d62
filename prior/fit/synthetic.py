"""Synthetic fitting problems with known truth (tests and benchmarks/fit_landmarks.py).

Identity ``i`` of run ``seed`` gets the planner's identity code and expression 0's code and
jaw/eye rotations (synth.plan: the model's identity GMM, truncated as in a dataset, and the
expression sampler with the neutral kind switched off), and cameras like the planner's:
orbiting the eyes' midpoint, looking at it, at the given azimuths with a seeded jitter of
+-``jitter_deg`` in azimuth and elevation and a radius in [0.9, 1.3] m, with the default
lens (85 mm on a 36 mm sensor). Landmarks are the numpy HeadModel's, projected; a landmark
is visible when its triangle faces the camera (no occlusion test). Every random number comes
from synth.seeds keyed by (seed, identity): camera jitter from the CAMERA stream's view
blocks, landmark noise from ``seeds.generator(seed, FRAME, identity, 0, view)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from prior.fit.camera import relative_pose_errors, scale_free_position_errors
from prior.fit.landmarks_fit import FitResult, Observations
from synth import seeds
from synth.config import load_config
from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
from synth.model.format import HeadModelData
from synth.model.head import HeadModel
from synth.plan.expressions import resolve, sample_expressions
from synth.plan.identities import look_at_targets, prior_of, sample_identities, truncation_radius


@dataclass
class Scene:
    identity: np.ndarray  # (Ki,)
    expression: np.ndarray  # (Ke,)
    joint_rotations: np.ndarray  # (J, 3)
    K: np.ndarray  # (N, 3, 3)
    world_to_camera: np.ndarray  # (N, 4, 4)
    width: int
    height: int
    landmarks_2d: np.ndarray  # (N, L, 2), exact projections
    visible: np.ndarray  # (N, L) bool

    def observations(self, noise_px: float, seed: int, identity_index: int, known_intrinsics: bool = True,
                     landmark_set: str = "ibug68") -> Observations:
        """Landmarks with isotropic Gaussian noise of ``noise_px`` (also their sigma); hidden
        points unused."""
        noisy = self.landmarks_2d.copy()
        for v in range(len(noisy)):
            g = seeds.generator(seed, seeds.Stream.FRAME, identity_index, 0, v)
            noisy[v] += noise_px * g.standard_normal(noisy[v].shape)
        sigma = np.where(self.visible, max(noise_px, 1e-3), np.inf)
        return Observations(noisy, sigma, self.width, self.height, self.K if known_intrinsics else None,
                            landmark_set=landmark_set)


def make_scene(model: HeadModelData, seed: int, identity_index: int, azimuths_deg=(0.0, 45.0, -45.0),
               resolution: int = 512, jitter_deg: float = 5.0, landmark_set: str = "ibug68",
               head: HeadModel | None = None) -> Scene:
    # the eye target keeps these scenes (and docs/fitting.md's figures) as they were before the head framing
    cfg = load_config(overrides=["expression.neutral_weight=0", 'camera.target="eyes"']).resolved()
    head = head or HeadModel(model, np.float64)
    i = np.array([identity_index])
    beta = sample_identities(seed, i, prior_of(model), truncation_radius(model.identity_dims, cfg.identity))[0]
    ex = sample_expressions(seed, i, np.array([0]), resolve(list(model.expression_names), cfg.expression),
                            cfg.expression)
    rot = np.zeros((head.J, 3))
    for name, r in ex.joint_rotations().items():
        rot[head.joint_index[name]] = r[0]
    psi = ex.codes[0]
    target = look_at_targets(model, beta, cfg.camera.target, cfg.camera.target_offset_m)[0]
    n = len(azimuths_deg)
    u = seeds.uniforms(seed, seeds.Stream.CAMERA, np.full(n, identity_index), 0, np.arange(n), n=3)
    az = np.asarray(azimuths_deg, np.float64) + jitter_deg * (2.0 * u[:, 0] - 1.0)
    el = jitter_deg * (2.0 * u[:, 1] - 1.0)
    r0, r1 = cfg.camera.radius_m
    radius = r0 + u[:, 2] * (r1 - r0)
    c2w = orbit_camera_to_world(az, el, radius, target)
    w2c = invert_rigid(c2w)
    K = np.broadcast_to(intrinsics(resolution, resolution, cfg.fov_deg), (n, 3, 3)).copy()
    ev = head.evaluate(beta, psi, rot)
    X = ev.landmarks[landmark_set][0].astype(np.float64)
    uv, z = project(K, w2c, np.broadcast_to(X, (n,) + X.shape))
    tri, _ = model.landmarks[landmark_set]
    V = ev.vertices[0].astype(np.float64)[model.triangles[tri]]  # (L, 3, 3)
    normal = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    facing = np.einsum("lk,nlk->nl", normal, c2w[:, None, :3, 3] - X[None]) > 0
    inside = np.all((uv >= 0) & (uv <= resolution), -1) & (z > 0)
    return Scene(beta, psi, rot, K, w2c, resolution, resolution, uv, facing & inside)


def scene_errors(scene: Scene, fit: FitResult, head: HeadModel, landmark_set: str = "ibug68") -> dict[str, np.ndarray]:
    """Per-camera errors of a fit against the scene's truth, all relative to the head:
    rotation (deg), position (m), scale-free position (m, :func:`scale_free_position_errors`
    on the 3D landmarks), and per-image reprojection RMSE (px) against the true (noise-free)
    projections of the visible landmarks."""
    rot, pos = relative_pose_errors(fit.world_to_camera, scene.world_to_camera, fit.head_to_world)
    X_fit = head.landmarks(fit.identity, fit.expression[0], fit.joint_rotations[0], landmark_set=landmark_set)[0]
    X_true = head.landmarks(scene.identity, scene.expression, scene.joint_rotations, landmark_set=landmark_set)[0]
    d2 = ((fit.landmarks_2d - scene.landmarks_2d) ** 2).sum(-1)
    clean = np.sqrt((d2 * scene.visible).sum(1) / np.maximum(scene.visible.sum(1), 1))
    return {"rotation_deg": rot, "position_m": pos,
            "position_scale_free_m": scale_free_position_errors(fit.world_to_camera, scene.world_to_camera,
                                                                 X_fit, X_true),
            "rmse_observed_px": fit.rmse_px, "rmse_true_px": clean}
