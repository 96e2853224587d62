"""The paper's central claim at small scale: a prior pre-trained on more synthetic identities makes
few-shot reconstruction of an unseen face better (Cafca Table 2 a.i-a.iv), and more input views do
not make it worse (Table S1).

    .venv/bin/python benchmarks/prior_claim.py all --work W [--profile cpu|tiny] [--scale S] [--device cuda]
    .venv/bin/python benchmarks/prior_claim.py render|train|fit|report --work W [...]   # one stage
    .venv/bin/python benchmarks/prior_claim.py bf16 --work W       # bf16 vs float32 training, same steps

Stages (each resumable: finished outputs are kept and skipped):

1. render: one training dataset of the largest rung's identities (``synth render --preset preview``
   at the prior's resolution; the smaller rungs are its first shards, so every frame is rendered
   once), and a test dataset of held-out identities (never trained on; identity indices
   after the training ones, random non-neutral expressions) at ``test_res``, from a hand-made plan:
   ``synth plan``'s identities, expressions, assets and lighting, with every expression's cameras
   replaced by fixed ones: views 0-2 the inputs (frontal, +45 and -45 degrees azimuth), views 3-8
   held-out views in the frontal hemisphere; rendered with ``synth render --plan``.
2. train: one prior per rung (same steps and schedule for all; ``train.bf16=auto``: bf16 autocast where the
   device computes bf16 natively, float32 elsewhere; the run's log says which).
3. fit: ``synth prior fit``'s pipeline on every test scene with 3 views for every rung and with no
   pre-training, and with 1 and 2 views for the largest rung; each fit evaluated on views 3-8
   (``synth prior eval``'s protocol).
4. report: the tables (markdown), the acceptance checks and a figure like the paper's Fig. 5.

``--scale S`` multiplies training steps, fitting steps and rays per step (a GPU with ``--device cuda``).
Times and the machine's load average go to ``W/times.json``, results to ``W/results.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from synth.conventions import invert_rigid, orbit_camera_to_world  # noqa: E402
from synth.io import atomic_write_json  # noqa: E402

#: views of every test expression: (azimuth, elevation) degrees; 0-2 inputs, 3-8 held out (frontal hemisphere)
TEST_VIEWS = [(0.0, 0.0), (45.0, 0.0), (-45.0, 0.0), (-70.0, 10.0), (-25.0, -10.0), (20.0, 15.0), (30.0, -5.0),
              (65.0, 5.0), (0.0, 25.0)]
HELD_OUT = list(range(3, len(TEST_VIEWS)))
INPUT_SETS = {1: [0], 2: [0, 1], 3: [0, 1, 2]}
TEST_RADIUS_M = 1.0

PROFILES = {
    # the run reported in docs/prior.md, sized for about 75 minutes of training and fitting on the shared
    # 2-core machine (one torch thread: under other jobs' load two threads ran 40x slower)
    "cpu": dict(rungs=[1, 4, 12], expressions=2, views=12, res=32, test_ids=4, test_expressions=1, test_res=64,
                train_steps=1000, train_sets=["train.identities_per_batch=2", "train.views_per_identity=4",
                                              "train.pixels_per_view=32", "train.foreground_fraction=0.5",
                                              "train.warmup_steps=30", "train.background_steps=100",
                                              "train.log_every=50", "train.checkpoint_every=250",
                                              "train.preview_every=0", "train.bf16=auto",
                                              "sampling.proposal_samples=[16,16]", "sampling.nerf_samples=24"],
                fit_sets=["inversion.steps=30", "inversion.patches=1", "inversion.patch_size=16",
                          "finetune.steps=300", "finetune.rays_per_step=256", "finetune.warmup_steps=10",
                          "finetune.normal_weight=0", "finetune.bf16=auto", "landmarks.sigma_px=0.3"]),
    # a few minutes end to end: checks the script, proves nothing
    "tiny": dict(rungs=[1, 2], expressions=1, views=6, res=32, test_ids=1, test_expressions=1, test_res=64,
                 train_steps=20, train_sets=["train.identities_per_batch=2", "train.views_per_identity=2",
                                             "train.pixels_per_view=64", "train.warmup_steps=2",
                                             "train.background_steps=4", "train.log_every=5",
                                             "train.checkpoint_every=10", "train.preview_every=0", "train.bf16=auto"],
                 fit_sets=["inversion.steps=4", "inversion.patches=1", "inversion.patch_size=16",
                           "finetune.steps=6", "finetune.rays_per_step=256", "finetune.warmup_steps=2"]),
}
#: fitting overrides that --scale multiplies
SCALED = ("inversion.steps", "finetune.steps", "finetune.rays_per_step")


def scaled_sets(sets: list[str], scale: float) -> list[str]:
    """``key=value`` overrides with step and ray counts multiplied by ``scale``."""
    out = []
    for s in sets:
        k, v = s.split("=", 1)
        out.append(f"{k}={max(1, round(int(v) * scale))}" if k in SCALED and scale != 1 else s)
    return out


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


class Times:
    """Wall times and load averages per stage, kept in W/times.json across invocations."""

    def __init__(self, work: Path):
        self.path = work / "times.json"
        self.data = json.loads(self.path.read_text()) if self.path.is_file() else {}

    def record(self, key: str, t0: float, **extra) -> None:
        entry = {"seconds": round(time.perf_counter() - t0, 1), "load_end": list(os.getloadavg()), **extra}
        disk = json.loads(self.path.read_text()) if self.path.is_file() else {}  # other processes' entries
        self.data = {**self.data, **disk, key: entry}
        atomic_write_json(self.path, self.data)


def synth(*args) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "synth.cli.main", *map(str, args)], env=env, text=True,
                       capture_output=True)
    if r.returncode != 0:
        raise SystemExit(f"synth {' '.join(map(str, args[:3]))} failed ({r.returncode}): {r.stderr.strip()[-400:]}")


# --------------------------------------------------------------------------- render


def fixed_camera_plan(src: Path, dst: Path) -> None:
    """``src`` (a synth plan) with every expression's cameras replaced by TEST_VIEWS around its
    look-at target at TEST_RADIUS_M (same K, resolution and everything else)."""
    from synth.plan import io
    from synth.plan.planner import _rn

    plan = io.load_plan(src)
    if len(TEST_VIEWS) != plan.config["dataset"]["views_per_expression"]:
        raise SystemExit("the source plan must have one view per TEST_VIEWS entry")
    specs = []
    for sid in plan.shard_ids():
        spec = plan.shard(sid)
        for ident in spec["identities"]:
            tgt = np.asarray(ident["target"], np.float64)
            for ex in ident["expressions"]:
                for fr, (az, el) in zip(ex["frames"], TEST_VIEWS):
                    c2w = orbit_camera_to_world(az, el, TEST_RADIUS_M, tgt)
                    fr["camera"].update(camera_to_world=_rn(c2w), world_to_camera=_rn(invert_rigid(c2w)),
                                        azimuth_deg=az, elevation_deg=el, radius_m=TEST_RADIUS_M)
        specs.append((sid, spec))
    header = {k: v for k, v in plan.header.items() if k not in ("shards", "plan_hash")}
    summary = json.loads((src / io.SUMMARY_FILE).read_text())
    summary["note"] = "cameras replaced by benchmarks/prior_claim.py (TEST_VIEWS)"
    io.write_plan(dst, header, lambda tmp: (io.write_shards(tmp, specs), summary))


def render(work: Path, p: dict, times: Times) -> None:
    n_train = max(p["rungs"])
    res = f"render.resolution=[{p['res']},{p['res']}]"
    if "render_train" not in times.data:
        t0 = time.perf_counter()
        log(f"render: training set, {n_train} identities x {p['expressions']} x {p['views']} at {p['res']}^2")
        synth("render", "-n", n_train, "-e", p["expressions"], "-v", p["views"], "--preset", "preview",
              "--set", res, "--seed", 1, "--out", work / "ds_train", "-q")
        times.record("render_train", t0, frames=n_train * p["expressions"] * p["views"])
    if "render_test" not in times.data:
        t0 = time.perf_counter()
        tres = f"render.resolution=[{p['test_res']},{p['test_res']}]"
        log(f"render: test set, {p['test_ids']} held-out identities x {p['test_expressions']} x {len(TEST_VIEWS)} "
            f"at {p['test_res']}^2")
        if not (work / "plan_test").is_dir():
            synth("plan", "-n", p["test_ids"], "--start", n_train, "--seed", 1, "--out", work / "plan_test0",
                  "--set", "render.preset=\"preview\"", "--set", tres, "--set", "expression.neutral_weight=0",
                  "--set", f"dataset.expressions_per_identity={p['test_expressions']}",
                  "--set", f"dataset.views_per_expression={len(TEST_VIEWS)}", "--set", "camera.min_separation_deg=0")
            fixed_camera_plan(work / "plan_test0", work / "plan_test")
        synth("render", "--plan", work / "plan_test", "--out", work / "ds_test", "-q")
        times.record("render_test", t0, frames=p["test_ids"] * p["test_expressions"] * len(TEST_VIEWS))


def subset(work: Path, n: int) -> list[Path]:
    """The first ``n`` training identities: their shard directories, a training source as a list of
    shard paths (one identity per shard)."""
    return [work / "ds_train" / "shards" / f"shard_{k:06d}" for k in range(n)]


# --------------------------------------------------------------------------- train


def train(work: Path, p: dict, scale: float, device: str, times: Times, *, rungs=None, extra=(), tag="") -> None:
    import torch

    from prior.train.checkpoint import latest, load
    from prior.train.loop import Trainer
    from prior.train.run import prepare

    steps = max(1, round(p["train_steps"] * scale))
    for n in rungs or p["rungs"]:
        run = work / "runs" / f"ids{n:03d}{tag}"
        key = f"train_ids{n:03d}{tag}"
        if latest(run) is not None and load(latest(run)).step >= steps:
            continue
        t0 = time.perf_counter()
        log(f"train: prior on {n} identities, {steps} steps{(' ' + tag) if tag else ''}")
        resume = latest(run) is not None
        s = prepare(subset(work, n), run, preset=None if resume else "small",
                    sets=[] if resume else [*p["train_sets"], *extra], steps=steps, resume=resume)
        tr = Trainer(s, torch.device(device), tty=False, tensorboard=False)
        tr.run()
        m = tr.losses
        times.record(key, t0, steps=steps, rays_per_step=s.cfg.rays_per_step, psnr=m.get("psnr"),
                     acc_fg=m.get("acc_fg"))


# --------------------------------------------------------------------------- fit + eval


def scenes(work: Path) -> list[tuple[int, int]]:
    from synth.dataset.layout import parse_frame_key
    from synth.dataset.reader import list_frames

    return sorted({parse_frame_key(r.key)[:2] for r in list_frames(work / "ds_test")})


def fit_rows(p: dict) -> list[tuple[str, int | None, int]]:
    """(row name, rung, number of input views); a name starting with "none" is the fit from a randomly
    initialised field (the rung's run gives only its configuration)."""
    big = max(p["rungs"])
    rows = [("none", big, 3)] + [(f"ids{n}", n, 3) for n in p["rungs"]]
    return rows + [(f"ids{big}_views{v}", big, v) for v in (1, 2)]


def fit(work: Path, p: dict, scale: float, device: str, times: Times, rows=None, tag="", only=None) -> None:
    """Every row on every test scene (``only``: indices into the scenes, for parallel processes)."""
    from prior.evaluate import evaluate_fit
    from prior.fit.pipeline import fit_face

    sets = scaled_sets(p["fit_sets"], scale)
    t_stage = time.perf_counter()
    # scene by scene, every row for a scene before the next: a run cut short still compares every row
    for k, (ident, expr) in enumerate(scenes(work)):
        if only is not None and k not in only:
            continue
        for name, rung, nviews in rows or fit_rows(p):
            out = work / "fits" / f"{name}{tag}" / f"id{ident:06d}_ex{expr:02d}"
            if (out / "eval.json").is_file():
                continue
            frames = [next((work / "ds_test" / "shards").glob(f"*/id{ident:06d}_ex{expr:02d}_v{v:02d}.exr"))
                      for v in INPUT_SETS[nviews]]
            t0 = time.perf_counter()
            log(f"fit: {name}{tag} on identity {ident} expression {expr} ({nviews} views)")
            if not (out / "fit").is_dir():
                fit_face(frames, work / "runs" / f"ids{rung:03d}{tag}", out / "fit", landmarks="json", sets=sets,
                         pretrained=not name.startswith("none"), device=device, log=lambda m: None)
            t1 = time.perf_counter()
            res = evaluate_fit(out / "fit", work / "ds_test", views=HELD_OUT, device=device,
                               save=out / "views" if nviews == 3 else None)
            res["times"] = {**json.loads((out / "fit" / "report.json").read_text())["times"],
                            "fit_total_s": t1 - t0, "eval_s": time.perf_counter() - t1}
            atomic_write_json(out / "eval.json", res)
            m = res["mean"]
            log(f"  PSNR {m['psnr']:.2f} dB  SSIM {m['ssim']:.4f}  LPIPS {m['lpips']:.4f}")
    part = "" if only is None else "_scenes" + "_".join(map(str, only))
    times.record(f"fit{tag}{part}", t_stage, note="per-fit times are in fits/*/*/eval.json")


# --------------------------------------------------------------------------- report


def collect(work: Path, p: dict, tag: str = "") -> dict:
    out = {}
    for name, rung, nviews in fit_rows(p):
        evs = [json.loads(f.read_text()) for f in sorted((work / "fits" / f"{name}{tag}").glob("*/eval.json"))]
        if not evs:
            continue
        m = {k: float(np.mean([e["mean"][k] for e in evs])) for k in ("psnr", "ssim", "lpips")}
        t = {k: float(np.mean([e["times"][k] for e in evs])) for k in ("landmarks_s", "inversion_s", "finetune_s",
                                                                        "eval_s")}
        out[name] = {"rung": rung, "views": nviews, "scenes": len(evs), **m, "times": t,
                     "per_scene": {f"id{e['identity']}_ex{e['expression']}": e["mean"]["psnr"] for e in evs}}
    return out


def report(work: Path, p: dict, times: Times, figure: Path | None) -> dict:
    res = collect(work, p)
    big = max(p["rungs"])
    frames = {n: n * p["expressions"] * p["views"] for n in p["rungs"]}
    lines = ["| pre-training | training frames | input views | PSNR dB | SSIM | LPIPS |", "|---|---|---|---|---|---|"]
    for name, rung, nviews in fit_rows(p):
        if name not in res:
            continue
        r = res[name]
        label = "none (random init)" if name == "none" else f"{rung} identit{'y' if rung == 1 else 'ies'}"
        lines.append(f"| {label} | {0 if name == 'none' else frames[rung]} | {nviews} | {r['psnr']:.2f} | "
                     f"{r['ssim']:.4f} | {r['lpips']:.4f} |")
    checks = {}
    if {"none", f"ids{big}", "ids1"} <= set(res):
        checks["most_vs_none_db"] = res[f"ids{big}"]["psnr"] - res["none"]["psnr"]
        checks["most_beats_none_by_5db"] = checks["most_vs_none_db"] >= 5.0
        checks["most_beats_one"] = res[f"ids{big}"]["psnr"] > res["ids1"]["psnr"]
    views = [res.get(n, {}).get("psnr") for n in (f"ids{big}_views1", f"ids{big}_views2", f"ids{big}")]
    if None not in views:
        checks["views_1_2_3_psnr"] = views
        checks["more_views_not_worse"] = views[0] <= views[1] <= views[2]
    summary = {"profile": p, "rows": res, "checks": checks, "times": times.data}
    atomic_write_json(work / "results.json", summary)
    print("\n".join(lines))
    print("\nchecks:", json.dumps(checks))
    if figure is not None and {"none", "ids1", f"ids{big}"} <= set(res):
        make_figure(work, p, figure)
    return summary


def make_figure(work: Path, p: dict, path: Path, scenes_shown: int = 2) -> None:
    """Per test scene: the 3 inputs | for two held-out views: prediction of the largest prior,
    ground truth, depth, normals, and the predictions of the 1-identity prior and no pre-training."""
    from PIL import Image, ImageDraw

    from synth.appearance.srgb import linear_to_srgb
    from synth.dataset.reader import read_frame

    big, S = max(p["rungs"]), p["test_res"]
    rows = []
    for ident, expr in scenes(work)[:scenes_shown]:
        key = f"id{ident:06d}_ex{expr:02d}"
        tiles = []
        for v in INPUT_SETS[3]:
            f = read_frame(next((work / "ds_test" / "shards").glob(f"*/{key}_v{v:02d}.json")))
            tiles.append((linear_to_srgb(f.rgba[..., :3]) * 255 + 0.5).astype(np.uint8))
        for v in (HELD_OUT[1], HELD_OUT[4]):
            fk = f"{key}_v{v:02d}"
            d = work / "fits" / f"ids{big}" / key / "views"
            depth = _depth_tile(d / f"{fk}_pred_depth.exr")
            tiles += [np.asarray(Image.open(d / f"{fk}_pred_colour.png")), np.asarray(Image.open(d / f"{fk}_gt.png")),
                      depth, np.asarray(Image.open(d / f"{fk}_pred_normals.png"))]
            for other in ("ids1", "none"):
                tiles.append(np.asarray(Image.open(work / "fits" / other / key / "views" / f"{fk}_pred_colour.png")))
        rows.append(np.concatenate([t[..., :3] if t.ndim == 3 else np.repeat(t[..., None], 3, -1) for t in tiles], 1))
    img = np.concatenate(rows, 0)
    t = 128  # tile side in the figure
    fig = Image.fromarray(img).resize((img.shape[1] * t // S, img.shape[0] * t // S), Image.LANCZOS)
    labels = ["input 0°", "input +45°", "input -45°"]
    for v in (HELD_OUT[1], HELD_OUT[4]):
        az = TEST_VIEWS[v][0]
        labels += [f"{big} ids, {az:+.0f}°", "ground truth", "depth", "normals", "1 identity", "no pre-training"]
    out = Image.new("RGB", (fig.width, fig.height + 16), "white")
    out.paste(fig, (0, 16))
    draw = ImageDraw.Draw(out)
    for k, text in enumerate(labels):
        draw.text((k * t + 4, 2), text, fill="black")
    path.parent.mkdir(parents=True, exist_ok=True)
    out.save(path, optimize=True)
    log(f"figure: {path}")


def _depth_tile(path: Path) -> np.ndarray:
    import OpenEXR

    z = OpenEXR.File(str(path)).channels()["Z"].pixels.astype(np.float64)
    fg = z > 0
    out = np.zeros(z.shape, np.uint8)
    if fg.any():
        lo, hi = np.percentile(z[fg], [2, 98])
        out[fg] = (255 * (1 - np.clip((z[fg] - lo) / max(hi - lo, 1e-6), 0, 1)) * 0.8 + 40).astype(np.uint8)
    return out


# --------------------------------------------------------------------------- bf16 check


def bf16_check(work: Path, p: dict, scale: float, device: str, times: Times) -> None:
    """The 1-identity rung trained again in float32 (same steps), fitted on every test scene with 3 views."""
    train(work, p, scale, device, times, rungs=[1], extra=["train.bf16=false"], tag="_fp32")
    fit(work, p, scale, device, times, rows=[("ids1", 1, 3)], tag="_fp32")
    import torch

    from prior.precision import native_bf16

    a, b = collect(work, p).get("ids1"), collect(work, p, "_fp32").get("ids1")
    auto = "bf16" if native_bf16(torch.device(device))[0] else "auto: float32"
    if a and b:
        print(f"| training | train s | PSNR dB | SSIM | LPIPS |\n|---|---|---|---|---|\n"
              f"| {auto} | {times.data['train_ids001']['seconds']} | {a['psnr']:.2f} | {a['ssim']:.4f} | "
              f"{a['lpips']:.4f} |\n"
              f"| float32 | {times.data['train_ids001_fp32']['seconds']} | {b['psnr']:.2f} | {b['ssim']:.4f} | "
              f"{b['lpips']:.4f} |")


def stage_arguments(description: str, stages: list[str], profiles: dict) -> argparse.ArgumentParser:
    """The options of a staged prior benchmark (this one, prior_sizes.py): stage, work folder,
    profile, step scale, device, torch threads."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("stage", choices=stages)
    ap.add_argument("--work", type=Path, required=True, help="working directory (datasets, runs, fits, results)")
    ap.add_argument("--profile", choices=sorted(profiles), default="cpu")
    ap.add_argument("--scale", type=float, default=1.0, help="multiply training/fitting steps and rays per step")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", type=int, default=1,
                    help="torch threads (one per process on shared cores: more threads than free cores is much slower)")
    return ap


def stage_start(a, profiles: dict) -> tuple[dict, Times]:
    """Set the torch threads, make the work folder; the profile and the stage timer."""
    import torch

    torch.set_num_threads(a.threads)
    a.work.mkdir(parents=True, exist_ok=True)
    return profiles[a.profile], Times(a.work)


def main(argv=None) -> int:
    ap = stage_arguments(__doc__.splitlines()[0], ["all", "render", "train", "fit", "report", "bf16"], PROFILES)
    ap.add_argument("--scenes", default=None, help="fit: only these test scenes (indices, e.g. 0,1), so that "
                    "several processes can share the fits")
    ap.add_argument("--figure", type=Path, default=None, help="write the Fig. 5-like figure here (report)")
    a = ap.parse_args(argv)
    p, times = stage_start(a, PROFILES)
    times.data["load_start"] = list(os.getloadavg())
    if a.stage in ("all", "render"):
        render(a.work, p, times)
    if a.stage in ("all", "train"):
        train(a.work, p, a.scale, a.device, times)
    if a.stage in ("all", "fit"):
        only = None if a.scenes is None else [int(x) for x in a.scenes.split(",")]
        fit(a.work, p, a.scale, a.device, times, only=only)
    if a.stage == "bf16":
        bf16_check(a.work, p, a.scale, a.device, times)
    if a.stage in ("all", "report"):
        report(a.work, p, times, a.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
