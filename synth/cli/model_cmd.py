"""``synth model ...``: inspect, sample and import head models."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from synth.errors import SynthError

app = typer.Typer(help="Inspect, sample and import 3D morphable head models.", no_args_is_help=True)
import_app = typer.Typer(help="Import a head model from another layout into synth's format.", no_args_is_help=True)
app.add_typer(import_app, name="import")

ModelOpt = typer.Option(None, "--model", "-m", help="Model file (.npz). Default: the embedded MakeHuman model.")


def model_summary(data, path: Path | None) -> dict:
    from synth.assets.classes import NAMES, unavailable

    return {
        "name": data.name,
        "path": str(path) if path else None,
        "identity_dims": data.identity_dims,
        "expression_dims": data.expression_dims,
        "num_vertices": data.num_vertices,
        "num_triangles": int(data.triangles.shape[0]),
        "num_polygons": int(len(data.poly_offsets) - 1) if data.poly_offsets is not None else None,
        "has_uvs": data.uvs is not None,
        "joints": list(data.joint_names),
        "regions": {k: int(v.size) for k, v in sorted(data.regions.items())},
        "landmarks": {k: int(v[0].size) for k, v in sorted(data.landmarks.items())},
        "prior_components": int(data.prior_weights.shape[0]),
        "expression_names": list(data.expression_names),
        "license": data.license,
        "provenance": data.provenance,
        # per asset class: None if the model carries it, else why not (synth.assets.classes.needs)
        "asset_classes": {c: unavailable(data, c) for c in NAMES},
    }


def _load(model: Optional[Path]):
    from synth.model.default import default_model_path
    from synth.model.format import read_model

    path = Path(model) if model is not None else default_model_path()
    return read_model(path), path


@app.command("info")
def info(model: Optional[Path] = ModelOpt,
         as_json: bool = typer.Option(False, "--json", help="Print one JSON object.")) -> None:
    """Describe a model: dimensions, joints, regions, landmark sets, licence, and which asset
    classes it can carry (or why not)."""
    data, path = _load(model)
    s = model_summary(data, path)
    if as_json:
        typer.echo(json.dumps(s, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"head model: {s['name']}", show_header=False)
    for k in ("path", "identity_dims", "expression_dims", "num_vertices", "num_triangles", "num_polygons",
              "has_uvs", "prior_components"):
        t.add_row(k, str(s[k]))
    t.add_row("joints", ", ".join(s["joints"]))
    t.add_row("landmarks", ", ".join(f"{k} ({v})" for k, v in s["landmarks"].items()))
    t.add_row("regions", ", ".join(f"{k} ({v})" for k, v in s["regions"].items()))
    t.add_row("asset classes", "\n".join(f"{c}: {'available' if why is None else 'unavailable, ' + why}"
                                          for c, why in s["asset_classes"].items()))
    t.add_row("license", s["license"].strip().splitlines()[0] if s["license"].strip() else "")
    Console().print(t)


@app.command("sample")
def sample(n: int = typer.Option(4, "--n", min=1, max=100000, help="Number of meshes."),
           seed: int = typer.Option(0, "--seed", min=0, help="Run seed."),
           out: Path = typer.Option(..., "-o", "--out", help="Output directory (created; must not exist or be empty)."),
           model: Optional[Path] = ModelOpt,
           fmt: str = typer.Option("obj", "--format", help="obj or ply."),
           expressions: bool = typer.Option(True, "--expressions/--neutral", help="Random expressions or neutral."),
           truncation: float = typer.Option(3.0, "--truncation", min=0.5, max=10.0,
                                            help="Mahalanobis radius for identity codes.")) -> None:
    """Write meshes of random identities (and expressions), plus their codes as JSON."""
    import numpy as np

    from synth.model.head import HeadModel
    from synth.model.identity_gmm import GaussianMixture

    if fmt not in ("obj", "ply"):
        raise SynthError(f"unknown mesh format '{fmt}'", "--format", "use obj or ply")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SynthError("output directory exists and is not empty", str(out), "choose a new --out")
    data, path = _load(model)
    hm = HeadModel(data)
    gmm = GaussianMixture.from_model(data)
    from synth.io import atomic_dir, created_dirs, dumps_json
    from synth.model.export import write_mesh

    with created_dirs(out.parent), atomic_dir(out) as tmp:  # replaces an empty ``out`` (checked above)
        records = []
        for i in range(n):
            # one generator per mesh index, so mesh i is the same whatever n is
            rng = np.random.Generator(np.random.Philox(key=[seed, i]))
            beta = gmm.sample(rng, 1, max_mahalanobis=truncation)[0]
            psi = np.zeros(data.expression_dims)
            if expressions:
                k = rng.integers(1, 4)
                idx = rng.choice(data.expression_dims, size=min(k, data.expression_dims), replace=False)
                psi[idx] = rng.uniform(0.2, 0.9, size=idx.size)
            v = hm.vertices(beta, psi)[0]
            name = f"sample_{i:05d}.{fmt}"
            write_mesh(tmp / name, v, data)
            records.append({"file": name, "identity": [round(float(x), 6) for x in beta],
                            "expression": {data.expression_names[j]: round(float(psi[j]), 6)
                                           for j in np.nonzero(psi)[0]}})
        (tmp / "codes.json").write_bytes(dumps_json({"model": data.name, "seed": seed, "meshes": records}))
    typer.echo(f"wrote {n} meshes to {out}")


def _write_imported(data, out: Path) -> None:
    from synth.model.format import write_model

    if out.suffix != ".npz":
        raise SynthError("output must end in .npz", str(out), "e.g. -o model.npz")
    write_model(data, out)
    typer.echo(f"wrote {out} ({data.num_vertices} vertices, {data.identity_dims} identity and "
               f"{data.expression_dims} expression dimensions)")


@import_app.command("ict-facekit")
def import_ict(directory: Path = typer.Argument(..., help="ICT-FaceKit checkout (holding FaceXModel/)."),
               out: Path = typer.Option(..., "-o", "--out", help="Output model file (.npz).")) -> None:
    """Import the ICT-FaceKit face model (MIT licence)."""
    from synth.model.importers.ict_facekit import import_ict_facekit

    _write_imported(import_ict_facekit(directory), out)


@import_app.command("flame")
def import_flame_cmd(model_file: Path = typer.Argument(..., help="Your FLAME 2020/2023 .pkl file."),
                     out: Path = typer.Option(..., "-o", "--out", help="Output model file (.npz)."),
                     landmarks: Optional[Path] = typer.Option(None, "--landmarks",
                                                              help="FLAME landmark_embedding.npy.")) -> None:
    """Import a FLAME model you hold a licence for (loaded without executing pickled code)."""
    from synth.model.importers.flame import import_flame

    _write_imported(import_flame(model_file, landmark_embedding=landmarks), out)


@app.command("path")
def path_cmd() -> None:
    """Print the path of the embedded default model (the file shipped in the package)."""
    from synth.model.default import default_model_path

    typer.echo(str(default_model_path()))
