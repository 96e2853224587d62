"""Identity codes from the model's Gaussian-mixture prior, and the per-identity look-at target.

Identity i's code is ``prior.sample(seeds.generator(seed, IDENTITY, i), 1, max_mahalanobis)``:
it depends on (run seed, i) only. Under the head-shape rule (``identity.head_shape``, default
'auto'), a code whose neutral head leaves the adult ranges of :mod:`synth.plan.head_shapes` is redrawn:
attempt k = 1, 2, ... draws ``prior.sample(seeds.generator(seed, IDENTITY_REDRAW, i, k), ...)``
and the first one inside is kept (:func:`planned_codes`). The look-at target is linear in the
code (landmarks of the neutral, unposed head), so it is evaluated for all identities with one
matrix product.
"""

from __future__ import annotations

import numpy as np

from synth import seeds
from synth.errors import SynthError
from synth.geometry import exact
from synth.model.format import HeadModelData
from synth.model.head import landmark_basis
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


def planned_codes(seed: int, identity: np.ndarray, model: HeadModelData, cfg) -> np.ndarray:
    """(N, Ki) the plan's identity codes for an IdentityConfig ``cfg``: :func:`sample_identities`
    truncated at :func:`truncation_radius`, then :func:`redraw_outside_ranges` with ``cfg``'s
    ranges, as ``cfg.head_shape`` says: 'anthropometric' always (a model whose mean head lies
    outside a range, or that cannot be measured, is refused in one line: no redraw could meet
    it), 'auto' (the default) where the model's mean head lies inside every range (else every
    draw is kept: e.g. a test ellipsoid), 'none' never."""
    prior = prior_of(model)
    radius = truncation_radius(model.identity_dims, cfg)
    codes = sample_identities(seed, identity, prior, radius)
    if cfg.head_shape == "none":
        return codes
    from synth.plan import head_shapes as hs

    bounds = hs.bounds_of(cfg)
    mean = exact.lincomb(prior.weights, prior.means)  # the mixture's mean, in a fixed order
    why = hs.unmet(model, mean, bounds)
    if why is not None:
        if cfg.head_shape == "auto":
            return codes
        raise SynthError(f"identity.head_shape = 'anthropometric' cannot be met: {why}", model.name,
                         "widen the identity ranges (docs/realism.md 'Head shapes' lists the default model's "
                         "figures) or set identity.head_shape = 'auto' or 'none'")
    return redraw_outside_ranges(seed, identity, codes, prior, radius, model, bounds, cfg.head_shape_attempts)


def redraw_outside_ranges(seed: int, identity: np.ndarray, codes: np.ndarray, prior: GaussianMixture,
                          max_mahalanobis: float | None, model: HeadModelData,
                          bounds: dict[str, tuple[float, float]], attempts: int) -> np.ndarray:
    """``codes`` with each one whose head leaves ``bounds`` (:func:`head_shapes.inside`) replaced by
    the first of its redraws 1 .. ``attempts`` that is inside (redraw k of identity i from
    ``seeds.generator(seed, IDENTITY_REDRAW, i, k)``: a pure function of (seed, i), so a plan
    slice equals the matching part of a larger plan). If none is inside, the draw with the
    smallest :func:`head_shapes.excess` is kept (the earliest on a tie); with the default ranges
    about 30 % of first draws are outside, so that takes 33 misses in a row (about 1e-17)."""
    from synth.plan import head_shapes as hs

    sets = hs.measure_sets(model)
    ids = np.asarray(identity, np.int64)
    best = np.array(codes, np.float64, copy=True)
    m = hs.measure_codes(model, best, sets)
    best_x = hs.excess(m, bounds)
    todo = np.nonzero(~hs.inside(m, bounds))[0]
    for attempt in range(1, int(attempts) + 1):
        if not todo.size:
            break
        cand = np.stack([prior.sample(seeds.generator(seed, seeds.Stream.IDENTITY_REDRAW, int(ids[j]), attempt), 1,
                                      max_mahalanobis)[0] for j in todo])
        m = hs.measure_codes(model, cand, sets)
        x = hs.excess(m, bounds)
        better = x < best_x[todo]  # strictly smaller: the earlier draw wins a tie (inside: excess 0)
        best[todo[better]] = cand[better]
        best_x[todo[better]] = x[better]
        todo = todo[~hs.inside(m, bounds)]
    return best


def look_at_targets(model: HeadModelData, codes: np.ndarray, mode: str, offset) -> np.ndarray:
    """(N, 3) look-at points: 'head' (centre of the head's bounding box, :func:`head_spheres`),
    'eyes' (midpoint of the four eye corners), 'landmarks' (centroid of all ibug68 landmarks)
    or 'origin'; plus ``offset``."""
    codes = np.atleast_2d(np.asarray(codes, np.float64))
    off = np.asarray(offset, np.float64)
    if mode == "origin":
        return np.zeros((codes.shape[0], 3)) + off
    if mode == "head":
        return head_spheres(model, codes, 0.0)[0] + off
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
    return t0 + exact.lincomb(codes, Bt) + off


#: Regions of the head (the bust's neck and shoulders excluded) whose extent bounds the head.
_NOT_HEAD = ("neck", "shoulders")


#: Version of the extreme-vertex search, part of its cache file's name (change it with the search).
_EXTREMES_VERSION = 1
_extremes_memo: dict[str, np.ndarray] = {}


def extreme_vertices(model: HeadModelData, model_sha256: str | None = None) -> np.ndarray:
    """:func:`_extreme_vertices` of ``model``, computed once per model: with the sha256 of the
    model's file it is kept in memory and in the user cache (``SYNTH_CACHE_DIR``;
    ``plan-extremes/<sha256>-v1.npy``, written atomically, recomputed when unreadable), since
    the hull search (~97 convex hulls, half a second) is the same for every plan of a model."""
    if model_sha256 is None:
        return _extreme_vertices(model)
    if model_sha256 in _extremes_memo:
        return _extremes_memo[model_sha256]
    from synth.io import atomic_write_bytes, cache_dir

    path = cache_dir() / "plan-extremes" / f"{model_sha256}-v{_EXTREMES_VERSION}.npy"
    v = None
    try:
        got = np.load(path, allow_pickle=False)
        if got.dtype == np.int64 and got.ndim == 1 and got.size and 0 <= got.min() and \
                got.max() < model.template.shape[0]:
            v = got
    except (OSError, ValueError):
        pass
    if v is None:
        import io

        v = _extreme_vertices(model)
        buf = io.BytesIO()
        np.save(buf, v, allow_pickle=False)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(path, buf.getvalue(), durable=False)
        except OSError:  # a cache that cannot be written costs time, never the plan
            pass
    _extremes_memo[model_sha256] = v
    return v


def _extreme_vertices(model: HeadModelData) -> np.ndarray:
    """Indices of head vertices on the convex hull of the template or of the template moved by
    +-3 SD along any one identity direction: the candidates for a head's extreme points."""
    from scipy.spatial import ConvexHull

    skin = model.regions.get("skin")
    idx = np.arange(model.template.shape[0]) if skin is None else np.asarray(skin, np.int64)
    drop = np.concatenate([np.asarray(model.regions[r], np.int64) for r in _NOT_HEAD if r in model.regions] or
                          [np.zeros(0, np.int64)])
    idx = np.setdiff1d(idx, drop)
    t = model.template[idx].astype(np.float64)
    B = model.identity_basis[:, idx].astype(np.float64) * model.identity_scale.astype(np.float64)[:, None, None]
    keep = set(ConvexHull(t).vertices.tolist())
    for k in range(B.shape[0]):
        for s in (-3.0, 3.0):
            keep.update(ConvexHull(t + s * B[k]).vertices.tolist())
    return idx[np.array(sorted(keep), np.int64)]


def head_spheres(model: HeadModelData, codes: np.ndarray, margin_m: float,
                 extremes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per identity, the neutral head's bounding sphere: centres (N, 3) = the centre of the
    axis-aligned box of its extreme vertices (``extremes``, default: searched now), radii (N,) =
    their largest distance from it plus ``margin_m`` (room for hair volume, expressions and the
    jaw)."""
    codes = np.atleast_2d(np.asarray(codes, np.float64))
    v = _extreme_vertices(model) if extremes is None else extremes
    t = model.template[v].astype(np.float64)
    B = model.identity_basis[:, v].astype(np.float64) * model.identity_scale.astype(np.float64)[:, None, None]
    pts = t[None] + exact.lincomb(codes, B.reshape(len(B), -1)).reshape(len(codes), *B.shape[1:])  # (N, n, 3)
    centre = 0.5 * (pts.min(axis=1) + pts.max(axis=1))
    radius = np.linalg.norm(pts - centre[:, None], axis=-1).max(axis=1) + float(margin_m)
    return centre, radius
