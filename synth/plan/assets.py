"""Sampling the assets of each identity from the catalogue (:mod:`synth.assets.catalogue`).

Sampling, per identity i and class c (in plan order, :data:`synth.assets.classes.NAMES`),
from the uniforms ``seeds.uniforms(seed, ASSETS, i, expression=c's slot)``: presence, then
an asset by weight among those compatible with the classes already chosen, then its
parameters from their ranges. Classes use independent counters, so editing one class never
changes the uniforms of another. Picks of external packs carry the catalogue's ``pack``
record for the rig.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from synth import seeds
from synth.assets.catalogue import MAX_PARAMETERS, Catalogue
from synth.assets.classes import CLASSES, NAMES
from synth.geometry import exact

_SLOTS = 2 + MAX_PARAMETERS


def _draw_param(spec: dict, u: float, chosen: dict[str, dict]) -> Any:
    """One parameter from its spec and one uniform in [0, 1)."""
    if "match" in spec:
        cls, pname = spec["match"].split(".", 1)
        if cls in chosen and pname in chosen[cls]["params"]:
            return chosen[cls]["params"][pname]
        spec = spec.get("otherwise", {"value": None})
    if "value" in spec:
        return spec["value"]
    if "probability" in spec:
        return bool(u < spec["probability"])
    if "choices" in spec:
        w = np.asarray(spec.get("weights", [1.0] * len(spec["choices"])), np.float64)
        k = int(np.searchsorted(np.cumsum(w) / w.sum(), u, side="right"))
        return spec["choices"][min(k, len(spec["choices"]) - 1)]
    lo, hi = spec["range"]
    if spec.get("integer"):
        return int(min(hi, lo + int(u * (hi - lo + 1))))
    if spec.get("log"):
        return round(float(exact.exp(exact.log(lo) + u * (exact.log(hi) - exact.log(lo)))), 8)
    return round(float(lo + u * (hi - lo)), 8)  # plans store floats to 8 decimals


def _prepared(cat: Catalogue) -> list[tuple[str, float, list[dict], np.ndarray, list[frozenset], list[frozenset]]]:
    """Per class: presence, assets, cumulative weights, tag sets and the tags each asset excludes."""
    out = []
    for cls in NAMES:
        c = cat.classes.get(cls)
        if c is None:
            out.append((cls, 0.0, [], np.zeros(0), [], []))
            continue
        tags = [frozenset(a.get("tags", ())) for a in c["assets"]]
        excl = [frozenset().union(*[r["excludes_tags"] for r in cat.rules if r["if_tag"] in t]) for t in tags]
        w = np.array([a.get("weight", 1.0) for a in c["assets"]], np.float64)
        out.append((cls, c["presence"], c["assets"], w, tags, excl))
    return out


def sample_assets_batch(seed: int, identities, cat: Catalogue, disabled: tuple[str, ...] = ()) -> list[dict]:
    """Assets of each identity: ``{class: {"id", "generator", "params"} | None}`` (the frame
    JSON's asset_choice). Class c of identity i uses the uniforms
    ``seeds.uniforms(seed, ASSETS, i, expression=c's slot)`` (classes.py): slot 0 =
    presence, 1 = pick, 2 + k = the k-th parameter in name order."""
    ids = np.asarray(identities, np.int64).reshape(-1)
    slots = np.array([CLASSES[c].slot for c in NAMES], np.int64)
    u = seeds.uniforms(seed, seeds.Stream.ASSETS, ids[:, None], slots[None, :], None,
                       n=_SLOTS).tolist()
    prep = _prepared(cat)
    result = []
    for n in range(ids.size):
        out: dict[str, Any] = {}
        chosen: dict[str, dict] = {}
        chosen_tags: set = set()
        forbidden: set = set()
        for ci, (cls, presence, assets, w, tags, excl) in enumerate(prep):
            un = u[n][ci]
            if not assets or cls in disabled or un[0] >= presence:
                out[cls] = None
                continue
            ok = [k for k in range(len(assets)) if not (tags[k] & forbidden) and not (excl[k] & chosen_tags)]
            if not ok:
                out[cls] = None
                continue
            cw = np.cumsum(w[ok])
            k = ok[min(len(ok) - 1, int(np.searchsorted(cw / cw[-1], un[1], side="right")))]
            a = assets[k]
            params = {name: _draw_param(spec, un[2 + j], chosen)
                      for j, (name, spec) in enumerate(sorted(a.get("parameters", {}).items()))}
            pick = {"id": a["id"], "generator": a["generator"], "params": params}
            pack = cat.packs.get(f"{cls}/{a['id']}")
            if pack is not None:  # external assets only: the procedural picks stay as they were
                pick["pack"] = dict(pack)
            chosen[cls] = pick
            chosen_tags |= tags[k]
            forbidden |= excl[k]
            out[cls] = pick
        result.append(out)
    return result


def sample_assets(seed: int, identity: int, cat: Catalogue, disabled: tuple[str, ...] = ()) -> dict[str, Any]:
    """Assets of one identity (see :func:`sample_assets_batch`)."""
    return sample_assets_batch(seed, [identity], cat, disabled)[0]


def _studio(lighting, rotation_deg: float) -> dict[str, Any]:
    return {"environment": "studio", "strength": lighting.strength, "color": list(lighting.color),
            "key_deg": list(lighting.studio_key_deg), "key_size_deg": lighting.studio_key_size_deg,
            "key_share": lighting.studio_key_share, "fill_deg": list(lighting.studio_fill_deg),
            "fill_size_deg": lighting.studio_fill_size_deg, "fill_share": lighting.studio_fill_share,
            "rotation_deg": round(float(rotation_deg), 8)}


def _hdri(lighting, rng: np.random.Generator) -> dict[str, Any]:
    files = lighting.hdri_files
    f = files[min(len(files) - 1, int(rng.random() * len(files)))]
    lo, hi = lighting.hdri_rotation_deg
    return {"environment": "hdri", "file": f, "rotation_deg": round(float(lo + rng.random() * (hi - lo)), 8),
            "strength": lighting.strength}


def sample_lighting(seed: int, identity: int, lighting) -> dict[str, Any]:
    """The environment of one identity (``lighting``: LightingConfig): environment 0 of each of
    its expressions."""
    if lighting.environment == "uniform":
        return {"environment": "uniform", "strength": lighting.strength, "color": list(lighting.color)}
    rng = seeds.generator(seed, seeds.Stream.LIGHTING, identity=identity)
    if lighting.environment == "studio":
        lo, hi = lighting.studio_rotation_deg
        return _studio(lighting, lo + rng.random() * (hi - lo))
    return _hdri(lighting, rng)


#: Rotation range of the drawn procedural studios (environments 1..): the whole circle.
STUDIO_ROTATION_DEG = (-180.0, 180.0)


def sample_environment(seed: int, identity: int, expression: int, environment: int, lighting) -> dict[str, Any]:
    """Environment ``environment`` >= 1 of one expression, a pure function of (seed, identity,
    expression, environment): a map drawn from ``lighting.hdri_files`` (and a rotation from
    ``lighting.hdri_rotation_deg``) when ``lighting.environment`` is 'hdri', else the procedural
    studio of ``lighting`` turned by a rotation drawn from :data:`STUDIO_ROTATION_DEG`."""
    rng = seeds.generator(seed, seeds.Stream.ENVIRONMENT, identity=identity, expression=expression,
                          view=environment)
    if lighting.environment == "hdri":
        return _hdri(lighting, rng)
    lo, hi = STUDIO_ROTATION_DEG
    return _studio(lighting, lo + rng.random() * (hi - lo))


#: How far each hair parameter lets the hair reach beyond the scalp, as (fraction of it, cap in
#: metres): long hair falls along the head, so only part of its length widens the silhouette.
_REACH = {"length_m": (0.6, 0.08), "top_length_m": (0.6, 0.08), "tail_length_m": (0.6, 0.08),
          "bun_radius_m": (2.0, 0.1), "volume_radius_m": (1.0, 0.1)}
#: Headwear (a brim, a pompom) reaches this far beyond the skull.
HEADWEAR_REACH_M = 0.03


def hair_reach_m(assets: list[dict[str, Any]]) -> np.ndarray:
    """(N,) rough reach (metres) of each identity's hair and headwear beyond the head, from the
    planned parameters (:data:`_REACH`, the largest term counts): room the camera framing
    leaves around the head."""
    out = np.zeros(len(assets))
    for n, a in enumerate(assets):
        prm = (a.get("hair") or {}).get("params", {})
        r = [min(f * float(prm[k]), cap) for k, (f, cap) in _REACH.items() if isinstance(prm.get(k), (int, float))]
        out[n] = max(r, default=0.0) + (HEADWEAR_REACH_M if a.get("headwear") else 0.0)
    return out
