"""Identity codes from the model's Gaussian-mixture prior, and the per-identity look-at target.

Identity i's code is ``prior.sample(seeds.generator(seed, IDENTITY, i), 1, max_mahalanobis)``:
it depends on (run seed, i) only. The look-at target is linear in the code (landmarks of
the neutral, unposed head), so it is evaluated for all identities with one matrix product.
"""

from __future__ import annotations

import numpy as np

from synth import seeds
from synth.errors import SynthError
from synth.model.format import HeadModelData
from synth.model.identity_gmm import GaussianMixture

#: ibug68 indices (0-based) of the outer and inner corners of both eyes.
EYE_CORNERS = (36, 39, 42, 45)


def prior_of(model: HeadModelData) -> GaussianMixture:
    return GaussianMixture.from_model(model)


def truncation_radius(dims: int, cfg) -> float | None:
    """Mahalanobis truncation radius for an IdentityConfig: the absolute ``max_mahalanobis``
    if set, else sqrt(chi2.ppf(truncation_quantile, dims)) (None = no truncation). A fixed
    radius would mean different things per dimension: in 48 dimensions a typical draw lies
    at radius ~6.9, so a radius of 3 would put every code on one shell."""
    if cfg.max_mahalanobis is not None:
        return float(cfg.max_mahalanobis)
    if cfg.truncation_quantile >= 1.0:
        return None
    from scipy.special import gammaincinv  # chi2.ppf(q, k) = 2 gammaincinv(k / 2, q), without scipy.stats

    return float(np.sqrt(2.0 * gammaincinv(0.5 * dims, cfg.truncation_quantile)))


def sample_identities(seed: int, identity: np.ndarray, prior: GaussianMixture,
                      max_mahalanobis: float | None) -> np.ndarray:
    """(N, Ki) identity codes for the given identity indices."""
    out = np.empty((len(identity), prior.dim))
    for n, i in enumerate(np.asarray(identity, np.int64).tolist()):
        out[n] = prior.sample(seeds.generator(seed, seeds.Stream.IDENTITY, i), 1, max_mahalanobis)[0]
    return out


def landmark_basis(model: HeadModelData, landmark_set: str = "ibug68") -> tuple[np.ndarray, np.ndarray]:
    """Neutral landmarks as template (L, 3) + code @ basis (Ki, L, 3) (identity_scale applied)."""
    if landmark_set not in model.landmarks:
        raise SynthError(f"the model has no '{landmark_set}' landmarks", model.name,
                         "use camera.target = 'origin' or a model with ibug68 landmarks")
    tri, bary = model.landmarks[landmark_set]
    corners = model.triangles[tri]  # (L, 3)
    b = bary.astype(np.float64)
    t = np.einsum("lkc,lk->lc", model.template[corners].astype(np.float64), b)
    basis = model.identity_basis.astype(np.float64) * model.identity_scale.astype(np.float64)[:, None, None]
    B = np.einsum("ilkc,lk->ilc", basis[:, corners], b)
    return t, B


def look_at_targets(model: HeadModelData, codes: np.ndarray, mode: str, offset) -> np.ndarray:
    """(N, 3) look-at points: 'eyes' (midpoint of the four eye corners), 'landmarks'
    (centroid of all ibug68 landmarks) or 'origin'; plus ``offset``."""
    codes = np.atleast_2d(np.asarray(codes, np.float64))
    off = np.asarray(offset, np.float64)
    if mode == "origin":
        return np.zeros((codes.shape[0], 3)) + off
    t, B = landmark_basis(model)
    if mode == "eyes":
        if t.shape[0] <= max(EYE_CORNERS):
            raise SynthError(f"the model's ibug68 set has {t.shape[0]} landmarks, the eye corners need 46",
                             model.name, "use camera.target = 'landmarks' or 'origin'")
        sel = list(EYE_CORNERS)
    else:
        sel = list(range(t.shape[0]))
    t0 = t[sel].mean(axis=0)
    Bt = B[:, sel].mean(axis=1)  # (Ki, 3)
    return t0 + codes @ Bt + off
