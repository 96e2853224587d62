"""The asset catalogue (``assets_manifest/``): reading, validation and per-identity sampling.

One TOML file per class (``hair.toml``, ``glasses.toml``, ...) holds the class's
``presence`` probability and its ``[[assets]]``; ``rules.toml`` holds compatibility rules
(``[[exclude]]``: an asset tagged ``if_tag`` never appears with one tagged in
``excludes_tags``, in either order). Files are checked against
``synth/schemas/asset.schema.json``. The format is documented in docs/plan-format.md.

Sampling, per identity i and class c (in ASSET_CLASSES order), from the uniforms
``seeds.uniforms(seed, ASSETS, i, expression=c's position)``: presence, then an asset by
weight among those compatible with the classes already chosen, then its parameters from
their ranges. Classes use independent counters, so editing one class never changes the
uniforms of another.

External packs (``generator = "blend:PATH.blend"``, docs/assets.md) are checked here at plan
time (file inside the file's ``asset_root``, sha256 as declared) and their picks carry a
``pack`` record for the rig. ``synth assets validate`` (synth/assets_validate.py) reports every
defect of a folder at once; this loader stops at the first.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from synth import seeds
from synth.config import ASSET_CLASSES
from synth.errors import SynthError

SCHEMA_PATH = Path(__file__).resolve().parents[1] / "schemas" / "asset.schema.json"


def default_manifest_dir() -> Path:
    return Path(__file__).resolve().parents[2] / "assets_manifest"


@lru_cache(maxsize=1)
def _schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text())


@lru_cache(maxsize=4)
def _validator(kind: str):
    import jsonschema

    return jsonschema.Draft202012Validator({**_schema(), "$ref": f"#/$defs/{kind}"})


@dataclass
class Catalogue:
    classes: dict[str, dict[str, Any]]  # class -> {"presence": p, "assets": [...]}
    rules: list[dict[str, Any]]
    digest: str  # sha256 of the canonical JSON of everything above
    path: str
    #: "class/id" -> pack record (synth.assets_validate.pack_record) of each external asset;
    #: not part of the digest (its asset_root is an absolute, machine-dependent path; the
    #: file's sha256 is in the digest through the entry itself)
    packs: dict[str, dict[str, Any]] = field(default_factory=dict)


def _read(path: Path) -> dict:
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise SynthError(f"asset manifest is not valid TOML: {e}", str(path), "fix the syntax") from None


def _validate(doc: dict, path: Path, kind: str = "class_file") -> None:
    import jsonschema

    try:
        _validator(kind).validate(doc)
    except jsonschema.ValidationError as e:
        loc = "/".join(str(p) for p in e.absolute_path) or "top level"
        raise SynthError(f"asset manifest invalid at {loc}: {e.message}", str(path),
                         "see docs/assets.md; 'synth assets validate' lists every defect") from None


def load_catalogue(manifest_dir: str | Path | None = None) -> Catalogue:
    """Read and validate every ``<class>.toml`` and ``rules.toml`` of the folder."""
    d = Path(manifest_dir) if manifest_dir else default_manifest_dir()
    if not d.is_dir():
        raise SynthError("asset manifest folder not found", str(d), "set assets.manifest_dir")
    from synth import assets_validate as av

    classes: dict[str, dict[str, Any]] = {}
    packs: dict[str, dict[str, Any]] = {}
    for cls in ASSET_CLASSES:
        p = d / f"{cls}.toml"
        if not p.is_file():
            continue
        doc = _read(p)
        _validate(doc, p)
        if doc["class"] != cls:
            raise SynthError(f"file declares class '{doc['class']}'", str(p), f"a {cls}.toml file holds class {cls}")
        ids = [a["id"] for a in doc["assets"]]
        if len(set(ids)) != len(ids):
            raise SynthError("duplicate asset id", str(p), "give every asset a unique id")
        for a in doc["assets"]:
            if a["class"] != cls:
                raise SynthError(f"asset '{a['id']}' has class '{a['class']}'", str(p), f"use class = '{cls}'")
            _check_params(a, p)
            if av.is_external(a["generator"]):
                root = av.asset_root_of(doc, p)
                where = f"{p} asset {a['id']}"
                for what, fix in av.pack_defects(cls, a, root, where):
                    raise SynthError(what, where, fix)
                packs[f"{cls}/{a['id']}"] = av.pack_record(cls, a, root)
        classes[cls] = {"presence": float(doc.get("presence", 1.0)), "assets": doc["assets"]}
    for p in sorted(d.glob("*.toml")):
        if p.stem not in ASSET_CLASSES and p.stem != "rules":
            raise SynthError(f"unknown asset class file '{p.name}'", str(p), f"classes: {', '.join(ASSET_CLASSES)}")
    rules: list[dict[str, Any]] = []
    rp = d / "rules.toml"
    if rp.is_file():
        doc = _read(rp)
        _validate(doc, rp, "rules_file")
        rules = list(doc.get("exclude", []))
    canon = json.dumps({"classes": classes, "rules": rules}, sort_keys=True, separators=(",", ":"))
    return Catalogue(classes, rules, hashlib.sha256(canon.encode()).hexdigest(), str(d), packs)


def _check_params(asset: dict, path: Path) -> None:
    from synth.assets_validate import parameter_defects

    for what, name, fix in parameter_defects(asset, MAX_PARAMETERS):
        where = f"{path} asset {asset['id']} parameter {name}" if name else str(path)
        raise SynthError(what, where, fix)


MAX_PARAMETERS = 14  # uniform slots per asset: presence, pick, then one per parameter
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
        return round(float(np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo)))), 8)
    return round(float(lo + u * (hi - lo)), 8)  # plans store floats to 8 decimals


def _prepared(cat: Catalogue) -> list[tuple[str, float, list[dict], np.ndarray, list[frozenset], list[frozenset]]]:
    """Per class: presence, assets, cumulative weights, tag sets and the tags each asset excludes."""
    out = []
    for cls in ASSET_CLASSES:
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
    ``seeds.uniforms(seed, ASSETS, i, expression=c's position in ASSET_CLASSES)``: slot 0 =
    presence, 1 = pick, 2 + k = the k-th parameter in name order."""
    ids = np.asarray(identities, np.int64).reshape(-1)
    u = seeds.uniforms(seed, seeds.Stream.ASSETS, ids[:, None], np.arange(len(ASSET_CLASSES))[None, :], None,
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


def sample_lighting(seed: int, identity: int, lighting) -> dict[str, Any]:
    """The environment of one identity (``lighting``: LightingConfig)."""
    if lighting.environment == "uniform":
        return {"environment": "uniform", "strength": lighting.strength, "color": list(lighting.color)}
    rng = seeds.generator(seed, seeds.Stream.LIGHTING, identity=identity)
    files = lighting.hdri_files
    f = files[min(len(files) - 1, int(rng.random() * len(files)))]
    lo, hi = lighting.hdri_rotation_deg
    return {"environment": "hdri", "file": f, "rotation_deg": round(float(lo + rng.random() * (hi - lo)), 8),
            "strength": lighting.strength}
