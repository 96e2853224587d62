"""Whole-catalogue validation: ``synth assets validate``.

Pure Python (no ``bpy``). :func:`validate_manifest` reads every file of an asset-manifest
folder and returns *all* defects it finds, one :class:`Defect` each (what, where, what to
do), instead of stopping at the first like :func:`synth.assets.catalogue.load_catalogue`.
The classes, their generators and rig modules come from the registry
(:mod:`synth.assets.classes`); external packs are checked by :mod:`synth.assets.packs`.
See docs/assets.md.
"""

from __future__ import annotations

import json
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from synth.assets import catalogue
from synth.assets.classes import CLASSES, NAMES, PROCEDURAL_GENERATORS
from synth.assets.packs import PACK_KEYS, asset_root_of, is_external, pack_defects

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


# --------------------------------------------------------------------------- whole catalogue


def _show(p: str | Path) -> str:
    """A path as printed in reports: relative to the working directory when inside it."""
    try:
        r = os.path.relpath(p)
    except ValueError:
        return str(p)
    return str(p) if r.startswith("..") else r


def default_rigs_dir() -> Path:
    return Path(__file__).resolve().parents[2] / "blender_scripts" / "assets"


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


def _read_toml(p: Path, rep: Report) -> dict | None:
    """A TOML file's content, or None after reporting why it cannot be read."""
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        rep.add(f"not valid TOML: {e}", p, "fix the syntax")
        return None


def validate_manifest(manifest_dir: str | Path | None = None, rigs_dir: str | Path | None = None) -> Report:
    """Check every file of a manifest folder; all defects, in file order."""
    d = Path(manifest_dir) if manifest_dir else catalogue.default_manifest_dir()
    rep = Report(str(d))
    if not d.is_dir():
        rep.add("asset manifest folder not found", d, "pass --manifest-dir or set assets.manifest_dir")
        return rep
    rigs = Path(rigs_dir) if rigs_dir else default_rigs_dir()
    all_tags: set[str] = set()
    missing_rig_reported: set[tuple[str, str]] = set()

    for p in sorted(d.glob("*.toml")):
        p = Path(_show(p))
        if p.stem not in NAMES and p.stem != "rules":
            rep.add(f"unknown asset class file '{p.name}'", p,
                    f"name class files after a class: {', '.join(NAMES)}")

    for cls in NAMES:
        p = Path(_show(d / f"{cls}.toml"))
        if not p.is_file():
            rep.add(f"class '{cls}' has no manifest file", p, f"add {cls}.toml (presence = 0 switches the class off)")
            continue
        rep.files += 1
        doc = _read_toml(p, rep)
        if doc is None:
            continue
        errs = catalogue.schema_validator("class_file").iter_errors(doc)
        for e in sorted(errs, key=lambda e: list(map(str, e.absolute_path))):
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
            for what, name, fix in catalogue.parameter_defects(a):
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
                owner = PROCEDURAL_GENERATORS.get(name)
                if owner is None:
                    rep.add(f"unknown generator '{gen}'", where,
                            f"use one of: {', '.join('procedural:' + g for g in sorted(PROCEDURAL_GENERATORS))}, "
                            "or blend:PATH.blend")
                    continue
                if owner != cls:
                    rep.add(f"generator '{gen}' builds class '{owner}', not '{cls}'", where,
                            f"use a {cls} generator")
                    continue
                mod = CLASSES[cls].rig
                f_mod = rigs / f"{mod}.py"
                if not (f_mod.is_file() or (rigs / mod / "__init__.py").is_file()) \
                        and (str(p), gen) not in missing_rig_reported:
                    missing_rig_reported.add((str(p), gen))
                    rep.add(f"no rig module for generator '{gen}': {_show(f_mod)} is missing", p,
                            f"add blender_scripts/assets/{mod}.py with build(ctx, entry)")

    rp = Path(_show(d / "rules.toml"))
    if rp.is_file():
        rep.files += 1
        doc = _read_toml(rp, rep)
        if doc is None:
            return rep
        errs = list(catalogue.schema_validator("rules_file").iter_errors(doc))
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
