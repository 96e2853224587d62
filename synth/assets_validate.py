"""Whole-catalogue validation (``synth assets validate``) and the checks on external packs.

Pure Python (no ``bpy``). :func:`validate_manifest` reads every file of an asset-manifest
folder and returns *all* defects it finds, one :class:`Defect` each (what, where, what to
do), instead of stopping at the first like :func:`synth.plan.assets.load_catalogue`.

External packs (``generator = "blend:PATH.blend"``) are checked here and again, by the same
functions, when the catalogue is loaded at plan time and when the rig links the file
(``blender_scripts/assets/external.py``): the file must exist, lie inside the declared asset
root once symlinks are resolved, and have the declared sha256. See docs/assets.md.
"""

from __future__ import annotations

import json
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from synth.config import ASSET_CLASSES
from synth.dataset.fsio import sha256_file  # noqa: F401 - re-exported for the pack rig
from synth.errors import SynthError

#: Procedural generator name -> the asset class whose rig (blender_scripts.assets.MODULES)
#: builds it. A new procedural generator is added here (or, if blender_scripts.assets grows a
#: ``GENERATORS`` mapping of the same shape, there; that one then wins).
PROCEDURAL_GENERATORS: dict[str, str] = {
    "skin_shader": "skin", "iris_shader": "iris", "hair_strands": "hair", "eyebrow_strands": "eyebrows",
    "eyelash_cards": "eyelashes", "beard_strands": "beard", "makeup_layer": "makeup",
    "garment_shell": "garment", "glasses_frame": "glasses", "headwear_shell": "headwear",
}

#: Classes an external pack may provide (geometry classes; skin, iris and makeup are shader
#: layers on the head's own materials) and the point each is anchored to by default.
PACK_ANCHORS: dict[str, str] = {"hair": "head", "beard": "head", "eyebrows": "head", "eyelashes": "head",
                                "headwear": "head", "glasses": "nose_bridge", "garment": "neck"}
ANCHORS = ("head", "nose_bridge", "neck")
#: Skull width (X extent of the scalp region in the head-joint frame, metres) a pack is
#: modelled for unless the entry says otherwise (the default head measures 0.149 m).
REFERENCE_SKULL_WIDTH_M = 0.15
#: Entry keys only an external pack may carry.
PACK_KEYS = ("object", "sha256", "anchor", "reference_width_m")

DOCS = "see docs/assets.md"


@dataclass(frozen=True)
class Defect:
    what: str
    where: str
    fix: str

    def line(self) -> str:
        """One line, formatted like a SynthError: what (where); fix."""
        return f"{self.what} ({self.where}); {self.fix}"


@dataclass
class Report:
    manifest_dir: str
    defects: list[Defect] = field(default_factory=list)
    files: int = 0
    assets: int = 0
    packs: int = 0

    @property
    def ok(self) -> bool:
        return not self.defects

    def add(self, what: str, where: Any, fix: str) -> None:
        self.defects.append(Defect(what, str(where), fix))


# --------------------------------------------------------------------------- external packs


def is_external(generator: str) -> bool:
    """True for a pack generator (``blend:PATH.blend`` or a bare ``PATH.blend``)."""
    g = str(generator)
    return g.startswith("blend:") or g.endswith(".blend") or ".blend#" in g


def split_generator(generator: str) -> tuple[str, str | None]:
    """``blend:packs/a.blend#Cap`` -> (``packs/a.blend``, ``Cap``); without ``#``: (path, None)."""
    g = str(generator)
    if g.startswith("blend:"):
        g = g[len("blend:"):]
    path, sep, obj = g.partition("#")
    return path, (obj or None) if sep else None


def pack_object_name(entry: dict) -> str | None:
    """The object or collection to link: the entry's ``object``, else the generator's ``#NAME``."""
    return entry.get("object") or split_generator(entry.get("generator", ""))[1]


def asset_root_of(doc: dict, manifest_file: Path) -> Path:
    """The folder packs of one class file are confined to: its top-level ``asset_root``
    (relative to the manifest folder, or absolute), default the manifest folder itself."""
    base = Path(manifest_file).resolve().parent
    root = doc.get("asset_root")
    return (base / root) if root else base


def pack_path_problem(rel: str, root: str | Path) -> tuple[Path | None, tuple[str, str] | None]:
    """Resolve a pack path inside ``root``. Returns (resolved path, None) or (None, (what, fix)).

    Symlinks are resolved (the root's too) before the confinement test, so neither ``..``
    nor a link may lead outside the root; an absolute path is accepted only if it resolves
    inside the root."""
    if not rel:
        return None, ("external pack names no .blend file", "write generator = \"blend:PATH.blend\"")
    if not str(rel).endswith(".blend"):
        return None, (f"external pack '{rel}' is not a .blend file", "point the generator at a .blend file")
    root_p = Path(root)
    if not root_p.is_dir():
        return None, (f"asset root '{root_p}' is not a folder", "fix asset_root (relative to the manifest folder)")
    root_r = root_p.resolve()
    cand = root_r / rel  # an absolute rel replaces the root here; it is then checked like any other
    try:
        real = Path(os.path.realpath(cand))
    except (OSError, RuntimeError) as e:  # symlink loop
        return None, (f"external pack path '{rel}' cannot be resolved: {e}", "fix the path or the symlink")
    if not real.is_relative_to(root_r):
        if Path(os.path.normpath(cand)).is_relative_to(root_r):
            how = "a symlink"
        else:
            how = "an absolute path" if Path(rel).is_absolute() else "'..'"
        return None, (f"external pack '{rel}' escapes the asset root {root_r} via {how} (resolves to {real})",
                      "keep pack files inside asset_root; copy the file there instead of linking to it")
    if not real.exists():
        return None, (f"external pack file '{rel}' not found (looked for {real})",
                      "restore the file or fix the generator path")
    if not real.is_file():
        return None, (f"external pack '{rel}' is not a file ({real})", "point the generator at a .blend file")
    return real, None


def verify_pack(rel: str, root: str | Path, sha256: str | None, where: str) -> Path:
    """Resolve, confine and checksum one pack file; the resolved path or a SynthError.

    Used at plan time (load_catalogue) and by the rig before linking (defence in depth)."""
    real, problem = pack_path_problem(rel, root)
    if problem:
        raise SynthError(problem[0], where, problem[1])
    if not sha256:
        raise SynthError(f"external pack '{rel}' declares no sha256", where,
                         f"add sha256 = \"{sha256_file(real)}\" after checking the file")
    got = sha256_file(real)
    if got != sha256.lower():
        raise SynthError(f"external pack file {real} does not match its checksum (sha256 {got}, declared {sha256})",
                         where, "the file changed: restore the original or review it and update sha256")
    return real


def pack_record(cls: str, entry: dict, root: Path) -> dict:
    """What the plan stores for an external asset (``asset_choice["pack"]``) and the rig reads."""
    rel, _ = split_generator(entry["generator"])
    return {"class": cls, "file": rel, "asset_root": str(Path(root).resolve()), "object": pack_object_name(entry),
            "sha256": str(entry.get("sha256", "")).lower(),
            "anchor": entry.get("anchor", PACK_ANCHORS.get(cls, "head")),
            "reference_width_m": float(entry.get("reference_width_m", REFERENCE_SKULL_WIDTH_M))}


def pack_defects(cls: str, entry: dict, root: Path, where: str) -> list[tuple[str, str]]:
    """Every problem of one external entry as (what, fix) pairs (empty when it is usable)."""
    out: list[tuple[str, str]] = []
    if cls not in PACK_ANCHORS:
        out.append((f"class '{cls}' cannot come from an external pack (it is a shader layer on the head)",
                    f"use a procedural generator; packs may provide: {', '.join(PACK_ANCHORS)}"))
    if not pack_object_name(entry):
        out.append(("external pack names no object or collection",
                    "add object = \"NAME\" (the object or collection inside the .blend)"))
    if not str(entry.get("licence", "")).strip():
        out.append(("external pack has no licence", "add licence = \"...\" (the pack's licence)"))
    rel, _ = split_generator(entry.get("generator", ""))
    real, problem = pack_path_problem(rel, root)
    if problem:
        out.append(problem)
        return out
    declared = entry.get("sha256")
    if not declared:
        out.append((f"external pack '{rel}' declares no sha256",
                    f"add sha256 = \"{sha256_file(real)}\" after checking the file"))
    else:
        got = sha256_file(real)
        if got != str(declared).lower():
            out.append((f"external pack file {real} does not match its checksum (sha256 {got}, declared {declared})",
                        "the file changed: restore the original or review it and update sha256"))
    return out


# --------------------------------------------------------------------------- parameters


def parameter_defects(asset: dict, max_parameters: int) -> list[tuple[str, str, str]]:
    """(what, parameter name or '', fix) for each inconsistent parameter spec of one asset."""
    out: list[tuple[str, str, str]] = []
    params = asset.get("parameters", {}) or {}
    if len(params) > max_parameters:
        out.append((f"asset '{asset.get('id')}' has more than {max_parameters} parameters", "",
                    "split it into several assets"))
    for name, spec in params.items():
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
        if "match" in spec and str(spec["match"]).split(".")[0] not in ASSET_CLASSES:
            out.append((f"match names unknown class in '{spec['match']}'", name, "write 'class.parameter'"))
    return out


# --------------------------------------------------------------------------- whole catalogue


def _generators() -> dict[str, str]:
    try:
        import blender_scripts.assets as ba

        return dict(getattr(ba, "GENERATORS", PROCEDURAL_GENERATORS))
    except Exception:  # noqa: BLE001 - the package is optional for pure-Python validation
        return dict(PROCEDURAL_GENERATORS)


def _rig_modules() -> dict[str, str]:
    try:
        from blender_scripts.assets import MODULES

        return dict(MODULES)
    except Exception:  # noqa: BLE001
        return {"hair": "hair", "beard": "beard", "eyebrows": "eyebrows", "eyelashes": "eyelashes",
                "garment": "garment", "glasses": "glasses", "headwear": "headwear", "makeup": "makeup",
                "iris": "iris", "skin": "skin_detail"}


def _show(p: str | Path) -> str:
    """A path as printed in reports: relative to the working directory when inside it."""
    try:
        r = os.path.relpath(p)
    except ValueError:
        return str(p)
    return str(p) if r.startswith("..") else r


def default_rigs_dir() -> Path:
    return Path(__file__).resolve().parents[1] / "blender_scripts" / "assets"


def _schema_message(e) -> str:
    msg = e.message
    if e.validator == "oneOf" and e.context and isinstance(e.instance, dict):
        # a parameter spec: report the error of the form whose key it uses ({range: [1]} -> too short)
        import jsonschema

        same = [c for c in e.context if c.schema_path and isinstance(c.schema_path[0], int)
                and all(k in e.instance for k in e.validator_value[c.schema_path[0]].get("required", []))]
        best = jsonschema.exceptions.best_match(same or e.context)
        msg = f"not a valid parameter form (range, choices, probability, value or match): {best.message}"
    return msg if len(msg) <= 240 else msg[:237] + "..."


def validate_manifest(manifest_dir: str | Path | None = None, rigs_dir: str | Path | None = None) -> Report:
    """Check every file of a manifest folder; all defects, in file order."""
    from synth.plan import assets as pa

    d = Path(manifest_dir) if manifest_dir else pa.default_manifest_dir()
    rep = Report(str(d))
    if not d.is_dir():
        rep.add("asset manifest folder not found", d, "pass --manifest-dir or set assets.manifest_dir")
        return rep
    rigs = Path(rigs_dir) if rigs_dir else default_rigs_dir()
    gens, modules = _generators(), _rig_modules()
    all_tags: set[str] = set()
    missing_rig_reported: set[tuple[str, str]] = set()

    for p in sorted(d.glob("*.toml")):
        p = Path(_show(p))
        if p.stem not in ASSET_CLASSES and p.stem != "rules":
            rep.add(f"unknown asset class file '{p.name}'", p,
                    f"name class files after a class: {', '.join(ASSET_CLASSES)}")

    for cls in ASSET_CLASSES:
        p = Path(_show(d / f"{cls}.toml"))
        if not p.is_file():
            rep.add(f"class '{cls}' has no manifest file", p, f"add {cls}.toml (presence = 0 switches the class off)")
            continue
        rep.files += 1
        try:
            with p.open("rb") as f:
                doc = tomllib.load(f)
        except tomllib.TOMLDecodeError as e:
            rep.add(f"not valid TOML: {e}", p, "fix the syntax")
            continue
        for e in sorted(pa._validator("class_file").iter_errors(doc), key=lambda e: list(map(str, e.absolute_path))):
            loc = "/".join(str(x) for x in e.absolute_path) or "top level"
            rep.add(f"schema: {_schema_message(e)}", f"{p} at {loc}", DOCS)
        if doc.get("class") not in (None, cls):
            rep.add(f"file declares class '{doc.get('class')}'", p, f"a {cls}.toml file holds class {cls}")
        assets = doc.get("assets") if isinstance(doc.get("assets"), list) else []
        root = asset_root_of(doc, p)
        seen: dict[str, int] = {}
        for k, a in enumerate(assets):
            if not isinstance(a, dict):
                continue
            rep.assets += 1
            aid = str(a.get("id", f"#{k}"))
            where = f"{p} asset {aid}"
            if aid in seen:
                rep.add(f"duplicate asset id '{aid}' (also asset #{seen[aid]})", where, "give every asset a unique id")
            else:
                seen[aid] = k
            if a.get("class") not in (None, cls):
                rep.add(f"asset '{aid}' has class '{a.get('class')}'", where, f"use class = '{cls}'")
            tags = a.get("tags", [])
            if isinstance(tags, list):
                all_tags.update(str(t) for t in tags)
            for what, name, fix in parameter_defects(a, pa.MAX_PARAMETERS):
                rep.add(what, f"{where} parameter {name}" if name else where, fix)
            gen = str(a.get("generator", ""))
            if is_external(gen):
                rep.packs += 1
                for what, fix in pack_defects(cls, a, root, where):
                    rep.add(what, where, fix)
            elif gen.startswith("procedural:"):
                name = gen.split(":", 1)[1]
                extra = [k2 for k2 in PACK_KEYS if k2 in a]
                if extra:
                    rep.add(f"pack-only field(s) {', '.join(extra)} on a procedural asset", where,
                            "remove them, or use generator = \"blend:PATH.blend\"")
                owner = gens.get(name)
                if owner is None:
                    rep.add(f"unknown generator '{gen}'", where,
                            f"use one of: {', '.join('procedural:' + g for g in sorted(gens))}, or blend:PATH.blend")
                    continue
                if owner != cls:
                    rep.add(f"generator '{gen}' builds class '{owner}', not '{cls}'", where,
                            f"use a {cls} generator")
                    continue
                mod = modules.get(cls)
                f_mod = rigs / f"{mod}.py" if mod else None
                if (f_mod is None or not (f_mod.is_file() or (rigs / str(mod) / "__init__.py").is_file())) \
                        and (str(p), gen) not in missing_rig_reported:
                    missing_rig_reported.add((str(p), gen))
                    rep.add(f"no rig module for generator '{gen}': {_show(f_mod) if f_mod else mod} is missing", p,
                            f"add blender_scripts/assets/{mod}.py with build(ctx, entry)")

    rp = Path(_show(d / "rules.toml"))
    if rp.is_file():
        rep.files += 1
        try:
            with rp.open("rb") as f:
                doc = tomllib.load(f)
        except tomllib.TOMLDecodeError as e:
            rep.add(f"not valid TOML: {e}", rp, "fix the syntax")
            return rep
        errs = list(pa._validator("rules_file").iter_errors(doc))
        for e in errs:
            loc = "/".join(str(x) for x in e.absolute_path) or "top level"
            rep.add(f"schema: {_schema_message(e)}", f"{rp} at {loc}", DOCS)
        if not errs:
            for k, r in enumerate(doc.get("exclude", [])):
                for t in [r["if_tag"], *r["excludes_tags"]]:
                    if t not in all_tags:
                        rep.add(f"rule names tag '{t}' that no asset carries", f"{rp} exclude #{k}",
                                "fix the tag's spelling or remove it from the rule")
    return rep


def report_json(rep: Report) -> str:
    return json.dumps({"manifest_dir": rep.manifest_dir, "ok": rep.ok, "files": rep.files, "assets": rep.assets,
                       "packs": rep.packs, "defects": [d.__dict__ for d in rep.defects]}, indent=2)
