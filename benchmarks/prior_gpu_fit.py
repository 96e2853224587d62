"""Few-shot fitting speed on one GPU (run by benchmarks/prior_gpu.sh after the training check).

Measures, for the ``paper`` preset (the prior's field; the fit config's ``paper`` preset:
4,096 random rays per step, every loss of Eq. 7 including the normal consistency):

- fine-tuning steps/s (:func:`prior.fit.finetune.finetune`, the code ``synth prior fit`` runs)
  in float32 and under bf16 autocast, and the projected time of the paper's 50,000 steps
  (paper: 3.5 hours on 4 TPUs; goal: at most 15 minutes);
- the time to render one 1024 x 1024 view (:func:`prior.render_views.render_image`, the code
  ``synth prior render FIT`` runs; paper: 20.5 s per frame; goal: at most 1 s), at the paper's
  samples per level and with fewer samples, each against the full-sample render of the same
  field (PSNR and max |difference| of colour, and opacity): speed against error.

The scene is synthetic, so no dataset or prior run is needed: three 512 x 512 views (frontal
and +-45 degrees at 1 m, as a few-shot fit's inputs) of a shaded 0.12 m sphere, and the field
is fine-tuned on them from a random initialisation for the timed steps; the errors of fewer
samples are therefore indicative only (a real fitted face has a sharper surface). ``--dry``
runs the same code on CPU at the small preset, 64 rays and a 16 x 16 view (a smoke test).
Prints a markdown table; ``--out F`` also writes the figures as JSON.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from prior.config import preset  # noqa: E402
from prior.fit import config as fit_config  # noqa: E402
from prior.fit.finetune import finetune  # noqa: E402
from prior.fit.views import ViewSet  # noqa: E402
from prior.model import PriorField  # noqa: E402
from prior.render_views import render_image  # noqa: E402
from synth.conventions import orbit_camera_to_world  # noqa: E402
from synth.dataset.reader import camera_rays  # noqa: E402

CODE_DIM, SPHERE_M, BOUNDS_M = 48 + 52 + 9, 0.12, 0.3


def sphere_views(size: int) -> ViewSet:
    """Three views of a Lambertian sphere at the origin (colour from its normal), masked."""
    K = np.array([[1.2 * size, 0, size / 2], [0, 1.2 * size, size / 2], [0, 0, 1.0]])
    c2ws, imgs = [], []
    for az in (0.0, 45.0, -45.0):
        c2w = orbit_camera_to_world(az, 0.0, 1.0, np.zeros(3))
        r = camera_rays(K, c2w, size, size)
        o, d = r.origins.astype(np.float64), r.directions.astype(np.float64)
        b = (o * d).sum(-1)
        disc = b * b - ((o * o).sum(-1) - SPHERE_M ** 2)
        t = -b - np.sqrt(np.clip(disc, 0, None))
        n = (o + t[..., None] * d) / SPHERE_M
        imgs.append(np.where((disc > 0)[..., None], 0.2 + 0.6 * (n * 0.5 + 0.5), 0.0).astype(np.float32))
        c2ws.append(c2w)
    return ViewSet(np.stack(imgs), np.stack([K] * 3), np.stack(c2ws), np.zeros((3, CODE_DIM), np.float32),
                   np.zeros(3), BOUNDS_M)


def time_finetune(model, views, w0, cfg, warmup: int, iters: int, device) -> tuple[float, list[dict]]:
    """Seconds per fine-tuning step (after ``warmup`` steps) and the loss history."""
    marks = {}

    def progress(stage, done, total, rec):
        if device.type == "cuda":
            torch.cuda.synchronize()
        marks[done] = time.perf_counter()

    cfg = dataclasses.replace(cfg, steps=warmup + iters)
    _, hist = finetune(model, views, w0, cfg, device=device, progress=progress, log_every=1)
    return (marks[warmup + iters] - marks[warmup]) / iters, hist


def render_timed(model, K, c2w, size: int, chunk: int, latent, device, bf16: bool) -> tuple[float, dict]:
    if device.type == "cuda":
        torch.cuda.synchronize()
    t0 = time.perf_counter()
    with torch.no_grad():
        img = render_image(model, K, c2w, size, size, np.zeros(CODE_DIM, np.float32), None, np.zeros(3), BOUNDS_M,
                           chunk=chunk, device=device, bf16=bf16, latent=latent)
    if device.type == "cuda":
        torch.cuda.synchronize()
    return time.perf_counter() - t0, img


def with_samples(model, scfg, samples: tuple[int, int, int], device) -> PriorField:
    """The same field (weights shared) sampled with (proposal, proposal, nerf) samples per level."""
    s = dataclasses.replace(scfg, proposal_samples=samples[:2], nerf_samples=samples[2])
    other = PriorField(model.model_cfg, s, model.code_dim, model.codebook.embedding.num_embeddings).to(device)
    other.load_state_dict(model.state_dict())
    return other.eval()


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(-10 * np.log10(max(float(np.mean((a - b) ** 2)), 1e-12)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iters", type=int, default=20, help="timed fine-tuning steps (after the warm-up)")
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--size", type=int, default=1024, help="side of the rendered view")
    ap.add_argument("--chunk", type=int, default=16384, help="rays per chunk when rendering")
    ap.add_argument("--dry", action="store_true", help="CPU, small preset, few rays: a smoke test")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    fcfg = fit_config.preset("paper").finetune
    if a.dry:
        torch.set_num_threads(1)  # a smoke test on a shared CPU: one thread does not wait on busy cores
        device, name, a.iters, a.warmup, a.size, a.chunk = torch.device("cpu"), "small", 1, 1, 16, 1024
        fcfg, in_size = dataclasses.replace(fcfg, rays_per_step=64), 16
    else:
        if not torch.cuda.is_available():
            sys.exit("prior_gpu_fit: no CUDA device (use --dry for a CPU smoke test)")
        device, name, in_size = torch.device("cuda"), "paper", 512
    fcfg = dataclasses.replace(fcfg, warmup_steps=0)
    mcfg, scfg = preset(name)
    model = PriorField(mcfg, scfg, CODE_DIM, 1).to(device)
    views = sphere_views(in_size)
    w = model.codebook.mean_latent()
    res = {"device": torch.cuda.get_device_name(0) if device.type == "cuda" else "cpu", "preset": name,
           "torch": torch.__version__, "rays_per_step": fcfg.rays_per_step, "input_size": in_size,
           "samples_per_level": list(scfg.samples_per_level), "paper_steps": fit_config.preset("paper").finetune.steps}
    # fine-tuning from random weights at the fit's learning rate empties the field within a step or two
    # (zero density everywhere), which times the same but renders black at every sample count: the
    # render rows use the initial (random, non-empty) field
    initial = {k: v.detach().clone() for k, v in model.state_dict().items()}
    for tag, bf16 in (("fp32", False), ("bf16", True)):
        dt, hist = time_finetune(model, views, w, dataclasses.replace(fcfg, bf16=bf16), a.warmup, a.iters, device)
        res[f"finetune_{tag}_s_per_step"] = dt
        res[f"finetune_{tag}_steps_per_s"] = 1 / dt
        res[f"finetune_{tag}_projected_min"] = dt * res["paper_steps"] / 60
        res[f"finetune_{tag}_last_psnr"] = hist[-1]["psnr"]
    if device.type == "cuda":
        res["peak_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
        torch.cuda.empty_cache()
    print(json.dumps(res), flush=True)  # the fine-tuning figures stand even if a render fails
    model.load_state_dict(initial)
    K = views.K[0] * np.array([[a.size / in_size], [a.size / in_size], [1.0]])
    model.eval()
    full = scfg.samples_per_level
    settings = [full, tuple(max(2, n // 2) for n in full), tuple(max(2, n // 4) for n in full),
                (full[0], max(2, full[1] // 2), max(2, full[2] // 4))]
    rows, ref = [], None
    for samples in settings:
        m = model if tuple(samples) == tuple(full) else with_samples(model, scfg, samples, device)
        for bf16 in (False, True):
            render_timed(m, K, views.c2w[0], min(a.size, 64), a.chunk, w, device, bf16)  # warm-up
            dt, img = render_timed(m, K, views.c2w[0], a.size, a.chunk, w, device, bf16)
            ref = img if ref is None else ref
            rows.append({"samples": list(samples), "bf16": bf16, "seconds": dt,
                         "psnr_vs_full": psnr(img["rgb"], ref["rgb"]),
                         "max_abs_rgb": float(np.abs(img["rgb"] - ref["rgb"]).max()),
                         "max_abs_acc": float(np.abs(img["acc"] - ref["acc"]).max()),
                         "max_acc": float(img["acc"].max())})
    res["render"] = rows
    res["render_size"] = a.size
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(res, indent=1))
    print(json.dumps(res, indent=1))
    print(tables(res))


def tables(res: dict) -> str:
    """The two markdown tables: fine-tuning speed, and render time against error."""
    lines = [f"| fine-tuning | s/step | steps/s | projected {res['paper_steps']:,} steps |", "|---|---|---|---|"]
    lines += [f"| {t} | {res[f'finetune_{t}_s_per_step']:.3f} | {res[f'finetune_{t}_steps_per_s']:.2f} | "
              f"{res[f'finetune_{t}_projected_min']:.1f} min |" for t in ("fp32", "bf16")]
    lines += ["", f"| samples per level | autocast | {res['render_size']}² view s | PSNR vs full | max abs rgb |",
              "|---|---|---|---|---|"]
    lines += [f"| {'/'.join(map(str, r['samples']))} | {'bf16' if r['bf16'] else 'fp32'} | {r['seconds']:.2f} | "
              f"{r['psnr_vs_full']:.1f} dB | {r['max_abs_rgb']:.4f} |" for r in res["render"]]
    return "\n".join(lines)

if __name__ == "__main__":
    main()
