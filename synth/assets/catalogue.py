"""The asset catalogue (``assets_manifest/`` at the repository's top level; ``synth/assets_manifest`` is a
link to it, so a wheel carries it as package data): reading and checking it.

One TOML file per registered class (``hair.toml``, ``glasses.toml``, ...; the classes are
:data:`synth.assets.classes.NAMES`) holds the class's ``presence`` probability and its
``[[assets]]``; ``rules.toml`` holds compatibility rules (``[[exclude]]``: an asset tagged
``if_tag`` never appears with one tagged in ``excludes_tags``, in either order). Files are
checked against ``synth/schemas/asset.schema.json``. The format is documented in
docs/assets.md and docs/plan-format.md.

:func:`load_catalogue` stops at the first defect (plan time); ``synth assets validate``
(:mod:`synth.assets.validate`) reports every defect of a folder at once with the same
checks. External packs (``generator = "blend:PATH.blend"``) are checked here at load time
(:mod:`synth.assets.packs`) and their entries get a ``pack`` record for the rig.
Sampling from a catalogue is :mod:`synth.plan.assets`.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

from synth.assets import packs
from synth.assets.classes import NAMES, PROCEDURAL_GENERATORS
from synth.assets.params import PARAMS, UNKNOWN_PARAMETER_FIX
from synth.errors import SynthError
from synth.io import sha256_bytes

SCHEMA_PATH = Path(__file__).resolve().parents[1] / "schemas" / "asset.schema.json"
#: Parameters an asset may have: the planner gives each class 2 + MAX_PARAMETERS uniforms
#: (presence, pick, then one per parameter), so this is part of the seed scheme.
MAX_PARAMETERS = 14


def default_manifest_dir() -> Path:
    """The catalogue shipped with synth: ``synth/assets_manifest`` (in a checkout a link to the top-level
    ``assets_manifest/``; in a wheel a copy of it, package data)."""
    return Path(__file__).resolve().parent.parent / "assets_manifest"


@lru_cache(maxsize=1)
def _schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text())


@lru_cache(maxsize=4)
def schema_validator(kind: str):
    """A validator for ``$defs/<kind>`` of the asset schema (``class_file`` or ``rules_file``)."""
    import jsonschema

    return jsonschema.Draft202012Validator({**_schema(), "$ref": f"#/$defs/{kind}"})


@dataclass
class Catalogue:
    classes: dict[str, dict[str, Any]]  # class -> {"presence": p, "assets": [...]}
    rules: list[dict[str, Any]]
    digest: str  # sha256 of the canonical JSON of everything above
    path: str
    #: "class/id" -> pack record (synth.assets.packs.pack_record) of each external asset;
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
        schema_validator(kind).validate(doc)
    except jsonschema.ValidationError as e:
        loc = "/".join(str(p) for p in e.absolute_path) or "top level"
        raise SynthError(f"asset manifest invalid at {loc}: {e.message}", str(path),
                         "see docs/assets.md; 'synth assets validate' lists every defect") from None


def load_catalogue(manifest_dir: str | Path | None = None) -> Catalogue:
    """Read and validate every ``<class>.toml`` and ``rules.toml`` of the folder."""
    d = Path(manifest_dir) if manifest_dir else default_manifest_dir()
    if not d.is_dir():
        raise SynthError("asset manifest folder not found", str(d), "set assets.manifest_dir")
    classes: dict[str, dict[str, Any]] = {}
    pack_records: dict[str, dict[str, Any]] = {}
    for cls in NAMES:
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
            if packs.is_external(a["generator"]):
                root = packs.asset_root_of(doc, p)
                where = f"{p} asset {a['id']}"
                for what, fix in packs.pack_defects(cls, a, root, where):
                    raise SynthError(what, where, fix)
                pack_records[f"{cls}/{a['id']}"] = packs.pack_record(cls, a, root)
        classes[cls] = {"presence": float(doc.get("presence", 1.0)), "assets": doc["assets"]}
    for p in sorted(d.glob("*.toml")):
        if p.stem not in NAMES and p.stem != "rules":
            raise SynthError(f"unknown asset class file '{p.name}'", str(p), f"classes: {', '.join(NAMES)}")
    rules: list[dict[str, Any]] = []
    rp = d / "rules.toml"
    if rp.is_file():
        doc = _read(rp)
        _validate(doc, rp, "rules_file")
        rules = list(doc.get("exclude", []))
    canon = json.dumps({"classes": classes, "rules": rules}, sort_keys=True, separators=(",", ":"))
    return Catalogue(classes, rules, sha256_bytes(canon.encode()), str(d), pack_records)


def _check_params(asset: dict, path: Path) -> None:
    for what, name, fix in parameter_defects(asset):
        where = f"{path} asset {asset['id']} parameter {name}" if name else str(path)
        raise SynthError(what, where, fix)


#: generator -> "module:function" giving (what, parameter, fix) for the values its rig would refuse
GENERATOR_CHECKS = {"procedural:glasses_frame": "synth.assets.fit.glasses.spec:manifest_defects"}


def parameter_defects(asset: dict, max_parameters: int = MAX_PARAMETERS) -> list[tuple[str, str, str]]:
    """(what, parameter name or '', fix) for each inconsistent parameter spec of one asset, and
    each value its generator's rig would refuse (:data:`GENERATOR_CHECKS`)."""
    out: list[tuple[str, str, str]] = []
    gen = str(asset.get("generator", ""))
    check = GENERATOR_CHECKS.get(gen)
    if check is not None and PROCEDURAL_GENERATORS.get(gen.split(":", 1)[-1]) == asset.get("class"):
        import importlib

        module, func = check.split(":")
        out.extend(getattr(importlib.import_module(module), func)(asset))
    params = asset.get("parameters", {}) or {}
    known = PARAMS[asset["class"]].names() if asset.get("class") in PARAMS else None
    if len(params) > max_parameters:
        out.append((f"asset '{asset.get('id')}' has more than {max_parameters} parameters", "",
                    "split it into several assets"))
    for name, spec in params.items():
        if known is not None and name not in known:
            out.append((f"parameter '{name}' is not one the {asset['class']} rig reads", name, UNKNOWN_PARAMETER_FIX))
        if not isinstance(spec, dict):
            continue  # the schema reports it
        if "range" in spec and len(spec["range"]) == 2 and spec["range"][0] > spec["range"][1]:
            out.append(("range low > high", name, "write [low, high]"))
        if "range" in spec and spec.get("log") and spec["range"][0] <= 0:
            out.append(("log range must be positive", name, "use a positive low end"))
        if "choices" in spec and "weights" in spec and len(spec["weights"]) != len(spec["choices"]):
            out.append(("weights and choices differ in length", name, "give one weight per choice"))
        if "choices" in spec and "weights" in spec and spec["weights"] and sum(spec["weights"]) <= 0:
            out.append(("weights sum to zero", name, "give at least one positive weight"))
        if "match" in spec and str(spec["match"]).split(".")[0] not in NAMES:
            out.append((f"match names unknown class in '{spec['match']}'", name, "write 'class.parameter'"))
    return out
