"""Paper-size training speed of the prior on one GPU (run by benchmarks/prior_gpu.sh).

Measures, for the ``paper`` preset (32 M parameters, 128 + 128 + 128 samples per ray, a 1,500-row
codebook, a 109-value code as beta 48 || psi 52 + 9):

- training rays/s of full steps (forward, L1 + proposal loss, backward, per-group clipping,
  Adam) under bf16 autocast, eager and ``torch.compile``d;
- matmul FLOPs per step (``torch.utils.flop_counter``: the MLPs' linear layers, forward and
  backward) and the achieved fraction of the GPU's dense bf16 peak (``--peak``, FLOP/s);
- peak GPU memory;
- agreement of CUDA and CPU forward passes (float32, TF32 off, same weights and rays) and the
  bf16 deviation.

Rays are synthetic (random cameras around a 0.3 m ball), so no dataset is needed. ``--dry`` runs
the same code on CPU at the small preset with a few rays (a smoke test of this script).
Prints a markdown table; ``--out F`` also writes the figures as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from prior import losses  # noqa: E402
from prior.config import preset  # noqa: E402
from prior.model import PriorField, num_parameters  # noqa: E402
from prior.rays import RayBundle  # noqa: E402

CODE_DIM, LATENTS = 48 + 52 + 9, 1500


def rays(n: int, device, seed: int = 0) -> tuple[RayBundle, torch.Tensor]:
    """``n`` random rays through a 0.3 m ball and random target colours."""
    g = torch.Generator().manual_seed(seed)
    o = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1) * 1.1
    target = torch.randn(n, 3, generator=g) * 0.1
    d = torch.nn.functional.normalize(target - o, dim=-1)
    dist = (target - o).norm(dim=-1)
    near, far = (dist - 0.3).clamp_min(0.05), dist + 0.3
    codes = torch.randn(n, CODE_DIM, generator=g) * 0.5
    ids = torch.randint(0, LATENTS, (n,), generator=g)
    radii = torch.full((n,), 2 / 12 ** 0.5 / 100.0)
    rgb = torch.rand(n, 3, generator=g)
    return RayBundle(o, d, near, far, codes, latent_ids=ids, radii=radii).to(device), rgb.to(device)


def step_fn(model, fwd, opt, batch, clip: float, bf16: bool, device):
    bundle, rgb = batch
    gen = torch.Generator(device=device).manual_seed(1)

    def step():
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
            out = fwd(bundle, train_frac=0.5, randomized=True, generator=gen)
        loss = losses.l1_loss(out["rgb"], rgb) + losses.proposal_loss(out["history"])
        loss.backward()
        for ps in model.param_groups().values():
            torch.nn.utils.clip_grad_norm_([p for p in ps if p.grad is not None], clip)
        opt.step()
        opt.zero_grad(set_to_none=True)
        return loss.detach()
    return step


def timed(step, iters: int, warmup: int, device) -> float:
    for _ in range(warmup):
        step()
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    sync()
    t0 = time.perf_counter()
    for _ in range(iters):
        loss = step()
    sync()
    assert torch.isfinite(loss), "non-finite loss"
    return (time.perf_counter() - t0) / iters


def agreement(model, device, n: int = 512) -> dict:
    """Max |CUDA - CPU| of rgb, acc, depth (float32, deterministic sampling), and bf16 - fp32 on device."""
    cpu = PriorField(model.model_cfg, model.sampling_cfg, model.code_dim, LATENTS)
    cpu.load_state_dict({k: v.detach().cpu() for k, v in model.state_dict().items()})
    bundle, _ = rays(n, "cpu", seed=3)
    torch.backends.cuda.matmul.allow_tf32 = False
    torch.backends.cudnn.allow_tf32 = False
    with torch.no_grad():
        ref = cpu(bundle, randomized=False)
        on_device = bundle.to(device)
        got = model(on_device, randomized=False)
        with torch.autocast(device.type, dtype=torch.bfloat16):
            half = model(on_device, randomized=False)
    res = {f"max_abs_{k}": float((got[k].float().cpu() - ref[k]).abs().max()) for k in ("rgb", "acc", "depth")}
    res.update({f"bf16_max_abs_{k}": float((half[k].float() - got[k].float()).abs().max()) for k in ("rgb", "acc")})
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=16384, help="rays per step")
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--peak", type=float, default=790e12, help="dense bf16 peak FLOP/s of the GPU")
    ap.add_argument("--no-compile", action="store_true")
    ap.add_argument("--dry", action="store_true", help="CPU, small preset, few rays: a smoke test")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    if a.dry:
        device, name, a.rays, a.iters, a.warmup = torch.device("cpu"), "small", min(a.rays, 128), 2, 1
    else:
        if not torch.cuda.is_available():
            sys.exit("prior_gpu: no CUDA device (use --dry for a CPU smoke test)")
        device, name = torch.device("cuda"), "paper"
    mcfg, scfg = preset(name)
    model = PriorField(mcfg, scfg, CODE_DIM, LATENTS).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=1e-4, betas=(0.9, 0.999))
    from torch.utils.flop_counter import FlopCounterMode

    while True:  # the largest batch (halving from --rays) whose step fits in memory
        batch = rays(a.rays, device)
        try:
            with FlopCounterMode(display=False) as fc:
                step_fn(model, model, opt, batch, 1e-3, True, device)()
            break
        except torch.cuda.OutOfMemoryError:
            del batch
            opt.zero_grad(set_to_none=True)
            torch.cuda.empty_cache()
            if a.rays <= 1024:
                raise
            a.rays //= 2
    res = {"device": torch.cuda.get_device_name(0) if device.type == "cuda" else "cpu", "preset": name,
           "torch": torch.__version__, "parameters": num_parameters(model), "rays_per_step": a.rays,
           "samples_per_ray": sum(scfg.samples_per_level), "flops_per_step": int(fc.get_total_flops())}
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats()
    variants = [("eager", model)] + ([] if a.no_compile or a.dry else [("compiled", torch.compile(model))])
    for tag, fwd in variants:
        try:
            dt = timed(step_fn(model, fwd, opt, batch, 1e-3, True, device), a.iters, a.warmup, device)
        except Exception as e:  # report and go on: the eager figure still counts
            res[f"{tag}_error"] = f"{type(e).__name__}: {str(e).splitlines()[0][:200]}"
            continue
        res[f"{tag}_s_per_step"] = dt
        res[f"{tag}_rays_per_s"] = a.rays / dt
        res[f"{tag}_tflops"] = res["flops_per_step"] / dt / 1e12
        res[f"{tag}_peak_fraction"] = res["flops_per_step"] / dt / a.peak
    if device.type == "cuda":
        res["peak_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
    res.update(agreement(model, device))  # on CPU (--dry): CPU against itself, a smoke test
    print(json.dumps(res, indent=1))
    print("| variant | rays/s | s/step | TFLOP/s | fraction of bf16 peak |")
    print("|---|---|---|---|---|")
    for tag, _ in variants:
        if f"{tag}_rays_per_s" in res:
            print(f"| {tag} bf16 | {res[f'{tag}_rays_per_s']:,.0f} | {res[f'{tag}_s_per_step']:.3f} | "
                  f"{res[f'{tag}_tflops']:.1f} | {100 * res[f'{tag}_peak_fraction']:.1f} % |")
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
