"""Training the prior on CPU: speed (training and loader rays/s) and quality (held-out PSNR).

    # speed: training rays/s and samples/s at the small preset; the loader's rays/s
    .venv/bin/python benchmarks/prior_train.py speed DATASET [--steps 10] [--threads 2]

    # quality: train `small` for at most --minutes with 5 held-out views per expression, then
    # report PSNR on those views and write a contact sheet (held-out ground truth | prediction)
    .venv/bin/python benchmarks/prior_train.py quality DATASET --run RUN [--minutes 20] [--threads 2]
        [--steps N] [--set key=value ...] [--sheet docs/prior_heldout.png]
    (without --steps the schedule is sized to what a 4-step timing probe says fits in --minutes;
    training stops at --minutes in any case)

    # evaluate an existing run on its held-out views
    .venv/bin/python benchmarks/prior_train.py eval DATASET --run RUN [--sheet F]

The quality dataset: ``synth render --identities 2 --expressions 2 --views 30 --preset preview
--set 'render.resolution=[64,64]' --out DATASET`` (denoised; ``ci`` frames are too noisy).
PSNR is over premultiplied linear colour in [0, 1] (what the L1 loss sees: colour over black);
"foreground" restricts the mean squared error to pixels the ground truth covers (alpha > 0).
Prints markdown tables (docs/prior.md holds them).
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from prior.data import RaySampler  # noqa: E402
from prior.data.stream import load_identity  # noqa: E402
from prior.render_views import png_bytes, render_image  # noqa: E402
from prior.train import checkpoint as ckpt  # noqa: E402
from prior.train.loop import Trainer  # noqa: E402
from prior.train.optim import clip_per_group, learning_rate, set_learning_rate  # noqa: E402
from prior.train.run import prepare  # noqa: E402
from synth.appearance.srgb import srgb8  # noqa: E402
from prior.train.setup import build_model  # noqa: E402

HOLDOUT = 5


def speed(args) -> None:
    torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        s = prepare(args.dataset, Path(tmp) / "run", preset="small", sets=[*args.set, "train.preview_every=0"])
        tr = Trainer(s, torch.device("cpu"), tty=False, tensorboard=False)
        rays = s.cfg.rays_per_step
        t0 = time.perf_counter()
        n_load = 0
        while time.perf_counter() - t0 < 3.0:
            tr.sampler.batch(n_load)
            n_load += 1
        load_rate = n_load * rays / (time.perf_counter() - t0)
        # the loader at the paper's batch shape (256 x 8 x 64; identities repeat on a small dataset)
        paper = RaySampler(tr.loader, seed=0, identities=256, views=8, pixels=64)
        t0 = time.perf_counter()
        for k in range(3):
            paper.batch(k)
        paper_s = (time.perf_counter() - t0) / 3
        t = s.cfg.train
        for warm in range(2):
            tr.step(warm)
        t0 = time.perf_counter()
        for step in range(2, 2 + args.steps):
            set_learning_rate(tr.opt, learning_rate(step, t))
            tr.step(step)
            clip_per_group(tr.opt, t.grad_clip)
            tr.opt.step()
            tr.opt.zero_grad(set_to_none=True)
        dt = (time.perf_counter() - t0) / args.steps
    samples = sum(s.cfg.sampling.samples_per_level)
    print(f"| preset | threads | rays/step | s/step | training rays/s | samples/s | loader rays/s | loader / training |")
    print("|---|---|---|---|---|---|---|---|")
    print(f"| small | {args.threads} | {rays} | {dt:.3f} | {rays / dt:,.0f} | {rays * samples / dt:,.0f} | "
          f"{load_rate:,.0f} | {load_rate / (rays / dt):,.0f}x |")
    print(f"\nloader at the paper batch (256 x 8 x 64 = 131,072 rays): {paper_s:.3f} s/batch, "
          f"{131072 / paper_s:,.0f} rays/s")


def _psnr(mse: float) -> float:
    return -10 * math.log10(max(mse, 1e-12))


def evaluate(run: Path, dataset: Path, sheet: Path | None, threads: int) -> dict:
    """PSNR of every held-out view of the run's newest checkpoint (its own hold-out setting)."""
    torch.set_num_threads(threads)
    ck = ckpt.load(ckpt.latest(run))
    s = prepare(dataset, run, sets=[], resume=True)
    tb = s.table
    model = build_model(ck.config, tb.layout.size, len(tb.info.identity_index))
    model.load_state_dict(ck.model_state)
    model.eval()
    H, W = tb.size
    rows, fg_mse, all_mse, srgb_mse = [], [], [], []
    held = [(load_identity(tb, m, holdout_views=ck.config.data.holdout_views), m) for m in tb.available.tolist()]
    held = [(d, m, n) for d, m in held for n in np.nonzero(~d.train)[0].tolist()]
    for d, m, n in held:
        img = render_image(model, d.K[n], d.c2w[n], W, H, d.codes[n], m, tb.info.centre[m],
                           float(tb.info.radius[m]), chunk=ck.config.train.render_chunk)
        gt = d.rgba[n].astype(np.float32)
        pred, ref = np.clip(img["rgb"], 0, 1), np.clip(gt[..., :3], 0, 1)
        fg = gt[..., 3] > 0
        err = (pred - ref) ** 2
        fg_mse.append(float(err[fg].mean()))
        all_mse.append(float(err.mean()))
        srgb_mse.append(float(((srgb8(pred) / 255.0 - srgb8(ref) / 255.0) ** 2)[fg].mean()))
        rows.append((srgb8(ref), srgb8(pred)))
    res = {"step": ck.step, "views": len(held), "fg_psnr_mean": float(np.mean([_psnr(x) for x in fg_mse])),
           "fg_psnr_pooled": _psnr(float(np.mean(fg_mse))), "psnr_mean": float(np.mean([_psnr(x) for x in all_mse])),
           "fg_psnr_srgb_mean": float(np.mean([_psnr(x) for x in srgb_mse]))}
    if sheet is not None and rows:
        _sheet(rows, sheet, cols=HOLDOUT)
    return res


def _sheet(pairs, out: Path, cols: int, scale: int = 2) -> None:
    """Ground truth | prediction pairs in a grid, ``cols`` pairs per row, upscaled ``scale`` x."""
    h, w = pairs[0][0].shape[:2]
    gap = 4
    n_rows = -(-len(pairs) // cols)
    tile_w = 2 * w * scale + gap
    canvas = np.full((n_rows * (h * scale + gap) + gap, cols * (tile_w + gap) + gap, 3), 32, np.uint8)
    for k, (gt, pred) in enumerate(pairs):
        r, c = divmod(k, cols)
        y, x = gap + r * (h * scale + gap), gap + c * (tile_w + gap)
        pair = np.concatenate([gt, pred], axis=1).repeat(scale, 0).repeat(scale, 1)
        canvas[y:y + h * scale, x:x + 2 * w * scale] = pair
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(png_bytes(canvas))


def _probe_steps(args, sets) -> int:
    """How many steps fit in ``--minutes``: 4 timed steps (after one warm-up) of a throwaway run."""
    with tempfile.TemporaryDirectory() as tmp:
        s = prepare(args.dataset, Path(tmp) / "run", preset="small", sets=[*sets, "train.preview_every=0"])
        tr = Trainer(s, torch.device("cpu"), tty=False, tensorboard=False)
        tr.step(0)
        t0 = time.perf_counter()
        for k in range(1, 5):
            tr.step(k)
            tr.opt.step()
            tr.opt.zero_grad(set_to_none=True)
        per_step = (time.perf_counter() - t0) / 4
    return max(10, int(args.minutes * 60 / per_step))


def quality(args) -> None:
    torch.set_num_threads(args.threads)
    if args.run.exists():
        shutil.rmtree(args.run)
    sets = [f"data.holdout_views={HOLDOUT}", *args.set]
    steps = args.steps if args.steps is not None else _probe_steps(args, sets)
    s = prepare(args.dataset, args.run, preset="small", steps=steps, sets=sets)
    tr = Trainer(s, torch.device("cpu"), tty=False, tensorboard=True)
    t0 = time.perf_counter()
    tr.run(deadline=t0 + args.minutes * 60)
    wall = time.perf_counter() - t0
    res = evaluate(args.run, args.dataset, args.sheet, args.threads)
    print(f"trained {res['step']} of {s.cfg.train.steps} steps in {wall / 60:.1f} min on {args.threads} threads "
          f"({s.cfg.rays_per_step} rays/step)")
    _table(res)


def _table(res: dict) -> None:
    print("| steps | held-out views | foreground PSNR (mean) | foreground PSNR (pooled) | image PSNR (mean) | "
          "foreground PSNR, sRGB (mean) |")
    print("|---|---|---|---|---|---|")
    print(f"| {res['step']} | {res['views']} | {res['fg_psnr_mean']:.2f} dB | {res['fg_psnr_pooled']:.2f} dB | "
          f"{res['psnr_mean']:.2f} dB | {res['fg_psnr_srgb_mean']:.2f} dB |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name in ("speed", "quality", "eval"):
        p = sub.add_parser(name)
        p.add_argument("dataset", type=Path)
        p.add_argument("--threads", type=int, default=2)
        p.add_argument("--set", action="append", default=[])
        if name == "speed":
            p.add_argument("--steps", type=int, default=10)
        else:
            p.add_argument("--run", type=Path, required=True)
            p.add_argument("--sheet", type=Path, default=None)
        if name == "quality":
            p.add_argument("--minutes", type=float, default=20.0)
            p.add_argument("--steps", type=int, default=None,
                           help="train.steps, the schedule's length (default: as many as a timing probe says fit)")
    args = ap.parse_args()
    if args.cmd == "speed":
        speed(args)
    elif args.cmd == "quality":
        quality(args)
    else:
        _table(evaluate(args.run, args.dataset, args.sheet, args.threads))


if __name__ == "__main__":
    main()
