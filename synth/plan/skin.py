"""Skin tone of each identity: an ITA target drawn from the configured distribution over the
six ITA categories, turned into the melanin fraction that gives it (synth.appearance.skin).

Identity i's tone uses one uniform, ``seeds.uniforms(seed, SKIN, i)``, mapped by the inverse
CDF of a piecewise-uniform density over ITA: category k holds probability ``weights[k] /
sum(weights)``, spread uniformly over its ITA interval (the outer categories end at
``skin.ita_limits_deg``). The haemoglobin fraction (drawn with the other skin parameters from
the catalogue) is fixed first, so the melanin hits the target exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from synth import seeds
from synth.appearance.skin import ITA_CATEGORIES, melanin_for_ita
from synth.assets.params import SkinParams


def category_intervals(limits_deg) -> np.ndarray:
    """(6, 2) ITA intervals [low, high) of the categories (lightest first) within the limits."""
    lo, hi = float(limits_deg[0]), float(limits_deg[1])
    bounds = [hi] + [b for _, b in ITA_CATEGORIES[:-1]] + [lo]
    return np.array([[bounds[k + 1], bounds[k]] for k in range(len(ITA_CATEGORIES))])


def ita_from_uniform(u, weights, limits_deg) -> np.ndarray:
    """ITA targets (degrees) for uniforms in [0, 1): the inverse CDF of the piecewise-uniform
    density (category k: probability weights[k] / sum, uniform over its interval (low, high],
    the convention of :func:`synth.appearance.skin.ita_category`). Categories with zero weight
    (or cut away by the limits) are never drawn."""
    iv = category_intervals(limits_deg)
    w = np.asarray(weights, np.float64) * (iv[:, 1] > iv[:, 0])
    upper = np.cumsum(w) / w.sum()
    u = np.asarray(u, np.float64)
    last = int(np.nonzero(w > 0)[0][-1])
    k = np.minimum(np.searchsorted(upper, u, side="right"), last)  # first category whose upper CDF exceeds u
    lower = np.where(k > 0, upper[np.maximum(k - 1, 0)], 0.0)
    frac = np.clip((u - lower) / (upper[k] - lower), 0.0, 1.0)
    return iv[k, 1] - frac * (iv[k, 1] - iv[k, 0])  # the light end of a category first


def apply_skin_tones(seed: int, identities, assets: list[dict[str, Any]], skin_cfg) -> None:
    """Set ``melanin`` and ``ita_deg`` in the skin parameters of each identity's assets (in place;
    identities without a skin pick are left alone)."""
    ids = np.asarray(identities, np.int64).reshape(-1)
    rows = [n for n in range(ids.size) if assets[n].get("skin")]
    if not rows:
        return
    u = seeds.uniforms(seed, seeds.Stream.SKIN, ids[rows], None, None, n=1)[..., 0]
    ita = ita_from_uniform(u, skin_cfg.ita_weights, skin_cfg.ita_limits_deg)
    hb = np.array([float(assets[n]["skin"]["params"].get("haemoglobin", SkinParams.haemoglobin)) for n in rows])
    mel = melanin_for_ita(ita, hb)
    for j, n in enumerate(rows):
        p = assets[n]["skin"]["params"]
        p["melanin"] = round(float(mel[j]), 8)
        p["ita_deg"] = round(float(ita[j]), 8)
        assets[n]["skin"]["params"] = dict(sorted(p.items()))
