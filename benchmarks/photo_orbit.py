"""A real photo end to end: scikit-image's astronaut (public domain, one view) through landmarks ->
head model and camera -> inversion -> fine-tuning -> novel views (docs/fitting.md, "One photo end
to end"; issue 40).

    .venv/bin/python benchmarks/photo_orbit.py all --work W [--profile cpu|tiny] [--figure docs/fitting_astronaut.png]
    .venv/bin/python benchmarks/photo_orbit.py render --work W      # the training dataset (synth render, bpy)
    .venv/bin/python benchmarks/photo_orbit.py train --work W       # one prior per PRIORS entry
    .venv/bin/python benchmarks/photo_orbit.py fit --work W [--only NAME,...]   # the fits (resumable, shareable)
    .venv/bin/python benchmarks/photo_orbit.py report --work W --figure docs/fitting_astronaut.png

Stages (each resumable: finished outputs are kept and skipped):

1. render: one ``synth render --preset preview`` dataset (front hemisphere, azimuth -90..90 degrees);
   every prior trains on its first shards, so every frame is rendered once.
2. train: ``synth prior train`` with the claim benchmark's CPU settings, one run per prior (identities, steps).
3. fit: ``synth prior fit astronaut.png --landmarks mediapipe`` (:func:`prior.fit.pipeline.fit_face`) for every
   row of the profile (prior x fine-tuning steps x face_fraction), then the input view and five views at -40, -20,
   0, +20, +40 degrees about the face (``synth prior render FIT --orbit 5 --span 80``); each fit is scored on its
   input view inside the face mask: the hull of mediapipe's 478 face-mesh points (as detected) times the
   foreground mask, PSNR / SSIM / LPIPS (VGG) of sRGB colour over black, at the photo's resolution.
4. report: markdown tables (quality per row, time of each stage) and the figure: the input, the landmark fit, the
   fit at the input camera, the five views (colour, depth, normals) of the best row and the colour views of the
   fit with every ray uniform over the photo (``uniform_*``, ``finetune.face_fraction=0``).

Times (wall, one torch thread per process) and the machine's load average go to ``W/times.json``, the
results to ``W/results.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from synth.io import atomic_write_json  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from prior_claim import synth  # noqa: E402  (the synth CLI in a subprocess; exits with its message)

#: the prior training settings of benchmarks/prior_claim.py's cpu profile
TRAIN_SETS = ["train.identities_per_batch=2", "train.views_per_identity=4", "train.pixels_per_view=32",
              "train.foreground_fraction=0.5", "train.warmup_steps=30", "train.background_steps=100",
              "train.log_every=50", "train.checkpoint_every=250", "train.preview_every=0", "train.bf16=auto",
              "sampling.proposal_samples=[16,16]", "sampling.nerf_samples=24"]
#: views rendered about the face: azimuths relative to the input's
SPAN_DEG, ORBIT = 80.0, 5

PROFILES = {
    # the run in docs/fitting.md: about an hour and a half of the shared 2-core machine (two fit processes)
    "cpu": dict(ids=16, expressions=2, views=10, res=64, seed=1,
                priors={"ids04_1k": (4, 1000), "ids16_1k": (16, 1000), "ids16_4k": (16, 4000)},
                # (name, prior, fine-tuning steps, face_fraction)
                fits=[("uniform_300", "ids16_1k", 300, 0.0),
                      ("face_300", "ids16_1k", 300, 0.5), ("face_1000", "ids16_1k", 1000, 0.5),
                      ("face_3000", "ids16_1k", 3000, 0.5),
                      ("ids04_face_300", "ids04_1k", 300, 0.5), ("ids16_4k_face_300", "ids16_4k", 300, 0.5)],
                fit_sets=["inversion.steps=100", "finetune.rays_per_step=1024"], size=128),
    # a few minutes: checks the script, proves nothing
    "tiny": dict(ids=2, expressions=1, views=4, res=32, seed=1, priors={"ids02": (2, 20)},
                 fits=[("uniform_4", "ids02", 4, 0.0), ("face_4", "ids02", 4, 0.5)],
                 fit_sets=["inversion.steps=2", "inversion.patches=1", "finetune.rays_per_step=128",
                           "finetune.warmup_steps=1"], size=32),
}


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


class Times:
    """Wall times and load averages per stage, kept in W/times.json across invocations and processes."""

    def __init__(self, work: Path):
        self.path = work / "times.json"

    @property
    def data(self) -> dict:
        return json.loads(self.path.read_text()) if self.path.is_file() else {}

    def record(self, key: str, t0: float, **extra) -> None:
        entry = {"seconds": round(time.perf_counter() - t0, 1), "load_end": [round(x, 2) for x in os.getloadavg()],
                 **extra}
        atomic_write_json(self.path, {**self.data, key: entry})


def photo(work: Path) -> Path:
    """The astronaut as a PNG in the work directory."""
    from PIL import Image
    from skimage import data

    p = work / "astronaut.png"
    if not p.is_file():
        Image.fromarray(data.astronaut()).save(p)
    return p


# --------------------------------------------------------------------------- render, train


def render(work: Path, p: dict, times: Times) -> None:
    if "render" in times.data:
        return
    t0 = time.perf_counter()
    log(f"render: {p['ids']} identities x {p['expressions']} x {p['views']} views at {p['res']}^2")
    synth("render", "-n", p["ids"], "-e", p["expressions"], "-v", p["views"], "--preset", "preview",
          "--set", f"render.resolution=[{p['res']},{p['res']}]", "--set", "camera.azimuth_deg=[-90,90]",
          "--set", "camera.elevation_deg=[-30,45]", "--seed", p["seed"], "--out", work / "ds_train", "-q")
    times.record("render", t0, frames=p["ids"] * p["expressions"] * p["views"])


def train(work: Path, p: dict, times: Times, only=None) -> None:
    import torch

    from prior.train.checkpoint import latest, load
    from prior.train.loop import Trainer
    from prior.train.run import prepare

    for name, (n, steps) in p["priors"].items():
        if only and name not in only:
            continue
        run = work / "runs" / name
        if latest(run) is not None and load(latest(run)).step >= steps:
            continue
        t0 = time.perf_counter()
        log(f"train: {name}, {n} identities, {steps} steps")
        resume = latest(run) is not None
        shards = [work / "ds_train" / "shards" / f"shard_{k:06d}" for k in range(n)]
        s = prepare(shards, run, preset=None if resume else "small", sets=[] if resume else TRAIN_SETS,
                    steps=steps, resume=resume)
        tr = Trainer(s, torch.device("cpu"), tty=False, tensorboard=False)
        tr.run()
        times.record(f"train_{name}", t0, steps=steps, identities=n, psnr=tr.losses.get("psnr"))


# --------------------------------------------------------------------------- fit, score


def face_mask(fit_info: dict, mask: np.ndarray) -> np.ndarray:
    """(H, W) float: the hull of the input's detected landmarks (no growth) times its foreground mask."""
    from prior.fit.views import face_region

    pts = np.array([[np.nan, np.nan] if q is None else q for q in fit_info["landmarks_2d"][0]], np.float64)
    H, W = mask.shape
    return face_region(pts, W, H, 0.0).astype(np.float32) * mask


def input_view(fit_dir: Path, box: tuple[int, int, int, int]) -> dict:
    """The fit rendered at its input camera, over the pixel box (x0, y0, x1, y1) only."""
    from prior.fit.fitdir import load_fit
    from prior.fit.novel import render_fit_view

    fit = load_fit(fit_dir)
    x0, y0, x1, y1 = box
    K = fit.K[0].copy()
    K[0, 2] -= x0
    K[1, 2] -= y0
    return render_fit_view(fit, K, fit.camera_to_world[0], x1 - x0, y1 - y0, chunk=fit.render_chunk)


def score(fit_dir: Path, target: np.ndarray, mask: np.ndarray) -> dict:
    """PSNR / SSIM / LPIPS of the input view inside the face mask (sRGB over black), and the render."""
    import torch

    from prior.metrics import lpips, psnr, ssim
    from synth.appearance.srgb import linear_to_srgb

    info = json.loads((fit_dir / "fit.json").read_text())
    fm = face_mask(info, mask)
    ys, xs = np.nonzero(fm > 0)
    pad = 16  # room for SSIM's window and LPIPS's receptive field around the face
    H, W = fm.shape
    box = (max(0, xs.min() - pad), max(0, ys.min() - pad), min(W, xs.max() + 1 + pad), min(H, ys.max() + 1 + pad))
    x0, y0, x1, y1 = box
    t0 = time.perf_counter()
    img = input_view(fit_dir, box)
    render_s = time.perf_counter() - t0
    a = linear_to_srgb(np.clip(img["rgb"], 0, 1)).astype(np.float32)
    b = linear_to_srgb(np.clip(target[y0:y1, x0:x1], 0, 1)).astype(np.float32)
    m = fm[y0:y1, x0:x1]
    ta, tb, tm = (torch.from_numpy(np.ascontiguousarray(x)) for x in (a, b, m))
    return {"psnr": float(psnr(ta, tb, tm)), "ssim": float(ssim(ta, tb, tm)), "lpips": float(lpips(ta, tb, mask=tm)),
            "face_pixels": int((fm > 0).sum()), "box": [int(v) for v in box], "render_input_s": render_s,
            "rgb": img["rgb"]}


def photo_inputs(work: Path):
    """The photo as the fit reads it: (linear colour times mask, mask)."""
    from prior.fit.inputs import observations, read_inputs
    from synth.model.default import load_default_model

    inputs = read_inputs([photo(work)], 2048)
    observations(inputs, "mediapipe", load_default_model())
    return inputs[0].target, inputs[0].mask


def fit(work: Path, p: dict, times: Times, only=None) -> None:
    from PIL import Image

    from prior.fit.novel import render_fit
    from prior.fit.pipeline import fit_face
    from synth.appearance.srgb import srgb8

    t_stage = time.perf_counter()
    target, mask = photo_inputs(work)
    for name, prior_name, steps, face in p["fits"]:
        if only and name not in only:
            continue
        out = work / "fits" / name
        if (out / "score.json").is_file():
            continue
        if not (work / "runs" / prior_name).is_dir():
            log(f"fit: {name} skipped, prior {prior_name} is not trained")
            continue
        t0 = time.perf_counter()
        log(f"fit: {name} (prior {prior_name}, {steps} fine-tuning steps, face_fraction {face})")
        if not (out / "fit").is_dir():
            fit_face([photo(work)], work / "runs" / prior_name, out / "fit", landmarks="mediapipe",
                     sets=[*p["fit_sets"], f"finetune.face_fraction={face}"], steps=steps, log=lambda m: None)
        fit_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        render_fit(out / "fit", out / "views", orbit_views=ORBIT, size=p["size"], span_deg=SPAN_DEG)
        views_s = time.perf_counter() - t1
        s = score(out / "fit", target, mask)
        Image.fromarray(srgb8(s.pop("rgb"))).save(out / "input_view.png")
        rep = json.loads((out / "fit" / "report.json").read_text())
        s.update(name=name, prior=prior_name, steps=steps, face_fraction=face,
                 times={**rep["times"], "fit_total_s": fit_s, "views_s": views_s},
                 train_psnr=rep["finetune"][-1]["psnr"] if rep["finetune"] else None,
                 inversion_whole_l1=rep.get("inversion_whole_l1"), landmarks=rep["landmarks"],
                 load_end=[round(x, 2) for x in os.getloadavg()])
        atomic_write_json(out / "score.json", s)
        log(f"  input view, face mask: PSNR {s['psnr']:.2f} dB  SSIM {s['ssim']:.4f}  LPIPS {s['lpips']:.4f}  "
            f"({fit_s:.0f} s fit, {views_s:.0f} s views)")
    times.record("fit" + ("_" + "_".join(only) if only else ""), t_stage, note="per fit: fits/*/score.json")


# --------------------------------------------------------------------------- report


def results(work: Path, p: dict) -> dict:
    out = {}
    for name, *_ in p["fits"]:
        f = work / "fits" / name / "score.json"
        if f.is_file():
            out[name] = json.loads(f.read_text())
    return out


def prior_psnr(run: Path, last: int = 5) -> float:
    """Mean training PSNR (dB, the run's own batches) over its last ``last`` logged steps."""
    logs = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines() if line.strip()]
    return float(np.mean([m["psnr"] for m in logs if "psnr" in m][-last:]))


def report(work: Path, p: dict, figure: Path | None) -> dict:
    res = results(work, p)
    tdata = Times(work).data
    lines = ["| fit | prior (identities, steps) | fine-tuning steps | face_fraction | PSNR dB | SSIM | LPIPS | "
             "training-ray PSNR dB | fit time s |", "|---|---|---|---|---|---|---|---|---|"]
    for name, r in res.items():
        n, st = p["priors"][r["prior"]]
        lines.append(f"| {name} | {n}, {st} | {r['steps']} | {r['face_fraction']} | {r['psnr']:.2f} | "
                     f"{r['ssim']:.4f} | {r['lpips']:.4f} | {r['train_psnr']:.2f} | {r['times']['fit_total_s']:.0f} |")
    print("\n".join(lines))
    lines2 = ["", "| fit | landmarks s | inversion s | fine-tuning s | 5 views s | input view s | "
              "inversion whole-image L1 |",
              "|---|---|---|---|---|---|---|"]
    for name, r in res.items():
        t = r["times"]
        inv = r.get("inversion_whole_l1") or [float("nan")] * 2
        lines2.append(f"| {name} | {t['landmarks_s']:.1f} | {t['inversion_s']:.1f} | {t['finetune_s']:.1f} | "
                      f"{t['views_s']:.1f} | {r['render_input_s']:.1f} | {inv[0]:.4f} -> {inv[1]:.4f} |")
    print("\n".join(lines2))
    lines3 = ["", "| stage | seconds | note |", "|---|---|---|"]
    for k, v in tdata.items():
        if k.startswith(("render", "train")):
            note = v.get("note", "")
            if k.startswith("train_"):
                note = f"training PSNR {prior_psnr(work / 'runs' / k[6:]):.2f} dB (mean of the last 5 logs)"
            lines3.append(f"| {k} | {v['seconds']:.0f} | {note} |")
    print("\n".join(lines3))
    atomic_write_json(work / "results.json", {"profile": {k: v for k, v in p.items()}, "rows": res, "times": tdata})
    if figure is not None and res:
        best = max(res, key=lambda k: res[k]["psnr"])
        baseline = next((k for k in res if k.startswith("uniform")), None)
        make_figure(work, p, figure, best, baseline)
        print(f"\nfigure: {figure} (best row: {best})")
    return res


def _depth_tile(path: Path) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        z = np.asarray(f.channels()["Z"].pixels, np.float32)
    surf = z > 0
    out = np.zeros(z.shape, np.uint8)
    if surf.any():
        lo, hi = np.percentile(z[surf], [2, 98])
        out[surf] = (255 * (1 - np.clip((z[surf] - lo) / max(hi - lo, 1e-6), 0, 1)) * 0.8 + 51).astype(np.uint8)
    return np.repeat(out[..., None], 3, -1)


def make_figure(work: Path, p: dict, path: Path, best: str, baseline: str | None) -> None:
    """Row 1: input (face-mask outline), landmark fit overlay, the best fit at the input camera, its views at
    -40..+40 degrees; rows 2-3: their depth (near = bright) and normals; row 4: the colour views of
    ``baseline`` (rays uniform over the photo)."""
    from PIL import Image, ImageDraw

    S = 160
    info = json.loads((work / "fits" / best / "fit" / "fit.json").read_text())
    s = json.loads((work / "fits" / best / "score.json").read_text())
    src = Image.open(photo(work)).convert("RGB")
    W, H = src.size
    # the head square: the box of the input view's score, made square about its centre
    x0, y0, x1, y1 = s["box"]
    c, half = ((x0 + x1) / 2, (y0 + y1) / 2), max(x1 - x0, y1 - y0) / 2 * 1.25
    sq = (c[0] - half, c[1] - half, c[0] + half, c[1] + half)

    def crop(im):
        return im.crop(tuple(round(v) for v in sq)).resize((S, S), Image.LANCZOS)

    overlay = src.copy()
    d = ImageDraw.Draw(overlay)
    for q in info["landmarks_2d"][0]:
        if q is not None:
            d.ellipse((q[0] - 1, q[1] - 1, q[0] + 1, q[1] + 1), fill=(255, 60, 60))
    for x, y in info["model_landmarks_2d"][0]:
        d.ellipse((x - 2, y - 2, x + 2, y + 2), outline=(60, 255, 60))
    fitted = Image.new("RGB", (W, H))
    fitted.paste(Image.open(work / "fits" / best / "input_view.png").convert("RGB"), (x0, y0))
    blank = Image.new("RGB", (S, S), (255, 255, 255))
    rows = [[crop(src), crop(overlay), crop(fitted)], [blank] * 3, [blank] * 3]
    vd = work / "fits" / best / "views"
    for k in range(ORBIT):
        rows[0].append(Image.open(vd / f"orbit{k:03d}_colour.png").convert("RGB").resize((S, S), Image.LANCZOS))
        rows[1].append(Image.fromarray(_depth_tile(vd / f"orbit{k:03d}_depth.exr")).resize((S, S), Image.NEAREST))
        rows[2].append(Image.open(vd / f"orbit{k:03d}_normals.png").convert("RGB").resize((S, S), Image.LANCZOS))
    if baseline is not None and baseline != best:
        dd = work / "fits" / baseline
        views = [Image.open(dd / "views" / f"orbit{k:03d}_colour.png").convert("RGB") for k in range(ORBIT)]
        rows.append([blank, blank, crop(_pasted(dd, W, H))] + [v.resize((S, S), Image.LANCZOS) for v in views])
    top = 18
    sheet = Image.new("RGB", (S * len(rows[0]), top + S * len(rows)), (255, 255, 255))
    dr = ImageDraw.Draw(sheet)
    angles = np.linspace(-SPAN_DEG / 2, SPAN_DEG / 2, ORBIT)
    labels = ["input (crop)", "landmarks: red detected, green fit", f"fit at input ({best})"] + \
        [f"{a:+.0f} deg" for a in angles]
    for i, t in enumerate(labels):
        dr.text((i * S + 3, 3), t, fill=(0, 0, 0))
    for r, row in enumerate(rows):
        for i, t in enumerate(row):
            sheet.paste(t, (i * S, top + r * S))
    if len(rows) > 3:
        dr.text((3, top + 3 * S + 3), f"{baseline}:", fill=(0, 0, 0))
        dr.text((3, top + 3 * S + 15), "rays uniform over the photo", fill=(0, 0, 0))
    path.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(path)


def _pasted(fit_dir: Path, W: int, H: int):
    from PIL import Image

    s = json.loads((fit_dir / "score.json").read_text())
    im = Image.new("RGB", (W, H))
    im.paste(Image.open(fit_dir / "input_view.png").convert("RGB"), tuple(s["box"][:2]))
    return im


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stage", choices=["all", "render", "train", "fit", "report"])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--profile", choices=sorted(PROFILES), default="cpu")
    ap.add_argument("--only", default="", help="comma-separated prior (train) or fit (fit) names")
    ap.add_argument("--figure", type=Path, default=None)
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    p = PROFILES[args.profile]
    args.work.mkdir(parents=True, exist_ok=True)
    times = Times(args.work)
    only = [s for s in args.only.split(",") if s] or None
    if args.stage in ("all", "render"):
        render(args.work, p, times)
    if args.stage in ("all", "train"):
        train(args.work, p, times, only)
    if args.stage in ("all", "fit"):
        fit(args.work, p, times, only)
    if args.stage in ("all", "report"):
        report(args.work, p, args.figure)
    return 0


if __name__ == "__main__":
    from benchmarks.runner import run_cli

    run_cli(main)
