"""Model format, evaluation (shape blending, joints, skinning, landmarks), rotations and prior,
on a small random model so the tests are fast and independent of any data source."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal

from synth.errors import CodeError, ModelFormatError
from synth.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from synth.model.format import model_bytes, read_model, validate_model, write_model
from synth.model.head import HeadModel
from synth.model.identity_gmm import GaussianMixture, fit_gmm
from tests.support.toy_model import random_model


@pytest.fixture(scope="module")
def model():
    return random_model()


@pytest.fixture(scope="module")
def hm(model):
    return HeadModel(model)


# ----------------------------------------------------------------------------- format

def test_round_trip(tmp_path, model):
    p = write_model(model, tmp_path / "m.npz")
    m2 = read_model(p)
    assert model_bytes(m2) == model_bytes(model)
    for k in ("template", "identity_basis", "skin_weights", "prior_covs"):
        np.testing.assert_array_equal(getattr(m2, k), getattr(model, k))
    assert m2.expression_names == model.expression_names
    np.testing.assert_array_equal(m2.landmarks["ibug68"][1], model.landmarks["ibug68"][1])


def test_compressed_round_trip(tmp_path, model):
    p = write_model(model, tmp_path / "c.npz", compress=True)
    assert model_bytes(read_model(p)) == model_bytes(model)


@pytest.mark.parametrize("mutate, msg", [
    (lambda m: setattr(m, "template", m.template[:, :2]), "template"),
    (lambda m: m.template.__setitem__((0, 0), np.nan), "NaN"),
    (lambda m: setattr(m, "joint_names", ["a", "head", "jaw", "eye_l", "eye_r"]), "neck"),
    (lambda m: setattr(m, "joint_parents", np.array([-1, 2, 0, 1, 1], np.int32)), "parent"),
    (lambda m: setattr(m, "skin_weights", m.skin_weights * 2), "skin_weights"),
    (lambda m: setattr(m, "prior_covs", -m.prior_covs), "positive definite"),
    (lambda m: m.triangles.__setitem__((0, 0), 10 ** 6), "triangle index"),
    (lambda m: setattr(m, "landmarks", {}), "ibug68"),
])
def test_validate_rejects(mutate, msg):
    m = random_model()
    mutate(m)
    with pytest.raises(ModelFormatError, match=msg):
        validate_model(m)


def test_read_rejects_garbage_and_pickles(tmp_path, model):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ModelFormatError, match="not a readable"):
        read_model(bad)
    # an object array inside the archive must not be unpickled
    p = write_model(model, tmp_path / "m.npz")
    with zipfile.ZipFile(p, "a") as z:
        import io
        buf = io.BytesIO()
        np.save(buf, np.array([{"evil": 1}], dtype=object), allow_pickle=True)
        z.writestr("evil.npy", buf.getvalue())
    with pytest.raises(ModelFormatError):
        read_model(p)
    with pytest.raises(ModelFormatError, match="not found"):
        read_model(tmp_path / "missing.npz")


def test_write_is_atomic_on_invalid(tmp_path):
    m = random_model()
    m.template[0, 0] = np.inf
    with pytest.raises(ModelFormatError):
        write_model(m, tmp_path / "x.npz")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- evaluation

def test_zero_codes_give_template(hm, model):
    v = hm.vertices(np.zeros(model.identity_dims), np.zeros(model.expression_dims))
    assert v.shape == (1, model.num_vertices, 3) and v.dtype == np.float32
    np.testing.assert_array_equal(v[0], model.template)


def test_linearity(hm, model):
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(2, model.identity_dims))
    ea, eb = rng.uniform(size=(2, model.expression_dims))
    T = model.template
    va = hm.vertices(a, ea)[0] - T
    vb = hm.vertices(b, eb)[0] - T
    vab = hm.vertices(a + b, ea + eb)[0] - T
    np.testing.assert_allclose(vab, va + vb, atol=2e-6)
    np.testing.assert_allclose(hm.vertices(2 * a, 0 * ea)[0] - T, 2 * (hm.vertices(a, 0 * ea)[0] - T), atol=2e-6)


def test_batch_equals_single(hm, model):
    rng = np.random.default_rng(2)
    B = 7
    beta = rng.normal(size=(B, model.identity_dims))
    psi = rng.uniform(size=(B, model.expression_dims))
    rot = rng.normal(size=(B, 5, 3)) * 0.3
    tr = rng.normal(size=(B, 3))
    ev = hm.evaluate(beta, psi, rot, tr)
    for i in range(B):
        e1 = hm.evaluate(beta[i], psi[i], rot[i], tr[i])
        np.testing.assert_allclose(ev.vertices[i], e1.vertices[0], atol=1e-6)
        np.testing.assert_allclose(ev.joint_transforms[i], e1.joint_transforms[0], atol=1e-6)
        np.testing.assert_allclose(ev.landmarks["ibug68"][i], e1.landmarks["ibug68"][0], atol=1e-6)


def _slow_lbs(model, beta, psi, rot, trans):
    """Obviously-correct reference: float64, per joint 4x4 chain, per vertex blend."""
    d = model
    s = d.identity_scale.astype(np.float64)
    v = d.template.astype(np.float64).copy()
    for k in range(d.identity_dims):
        v += beta[k] * s[k] * d.identity_basis[k]
    for k in range(d.expression_dims):
        v += psi[k] * d.expression_scale[k] * d.expression_basis[k]
    J = d.joint_rest.astype(np.float64).copy()
    for k in range(d.identity_dims):
        J += beta[k] * s[k] * d.joint_identity_basis[k]
    G = []
    for j, p in enumerate(d.joint_parents):
        L = np.eye(4)
        L[:3, :3] = axis_angle_to_matrix(np.asarray(rot[j], np.float64))
        L[:3, 3] = J[j] - (J[p] if p >= 0 else 0)
        G.append(L if p < 0 else G[p] @ L)
    out = np.zeros_like(v)
    for i in range(len(v)):
        acc = np.zeros(3)
        for j in range(len(G)):
            if d.skin_weights[i, j] == 0:
                continue
            A = G[j].copy()
            A[:3, 3] -= G[j][:3, :3] @ J[j]
            acc += d.skin_weights[i, j] * (A[:3, :3] @ v[i] + A[:3, 3])
        out[i] = acc + trans
    return out, np.stack(G)


def test_skinning_matches_slow_reference(hm, model):
    rng = np.random.default_rng(3)
    beta = rng.normal(size=model.identity_dims)
    psi = rng.uniform(size=model.expression_dims)
    rot = rng.normal(size=(5, 3)) * 0.5
    tr = np.array([0.1, -0.2, 0.3])
    ref, Gref = _slow_lbs(model, beta, psi, rot, tr)
    ev = hm.evaluate(beta, psi, rot, tr)
    np.testing.assert_allclose(ev.vertices[0], ref, atol=5e-6)
    G = ev.joint_transforms[0].astype(np.float64)
    np.testing.assert_allclose(G[:, :3, :3], Gref[:, :3, :3], atol=1e-6)
    np.testing.assert_allclose(G[:, :3, 3], Gref[:, :3, 3] + tr, atol=5e-6)


def test_landmarks_are_on_the_posed_surface(hm, model):
    rng = np.random.default_rng(4)
    ev = hm.evaluate(rng.normal(size=model.identity_dims), rng.uniform(size=model.expression_dims),
                     rng.normal(size=(5, 3)) * 0.2)
    tri, bary = model.landmarks["ibug68"]
    corners = ev.vertices[0][model.triangles[tri]]
    np.testing.assert_allclose(ev.landmarks["ibug68"][0], np.einsum("lkc,lk->lc", corners, bary), atol=1e-6)


@pytest.mark.parametrize("kw, name", [
    (dict(identity=np.zeros(3)), "identity"),
    (dict(expression=np.zeros(99)), "expression"),
    (dict(identity=np.full(6, np.nan)), "identity"),
    (dict(expression=np.array([np.inf, 0, 0, 0, 0])), "expression"),
    (dict(joint_rotations=np.zeros((4, 3))), "joint_rotations"),
    (dict(joint_rotations=np.full((5, 3), np.nan)), "joint_rotations"),
    (dict(translation=np.zeros(2)), "translation"),
])
def test_bad_codes_name_the_argument(hm, model, kw, name):
    args = dict(identity=np.zeros(model.identity_dims), expression=np.zeros(model.expression_dims))
    args.update(kw)
    with pytest.raises(CodeError, match=name):
        hm.vertices(**args)


def test_extreme_codes_stay_finite(hm, model):
    for s in (-5.0, 5.0):
        v = hm.vertices(np.full(model.identity_dims, s), np.full(model.expression_dims, s))
        assert np.all(np.isfinite(v))


def test_180_degree_rotations_rigid(hm, model):
    for axis in np.eye(3):
        rot = np.zeros((5, 3))
        rot[3] = np.pi * axis  # eye_l, 180 degrees
        rot[0] = np.pi * axis  # and the root
        ev = hm.evaluate(np.zeros(model.identity_dims), np.zeros(model.expression_dims), rot)
        v = ev.vertices[0]
        assert np.all(np.isfinite(v))
        rigid = np.arange(20)  # fully weighted to eye_l: pairwise distances preserved
        d0 = np.linalg.norm(model.template[rigid, None] - model.template[None, rigid], axis=-1)
        d1 = np.linalg.norm(v[rigid, None] - v[None, rigid], axis=-1)
        np.testing.assert_allclose(d1, d0, atol=1e-6)
        R = ev.joint_transforms[0, :, :3, :3]
        np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-6)


def test_float32_vs_float64(model):
    rng = np.random.default_rng(5)
    beta = rng.normal(size=(16, model.identity_dims)) * 3
    psi = rng.uniform(size=(16, model.expression_dims))
    rot = rng.normal(size=(16, 5, 3)) * 0.4
    v32 = HeadModel(model, np.float32).vertices(beta, psi, rot)
    v64 = HeadModel(model, np.float64).vertices(beta, psi, rot)
    assert np.abs(v32 - v64).max() < 1e-5  # metres: 10 micrometres


# ----------------------------------------------------------------------------- rotations

def test_rotations_stable():
    rng = np.random.default_rng(6)
    r = np.concatenate([rng.normal(size=(200, 3)), rng.normal(size=(50, 3)) * 1e-9, np.zeros((1, 3)),
                        np.pi * np.eye(3), np.pi * rng.normal(size=(20, 3)) /
                        np.linalg.norm(rng.normal(size=(20, 3)), axis=1, keepdims=True)])
    R = axis_angle_to_matrix(r)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    R2 = axis_angle_to_matrix(matrix_to_axis_angle(R))
    np.testing.assert_allclose(R2, R, atol=1e-7)


# ----------------------------------------------------------------------------- prior

def test_gmm_matches_scipy():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(4, 4))
    cov = A @ A.T + np.eye(4)
    g = GaussianMixture([1.0], rng.normal(size=(1, 4)), cov[None])
    x = rng.normal(size=(10, 4))
    np.testing.assert_allclose(g.log_likelihood(x), multivariate_normal(g.means[0], cov).logpdf(x), rtol=1e-10)


def test_gmm_parameters_give_the_same_density_by_plain_matrix_products(model):
    """The documented recipe for other frameworks (torch): whitened offsets by matrix products
    with the precision Cholesky factors, then log-sum-exp; equals log_likelihood and scipy."""
    rng = np.random.default_rng(12)
    D = 6
    A = rng.normal(size=(3, D, D))
    g = GaussianMixture([0.2, 0.5, 0.3], rng.normal(size=(3, D)), A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(D))
    for gmm in (g, GaussianMixture.from_model(model)):
        p = gmm.parameters()
        U = p["precision_cholesky"]
        assert np.allclose(np.tril(U, -1), 0.0)  # upper triangular
        for m in range(len(p["weights"])):
            np.testing.assert_allclose(U[m] @ U[m].T @ p["covs"][m], np.eye(gmm.dim), atol=1e-9)
        x = np.concatenate([rng.normal(size=(20, gmm.dim)), 50.0 * rng.normal(size=(5, gmm.dim))])
        z = np.einsum("nmd,mde->nme", x[:, None, :] - p["means"][None], U)
        logp = logsumexp(p["log_norm"][None] - 0.5 * np.sum(z * z, axis=2), axis=1)
        np.testing.assert_allclose(logp, gmm.log_likelihood(x), rtol=1e-10)
        np.testing.assert_allclose(gmm.nll(x), -logp, rtol=1e-10)
        np.testing.assert_allclose(np.einsum("mij,mkj->mik", gmm.cholesky, gmm.cholesky), p["covs"], atol=1e-12)
    x = rng.normal(size=(20, D))
    want = np.log(sum(w * multivariate_normal(mu, c).pdf(x) for w, mu, c in zip(g.weights, g.means, g.covs)))
    np.testing.assert_allclose(g.log_likelihood(x), want, rtol=1e-9)


def test_gmm_finite_and_monotone_far_away(model):
    g = GaussianMixture.from_model(model)
    d = np.ones(model.identity_dims) / np.sqrt(model.identity_dims)
    t = np.geomspace(1, 1e6, 40)
    ll = g.log_likelihood(t[:, None] * d[None])
    assert np.all(np.isfinite(ll))
    assert np.all(np.diff(ll) < 0)


def test_gmm_sampling_moments_and_truncation():
    rng = np.random.default_rng(8)
    D = 5
    g = GaussianMixture([0.4, 0.6], rng.normal(size=(2, D)), np.stack([np.eye(D) * 0.5, np.diag(np.arange(1, D + 1.0))]))
    x = g.sample(np.random.default_rng(9), 40000)
    np.testing.assert_allclose(x.mean(0), g.mean(), atol=0.05)
    np.testing.assert_allclose(np.cov(x.T), g.covariance(), atol=0.12)
    xt = g.sample(np.random.default_rng(10), 2000, max_mahalanobis=1.5)
    assert np.all(g.mahalanobis_sq(xt).min(1) <= 1.5 ** 2 + 1e-9)


def test_fit_gmm_recovers_and_is_positive_definite():
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.normal(size=(1500, 3)) + 4, rng.normal(size=(1500, 3)) - 4])
    g = fit_gmm(x, 2, np.random.default_rng(0))
    assert sorted(np.round(g.means[:, 0]).tolist()) == [-4.0, 4.0]
    for c in g.covs:
        assert np.all(np.linalg.eigvalsh(c) > 0)
