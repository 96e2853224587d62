"""prior.fit.head (torch) against synth.model.head.HeadModel (numpy) on the embedded default model."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from prior.fit.head import TorchHeadModel  # noqa: E402
from prior.fit.rotations import axis_angle_to_matrix  # noqa: E402
from synth.errors import CodeError  # noqa: E402
from synth.geometry import axis_angle_to_matrix as np_axis_angle_to_matrix  # noqa: E402
from synth.model.head import HeadModel  # noqa: E402


@pytest.fixture(scope="module")
def data(default_model):
    return default_model


@pytest.fixture(scope="module")
def np64(data):
    return HeadModel(data, dtype=np.float64)


@pytest.fixture(scope="module")
def th64(data):
    return TorchHeadModel(data, torch.float64)


def _codes(data, rng, B, sd=1.0, rot_deg=20.0, trans_m=0.1):
    J = len(data.joint_names)
    return (rng.normal(0, sd, (B, data.identity_dims)), rng.normal(0, sd, (B, data.expression_dims)),
            np.deg2rad(rng.uniform(-rot_deg, rot_deg, (B, J, 3))), rng.uniform(-trans_m, trans_m, (B, 3)))


def _extreme(data, rng):
    """+-3 sd codes, large jaw and eye rotations (including ~180 degrees) and a near-zero rotation."""
    J = len(data.joint_names)
    ji = {n: i for i, n in enumerate(data.joint_names)}
    B = 6
    beta = 3.0 * np.sign(rng.normal(size=(B, data.identity_dims)))
    beta[1] = -beta[0]
    psi = 3.0 * np.sign(rng.normal(size=(B, data.expression_dims)))
    psi[2] = 0.0
    rot = np.zeros((B, J, 3))
    rot[0, ji["jaw"]] = [np.deg2rad(60.0), 0.0, 0.0]
    rot[1, ji["eye_l"]] = [0.0, 0.0, np.deg2rad(179.0)]
    rot[1, ji["eye_r"]] = [np.deg2rad(-90.0), np.deg2rad(45.0), 0.0]
    rot[2, ji["neck"]] = [1e-9, -2e-9, 3e-10]  # Taylor branch
    rot[3] = np.deg2rad(rng.uniform(-90, 90, (J, 3)))
    rot[4, ji["head"]] = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0) * (np.pi - 1e-6)
    rot[5] = np.deg2rad(rng.uniform(-170, 170, (J, 3)))
    trans = rng.uniform(-2.0, 2.0, (B, 3))
    return beta, psi, rot, trans


@pytest.mark.parametrize("case", ["random", "extreme"])
def test_vertices_landmarks_joints_float64(data, np64, th64, case):
    rng = np.random.default_rng(0 if case == "random" else 1)
    beta, psi, rot, trans = _codes(data, rng, 5) if case == "random" else _extreme(data, rng)
    ref = np64.evaluate(beta, psi, rot, trans)
    v = th64.vertices(beta, psi, rot, trans).numpy()
    np.testing.assert_allclose(v, ref.vertices, atol=1e-5, rtol=0)
    for s in data.landmarks:
        lm = th64.landmarks(beta, psi, rot, trans, landmark_set=s).numpy()
        np.testing.assert_allclose(lm, ref.landmarks[s], atol=1e-5, rtol=0)
    np.testing.assert_allclose(th64.joint_transforms(beta, rot, trans).numpy(), ref.joint_transforms,
                               atol=1e-5, rtol=0)
    # far tighter than the 1e-5 asked (same maths, same precision; the numpy model rounds
    # skinning weights within 1e-6 of 1 to exactly 1, which bounds the difference)
    assert np.abs(v - ref.vertices).max() < 1e-7


def test_unposed_and_broadcast(data, np64, th64):
    rng = np.random.default_rng(2)
    beta, psi, _, _ = _codes(data, rng, 3)
    np.testing.assert_allclose(th64.vertices(beta, psi).numpy(), np64.vertices(beta, psi), atol=1e-9)
    # one identity with three expressions, and single codes give B = 1
    np.testing.assert_allclose(th64.landmarks(beta[0], psi).numpy(), np64.landmarks(beta[0], psi), atol=1e-9)
    assert th64.landmarks(beta[0], psi[0]).shape == (1, 68, 3)


def test_float32_tolerance(data):
    rng = np.random.default_rng(3)
    beta, psi, rot, trans = _extreme(data, rng)
    ref = HeadModel(data, dtype=np.float64).evaluate(beta, psi, rot, trans)
    th32 = TorchHeadModel(data, torch.float32)
    v = th32.vertices(beta, psi, rot, trans).numpy()
    assert v.dtype == np.float32
    # float32: |codes| = 3 on 100 components, coordinates up to ~3 m: errors of a few 1e-6 m
    np.testing.assert_allclose(v, ref.vertices, atol=2e-5, rtol=0)
    np.testing.assert_allclose(th32.landmarks(beta, psi, rot, trans).numpy(), ref.landmarks["ibug68"],
                               atol=2e-5, rtol=0)


def test_landmark_subset_is_small_and_exact(data, th64):
    sub, corners, bary = th64.landmark_subset("ibug68")
    assert sub.index.numel() < 300  # the corners only, not the 6,393 vertices
    rng = np.random.default_rng(4)
    beta, psi, rot, trans = _codes(data, rng, 2)
    full = th64.vertices(beta, psi, rot, trans)
    tri, b = data.landmarks["ibug68"]
    expect = torch.einsum("blkc,lk->blc", full[:, torch.as_tensor(data.triangles[tri].astype(np.int64))],
                          torch.as_tensor(b, dtype=torch.float64))
    torch.testing.assert_close(th64.landmarks(beta, psi, rot, trans), expect, atol=1e-12, rtol=0)


def test_gradients_match_finite_differences(data, th64):
    rng = np.random.default_rng(5)
    beta, psi, rot, trans = (torch.tensor(a[:1], requires_grad=True) for a in _codes(data, rng, 1))
    with torch.no_grad():
        rot[0, 2] = 0.0  # the jaw at exactly zero: the Taylor branch must carry gradients too

    def f(b, p, r, t):
        return th64.landmarks(b, p, r, t).square().sum()

    assert torch.autograd.gradcheck(f, (beta, psi, rot, trans), eps=1e-6, atol=1e-5, fast_mode=True)


def test_rodrigues_matches_numpy():
    rng = np.random.default_rng(6)
    r = np.concatenate([rng.normal(0, 1.5, (50, 3)), rng.normal(0, 1e-7, (5, 3)), np.zeros((1, 3)),
                        [[np.pi, 0, 0], [0, -np.pi + 1e-7, 0]]])
    np.testing.assert_allclose(axis_angle_to_matrix(torch.tensor(r)).numpy(), np_axis_angle_to_matrix(r),
                               atol=1e-12)
    z = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    axis_angle_to_matrix(z).sum().backward()
    assert torch.isfinite(z.grad).all()


def test_bad_shapes(th64, data):
    with pytest.raises(CodeError, match="identity"):
        th64.landmarks(np.zeros(3), np.zeros(data.expression_dims))
    with pytest.raises(CodeError, match="batch sizes"):
        th64.landmarks(np.zeros((2, data.identity_dims)), np.zeros((3, data.expression_dims)))
    with pytest.raises(CodeError, match="landmark set"):
        th64.landmarks(np.zeros(data.identity_dims), np.zeros(data.expression_dims), landmark_set="nope")


def test_eyelid_parameters(data, th64):
    """What the landmark fit gives the solver's exact-curvature block (prior.fit.lm ``curved``):
    the eye joints and the codes that move the lid margins; nothing for a model without the rig."""
    import dataclasses

    codes, joints = th64.eyelid_parameters()
    names = [data.expression_names[i] for i in codes]
    assert {"eyeBlinkLeft", "eyeBlinkRight", "eyeLookUpLeft", "eyeLookDownRight"} <= set(names)
    assert not {"jawOpen", "mouthSmileLeft", "mouthPucker"} & set(names)
    assert joints == sorted(data.joint_names.index(j) for j in ("eye_l", "eye_r"))
    plain = dataclasses.replace(data, extra={k: v for k, v in data.extra.items() if k != "eyelids"})
    assert TorchHeadModel(plain).eyelid_parameters() == ([], [])
