"""``synth prior``: train the conditional NeRF face prior, render novel views, inspect a run.

    synth prior prepare DATASET... [--out DIR]
    synth prior train DATASET... --out RUN [--preset small|paper] [--config F] [--set key=value]
                              [--steps N] [--resume] [--device cpu|cuda]
    synth prior render RUN --identity I --expression E [--orbit N] [--size S] -o DIR
    synth prior info RUN
    synth prior fit IMAGES... --prior RUN --out FIT [--landmarks auto|json|mediapipe] [--steps N]
                    [--preset small|paper] [--config F] [--set key=value] [--no-pretraining] [--model PATH]
    synth prior render FIT [--orbit N] [--size S] [--frame head|input] [--span DEG] [--cameras cameras.json] -o DIR
    synth prior eval FIT --gt DATASET [--views 3,4,5] [--json] [--save DIR]

Bad input gets one line ``synth: error: ...`` and exit code 2, with nothing written; Ctrl-C
during training writes a checkpoint and exits with 130 (``--resume`` continues exactly).
DATASET is the --out directory of ``synth render`` (its committed shards, listed again as the
farm commits more), or tar shards / shard directories, listed or as a brace pattern
(``DIR/shards/shard_{000000..000149}.tar``).
Multi-GPU / multi-node: ``torchrun --nproc-per-node G -m prior.cli train ...``.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Optional

import typer

from synth.cli.params import Device, Overrides, PriorPreset
from synth.errors import SynthError

app = typer.Typer(name="prior", help="Train the conditional NeRF face prior and render from it.",
                  no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False)


def _need_torch() -> None:
    """Stop with one line (exit 2) before anything is read or written when the prior extra is
    missing."""
    from synth.extras import require

    require("prior", ("torch", "safetensors"), "synth prior")


_DATASET_HELP = ("Dataset directory (the --out of synth render), or tar shards / shard directories (paths or a "
                 "brace pattern such as DIR/shards/shard_{000000..000149}.tar).")


@app.command("prepare")
def prepare_cmd(
    dataset: list[str] = typer.Argument(..., help=_DATASET_HELP),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Where the records go (default DATASET/.prior/"
                                                                    "prepare)."),
    workers: int = typer.Option(0, "--workers", "-j", help="Processes reading shards (0: one per CPU core)."),
) -> None:
    """The prepare pass over the committed shards (train runs it too): identity table, codes,
    bounds; only shards without a record are read."""
    import time

    from prior.data.prepare import build_table, prepare
    from prior.data.sources import open_source
    from prior.train.run import warn_line

    src = open_source(dataset)
    t0 = time.perf_counter()
    res = prepare(src, out or src.default_prepare_dir(), warn=warn_line, workers=workers or os.cpu_count() or 1)
    tb = build_table(res, joints=(), margin=0.0, planned=src.planned_identities,
                     where=src.describe())
    print(f"prepared {len(res.records)} shards ({res.written} read now, {res.reused} unchanged, "
          f"{len(res.skipped)} skipped as damaged): {int((tb.frames > 0).sum())} of {len(tb.frames)} identities, "
          f"{int(tb.frames.sum())} frames, {tb.size[1]}x{tb.size[0]}, head model "
          f"{tb.head_model.get('name')!r}; {time.perf_counter() - t0:.1f} s")


@app.command("train")
def train_cmd(
    dataset: list[str] = typer.Argument(..., help=_DATASET_HELP),
    out: Path = typer.Option(..., "--out", "-o", help="Run directory (created; with --resume: continued)."),
    preset: PriorPreset = None,
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="TOML file with model, sampling, data "
                                                                         "and train sections."),
    set_: Overrides = [],
    steps: Optional[int] = typer.Option(None, "--steps", help="Total training steps (train.steps)."),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in --out from its newest checkpoint."),
    device: Device = "cpu",
) -> None:
    """Train the prior on a rendered dataset."""
    _need_torch()
    from prior.train.loop import Trainer
    from prior.train.run import prepare
    from prior.train.setup import device_for, init_distributed, resolve_device, shutdown_distributed

    dev = resolve_device(device)
    dist = init_distributed(dev)
    finished = False
    try:
        setup = prepare(dataset, out, preset=preset, config_path=config, sets=set_, steps=steps, resume=resume,
                        dist=dist)
        trainer = Trainer(setup, device_for(dist, dev), dist)
        rc = trainer.run()
        finished = True
    finally:
        trainer = None  # the DDP model lets go of the process group before it is destroyed
        shutdown_distributed(wait_for_peers=finished)
    if rc:
        raise typer.Exit(rc)


@app.command("render")
def render_cmd(
    run: Path = typer.Argument(..., help="Run directory of synth prior train, or fit directory of synth prior fit."),
    identity: Optional[int] = typer.Option(None, "--identity", "-i", help="Run: dataset identity index (a trained "
                                                                           "identity)."),
    expression: Optional[int] = typer.Option(None, "--expression", "-e", help="Run: expression index of that "
                                                                               "identity."),
    orbit: int = typer.Option(8, "--orbit", help="Number of views (a run: on a circle about the vertical axis; "
                                                 "a fit: see --frame)."),
    frame: str = typer.Option("head", "--frame", help="Fit: 'head' (views centred on the fitted head, 0.5 m across "
                                                      "at the face, over --span degrees about the frontal input) or "
                                                      "'input' (the photo's own framing, orbiting the full circle)."),
    span: Optional[float] = typer.Option(None, "--span", help="Fit, head framing: degrees of azimuth the views "
                                                              "cover (default 80: -40 .. +40)."),
    size: Optional[int] = typer.Option(None, "--size", help="Image size in pixels (square; default: the dataset's "
                                                            "or the fit's inputs')."),
    cameras: Optional[Path] = typer.Option(None, "--cameras", help="Fit: render the views of this cameras.json "
                                                                   "(as render writes it) instead of an orbit."),
    out: Path = typer.Option(..., "-o", "--out", help="Output directory."),
    device: Device = "cpu",
) -> None:
    """Novel views of a training identity or of a fitted face: colour, opacity and normals PNGs, depth EXR."""
    _need_torch()
    from prior.fit.fitdir import FIT_FILE
    from prior.train.setup import resolve_device

    dev = str(resolve_device(device))
    if (run / FIT_FILE).is_file():
        if identity is not None or expression is not None:
            raise SynthError("--identity and --expression select a training identity of a prior run, not of a fit",
                             str(run), "drop them (a fit renders its own face)")
        from prior.fit.novel import render_fit

        files = render_fit(run, out, orbit_views=orbit, size=size, cameras=cameras, device=dev, framing=frame,
                           span_deg=span)
    else:
        if identity is None or expression is None:
            raise SynthError("rendering a prior run needs --identity and --expression", str(run),
                             "pass both (synth prior info RUN lists them), or pass a fit directory")
        if cameras is not None or frame != "head" or span is not None:
            raise SynthError("--cameras, --frame and --span render a fit, not a prior run", str(run),
                             "pass a fit directory")
        from prior.render_views import render_run

        files = render_run(run, identity, expression, out, orbit_views=orbit, size=size, device=dev)
    print(f"wrote {len(files)} files to {out}")


@app.command("fit")
def fit_cmd(
    images: list[Path] = typer.Argument(..., help="1-3 images of one face: photos (PNG/JPEG) or synth frame EXRs "
                                                  "with their JSON beside them; one size."),
    prior: Path = typer.Option(..., "--prior", help="Run directory of synth prior train (its newest checkpoint)."),
    out: Path = typer.Option(..., "--out", "-o", help="Fit directory (new)."),
    landmarks: str = typer.Option("auto", "--landmarks", help="json (synth frames), mediapipe (photos; the fit "
                                                              "extra), dlib (photos, iBUG's 68 points; the judge "
                                                              "extra) or auto (json for frames, else mediapipe)."),
    steps: Optional[int] = typer.Option(None, "--steps", help="Fine-tuning steps (finetune.steps)."),
    preset: PriorPreset = None,
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="TOML file with landmarks, inversion, "
                                                                         "finetune and fit sections."),
    set_: Overrides = [],
    no_pretraining: bool = typer.Option(False, "--no-pretraining", help="Start from a randomly initialised field "
                                                                        "of the prior's configuration (baseline)."),
    model: Optional[Path] = typer.Option(None, "--model", "-m", help="Head model .npz the prior's dataset was "
                                                                     "rendered with (default: embedded)."),
    device: Device = "cpu",
) -> None:
    """Reconstruct a face from a few images: landmarks -> head model and cameras -> inversion -> fine-tuning."""
    _need_torch()
    from prior.fit.pipeline import fit_face
    from prior.train.setup import resolve_device

    fit_face(images, prior, out, landmarks=landmarks, preset=preset, config_path=config, sets=set_, steps=steps,
             pretrained=not no_pretraining, model_path=model, device=str(resolve_device(device)))


def _view_list(text: Optional[str]) -> Optional[list[int]]:
    if text is None:
        return None
    try:
        views = [int(x) for x in text.replace(" ", "").split(",") if x]
    except ValueError:
        raise SynthError(f"bad view list {text!r}", "--views", "write view indices separated by commas: 3,4,5") \
            from None
    if not views:
        raise SynthError("empty view list", "--views", "write view indices separated by commas: 3,4,5")
    return views


@app.command("eval")
def eval_cmd(
    fit: Path = typer.Argument(..., help="Fit directory of synth prior fit (inputs: synth frames)."),
    gt: Path = typer.Option(..., "--gt", help="The synth dataset the inputs came from (ground truth)."),
    views: Optional[str] = typer.Option(None, "--views", help="View indices to evaluate, e.g. 3,4,5 (default: "
                                                              "every other view in the frontal hemisphere)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a Markdown table."),
    save: Optional[Path] = typer.Option(None, "--save", help="Also write the rendered and ground-truth views here."),
    device: Device = "cpu",
) -> None:
    """PSNR, SSIM and LPIPS of held-out views of a fitted synth identity, on the foreground."""
    _need_torch()
    from prior.evaluate import evaluate_fit, markdown
    from prior.train.setup import resolve_device

    res = evaluate_fit(fit, gt, views=_view_list(views), device=str(resolve_device(device)), save=save)
    print(json.dumps(res) if as_json else markdown(res))


@app.command("info")
def info_cmd(run: Path = typer.Argument(..., help="Run directory of synth prior train."),
             as_json: bool = typer.Option(False, "--json", help="Print one JSON object.")) -> None:
    """Config, steps, identities and the last losses of a run."""
    _need_torch()
    from prior.train.checkpoint import latest, list_checkpoints, load
    from prior.train.logs import read_metrics

    path = latest(run)
    if path is None:
        raise SynthError("no checkpoint in this run", str(run), "pass the --out directory of synth prior train")
    ck = load(path)
    metrics = read_metrics(run)
    t = ck.config.train
    info = {"run": str(run), "checkpoint": str(path), "step": ck.step, "steps": t.steps,
            "checkpoints": [s for s, _ in list_checkpoints(run)], "dataset": ck.dataset,
            "identities": ck.identities.identity_index.tolist(), "codes": ck.layout.to_dict(),
            "rays_per_step": ck.config.rays_per_step, "last_losses": ck.losses,
            "last_logged": metrics[-1] if metrics else None, "config": ck.config.to_dict()}
    if as_json:
        print(json.dumps(info))
        return
    m = ck.config.model
    ident = info["identities"]
    print(f"run         {run}\ncheckpoint  {path.name} (step {ck.step} of {t.steps}; kept: {info['checkpoints']})")
    print(f"dataset     {ck.dataset}")
    print(f"identities  {len(ident)}: {', '.join(map(str, ident[:10]))}{' ...' if len(ident) > 10 else ''}")
    print(f"codes       beta {ck.layout.identity_size} + expression {ck.layout.expression_size} + joints "
          f"{', '.join(ck.layout.joints)} (3 each) = {ck.layout.size}; latent w {m.latent_dim}")
    print(f"model       proposal {m.proposal_depth}x{m.proposal_width}, nerf {m.nerf_depth}x{m.nerf_width}, "
          f"samples {list(ck.config.sampling.samples_per_level)}")
    print(f"batch       {t.identities_per_batch} x {t.views_per_identity} x {t.pixels_per_view} = "
          f"{ck.config.rays_per_step} rays; background stage until step {t.background_steps}")
    if ck.losses:
        print("losses      " + "  ".join(f"{k} {v:.4g}" for k, v in ck.losses.items() if k != "step")
              + f"  (step {ck.losses.get('step')})")
    if metrics:
        last = metrics[-1]
        print(f"last log    step {last['step']}: loss {last['loss']:.4g}  psnr {last['psnr']:.2f} dB  "
              f"{last['rays_per_s']:.0f} rays/s")


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="prior")


def main() -> int:
    """``python -m prior.cli ...`` (for torchrun): the same commands and error handling as ``synth prior``."""
    from synth.cli.boundary import run

    return run(app, sys.argv[1:], prog_name="synth prior")


if __name__ == "__main__":
    sys.exit(main())
