"""``synth assets list`` and ``synth assets validate``: inspect and check the asset catalogue."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Optional

import typer

assets_app = typer.Typer(help="Inspect and check the asset catalogue (assets_manifest/, docs/assets.md).",
                         no_args_is_help=True)


def _fmt_num(x: Any) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def format_parameter(name: str, spec: dict) -> str:
    """One parameter as a short line: ``length_m [0.003, 0.012] m``, ``colour: black|brown (3/1)``."""
    if "match" in spec:
        s = f"{name} = {spec['match']}"
        if "otherwise" in spec:
            s += " else " + format_parameter("", spec["otherwise"]).strip()
        return s
    if "value" in spec:
        return f"{name} = {json.dumps(spec['value'])}"
    if "probability" in spec:
        return f"{name} p={_fmt_num(spec['probability'])}"
    if "choices" in spec:
        s = f"{name}: " + "|".join(str(c) for c in spec["choices"])
        if "weights" in spec:
            s += " (" + "/".join(_fmt_num(w) for w in spec["weights"]) + ")"
        return s
    lo, hi = spec.get("range", (None, None))
    s = f"{name} [{_fmt_num(lo)}, {_fmt_num(hi)}]"
    if spec.get("integer"):
        s += " int"
    if spec.get("log"):
        s += " log"
    if spec.get("unit"):
        s += f" {spec['unit']}"
    return s


@assets_app.command("list")
def list_cmd(
    cls: Optional[str] = typer.Option(None, "--class", help="Only this asset class."),
    manifest_dir: Optional[Path] = typer.Option(None, "--manifest-dir", "-d",
                                                help="Catalogue folder (default: assets_manifest/, "
                                                     "installed with the package)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
) -> None:
    """List the catalogue's assets: class, id, generator, weight, tags, parameters, licence."""
    from synth.assets.catalogue import load_catalogue
    from synth.assets.classes import NAMES
    from synth.errors import SynthError

    if cls is not None and cls not in NAMES:
        raise SynthError(f"unknown asset class '{cls}'", "--class", f"use one of: {', '.join(NAMES)}")
    cat = load_catalogue(manifest_dir)
    classes = [c for c in NAMES if c in cat.classes and (cls is None or c == cls)]
    if as_json:
        out = {"manifest_dir": cat.path, "catalogue_sha256": cat.digest,
               "presence": {c: cat.classes[c]["presence"] for c in classes},
               "assets": [{**a, **({"pack": cat.packs[f"{c}/{a['id']}"]} if f"{c}/{a['id']}" in cat.packs else {})}
                          for c in classes for a in cat.classes[c]["assets"]]}
        typer.echo(json.dumps(out, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    n = sum(len(cat.classes[c]["assets"]) for c in classes)
    t = Table(title=f"asset catalogue {cat.path} ({n} assets, sha256 {cat.digest[:12]})", show_lines=True)
    for col in ("class", "id", "generator", "weight", "tags", "parameters", "licence"):
        t.add_column(col, overflow="fold")
    for c in classes:
        presence = cat.classes[c]["presence"]
        for a in cat.classes[c]["assets"]:
            gen = a["generator"]
            if f"{c}/{a['id']}" in cat.packs:
                pk = cat.packs[f"{c}/{a['id']}"]
                gen += f"\nobject {pk['object']}, sha256 {pk['sha256'][:12]}"
            params = "\n".join(format_parameter(k, v) for k, v in sorted(a.get("parameters", {}).items()))
            t.add_row(f"{c} (p={_fmt_num(presence)})", a["id"], gen, _fmt_num(a.get("weight", 1.0)),
                      ", ".join(a.get("tags", [])), params, a["licence"])
    Console(width=200).print(t)


@assets_app.command("validate")
def validate_cmd(
    manifest_dir: Optional[Path] = typer.Option(None, "--manifest-dir", "-d",
                                                help="Catalogue folder (default: assets_manifest/, "
                                                     "installed with the package)."),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON."),
) -> None:
    """Check every entry: schema, unique ids, all classes present, rule tags, ranges, choices,
    generators (rig modules present), external packs (file, sha256, confinement, licence).
    Exit 0 when clean, 1 with one line per defect (what, where, what to do)."""
    from synth.assets.validate import report_json, validate_manifest
    from synth.errors import Incomplete, SynthError

    if manifest_dir is not None and not manifest_dir.is_dir():
        raise SynthError("asset manifest folder not found", str(manifest_dir), "pass an existing --manifest-dir")
    rep = validate_manifest(manifest_dir)
    if as_json:
        typer.echo(report_json(rep))
    else:
        for d in rep.defects:
            typer.echo(d.line())
        typer.echo(f"{rep.manifest_dir}: {rep.files} files, {rep.assets} assets ({rep.packs} external packs): "
                   + ("OK" if rep.ok else f"{len(rep.defects)} defect{'s' if len(rep.defects) != 1 else ''}"),
                   err=not rep.ok)
    if not rep.ok:
        raise Incomplete(f"{len(rep.defects)} defect(s) in the asset catalogue", str(rep.manifest_dir),
                         "fix each defect listed above, then validate again")


def register(app: typer.Typer) -> None:
    app.add_typer(assets_app, name="assets")
