"""prior.fit.landmarks_fit: head model and camera fitting on synthetic frames with known truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from prior.fit.camera import camera_centres, relative_pose_errors, weak_perspective_pose  # noqa: E402
from prior.fit.head import TorchHeadModel  # noqa: E402
from prior.fit.identity_prior import TorchGMM  # noqa: E402
from prior.fit.landmarks_fit import FitOptions, Observations, fit_landmarks  # noqa: E402
from prior.fit.synthetic import make_scene, scene_errors  # noqa: E402
from synth.conventions import invert_rigid, look_at, project  # noqa: E402
from synth.errors import SynthError  # noqa: E402
from synth.geometry import axis_angle_to_matrix  # noqa: E402
from synth.model.head import HeadModel  # noqa: E402

SEED = 7


@pytest.fixture(scope="module")
def model(default_model):
    return default_model


@pytest.fixture(scope="module")
def kit(model):
    torch.set_num_threads(1)
    return HeadModel(model, np.float64), TorchHeadModel(model), TorchGMM.from_model(model)


def _fit(model, kit, obs, **kw):
    _, th, gmm = kit
    return fit_landmarks(model, obs, FitOptions(**kw), head=th, gmm=gmm)


# --------------------------------------------------------------------------- initialisation


def test_weak_perspective_pose():
    rng = np.random.default_rng(0)
    X = rng.normal(0, 0.08, (40, 3))
    K = np.array([[1000.0, 0, 256], [0, 1000.0, 256], [0, 0, 1]])
    # exact in the orthographic limit; at 1 m off by about the points' depth spread over the distance
    for dist, tol, tol_pos in ((1000.0, 0.02, 1e-3), (1.0, 5.0, 0.1)):
        w2c = invert_rigid(look_at([0.3 * dist, -dist, 0.2 * dist], [0, 0, 0]))
        x, _ = project(K, w2c, X)
        R, t = weak_perspective_pose(X, x, K)
        assert np.linalg.det(R) == pytest.approx(1.0)
        ang = np.degrees(np.arccos(np.clip((np.trace(R @ w2c[:3, :3].T) - 1) / 2, -1, 1)))
        assert ang < tol
        assert np.linalg.norm(-R.T @ t - camera_centres(w2c)) < tol_pos * dist


# --------------------------------------------------------------------------- exact recovery


@pytest.mark.parametrize("landmark_set", ["ibug68", "dense"])
def test_noise_free_recovers_truth(model, kit, landmark_set):
    hm = kit[0]
    sc = make_scene(model, SEED, 3, landmark_set=landmark_set, head=hm)
    fit = _fit(model, kit, sc.observations(0.0, SEED, 3, landmark_set=landmark_set))
    e = scene_errors(sc, fit, hm, landmark_set)
    assert fit.converged
    assert e["rotation_deg"].max() < 0.01
    assert e["position_m"].max() < 5e-4
    assert e["rmse_true_px"].max() < 0.01
    d = json.loads(json.dumps(fit.to_json()))  # plain JSON for the fit's report
    assert d["converged"] and np.allclose(d["world_to_camera"], fit.world_to_camera)


def test_known_extrinsics_fit_the_head_placement(model, kit):
    """Cameras given, the head moved rigidly: the fit finds the head's placement instead."""
    hm = kit[0]
    sc = make_scene(model, SEED, 4, head=hm)
    T = np.eye(4)
    T[:3, :3] = axis_angle_to_matrix(np.array([0.1, -0.25, 0.05]))
    T[:3, 3] = [0.03, -0.05, 0.02]
    uv, _ = project(sc.K, sc.world_to_camera @ T, hm.landmarks(sc.identity, sc.expression, sc.joint_rotations)[0])
    obs = Observations(uv, np.where(sc.visible, 1e-3, np.inf), sc.width, sc.height, sc.K,
                       world_to_camera=sc.world_to_camera)
    fit = _fit(model, kit, obs)
    assert fit.converged
    np.testing.assert_allclose(fit.head_to_world, T, atol=2e-4)
    np.testing.assert_allclose(fit.world_to_camera, sc.world_to_camera)  # held
    rot, pos = relative_pose_errors(fit.world_to_camera, sc.world_to_camera @ T, fit.head_to_world)
    assert rot.max() < 0.02 and pos.max() < 5e-4


def test_per_image_expression_noise_free(model, kit):
    hm = kit[0]
    sc = make_scene(model, SEED, 5, head=hm)
    fit = _fit(model, kit, sc.observations(0.0, SEED, 5), per_image_expression=True)
    e = scene_errors(sc, fit, hm)
    assert fit.converged and e["rotation_deg"].max() < 0.05 and e["rmse_true_px"].max() < 0.05
    assert fit.expression.shape == (3, model.expression_dims)
    assert np.all(fit.expression >= 0.0) and np.all(fit.expression <= 1.0)  # the box holds per image


# --------------------------------------------------------------------------- 10 identities, 1 px


def _ten(model, kit, landmark_set, resolution, **kw):
    hm = kit[0]
    out = []
    for i in range(10):
        sc = make_scene(model, SEED, i, resolution=resolution, landmark_set=landmark_set, head=hm)
        fit = _fit(model, kit, sc.observations(1.0, SEED, i, landmark_set=landmark_set), **kw)
        out.append((fit, scene_errors(sc, fit, hm, landmark_set)))
    return out


@pytest.mark.slow
def test_ten_identities_dense_landmarks(model, kit):
    """The acceptance test: 3 views, 1 px noise per axis, 600 dense landmarks (the paper fits
    599), 1024 px, default initialisation, for each of 10 identities: rotation <= 2 deg,
    position <= 1 cm relative to the head at the head's true size, reprojection RMSE <= 1.5 px,
    converged. The metric position (head size from the shape prior alone) is bounded at 4 cm."""
    for i, (fit, e) in enumerate(_ten(model, kit, "dense", 1024)):
        assert fit.converged, i
        assert e["rotation_deg"].max() <= 2.0, (i, e["rotation_deg"])
        assert e["position_scale_free_m"].max() <= 0.01, (i, e["position_scale_free_m"])
        assert e["position_m"].max() <= 0.04, (i, e["position_m"])
        assert fit.rmse_px.max() <= 1.5, (i, fit.rmse_px)


@pytest.mark.slow
def test_ten_identities_ibug68(model, kit):
    """The same with the 68 ibug landmarks: rotation, RMSE and convergence meet the targets;
    the positions do not reach 1 cm (68 points at 1 px: even the true codes leave ~1 cm,
    docs/fitting.md), so they are only bounded here at the measured level."""
    for i, (fit, e) in enumerate(_ten(model, kit, "ibug68", 1024)):
        assert fit.converged, i
        assert e["rotation_deg"].max() <= 2.0, (i, e["rotation_deg"])
        assert fit.rmse_px.max() <= 1.5, (i, fit.rmse_px)
        assert e["position_scale_free_m"].max() <= 0.03, (i, e["position_scale_free_m"])


def test_unknown_focal_length(model, kit):
    hm = kit[0]
    sc = make_scene(model, SEED, 2, resolution=1024, landmark_set="dense", head=hm)
    fit = _fit(model, kit, sc.observations(1.0, SEED, 2, known_intrinsics=False, landmark_set="dense"))
    e = scene_errors(sc, fit, hm, "dense")
    assert fit.converged
    assert fit.K[0, 0, 0] == pytest.approx(sc.K[0, 0, 0], rel=0.05)
    np.testing.assert_allclose(fit.K[:, :2, 2], sc.K[:, :2, 2])  # the principal point stays
    assert e["rotation_deg"].max() <= 2.0


# --------------------------------------------------------------------------- bad input


def test_too_few_landmarks(model, kit):
    sc = make_scene(model, SEED, 0, head=kit[0])
    obs = sc.observations(1.0, SEED, 0)
    obs.sigma[1, np.nonzero(np.isfinite(obs.sigma[1]))[0][5:]] = np.inf
    with pytest.raises(SynthError, match="image 1 has 5 usable landmarks"):
        _fit(model, kit, obs)


def test_unknown_joint_and_bad_shapes(model, kit):
    sc = make_scene(model, SEED, 0, head=kit[0])
    with pytest.raises(SynthError, match="unknown joint 'elbow'"):
        _fit(model, kit, sc.observations(1.0, SEED, 0), joints=("jaw", "elbow"))
    with pytest.raises(SynthError, match="landmarks must be"):
        Observations(np.zeros((3, 68)), np.ones((3, 68)), 512, 512)
