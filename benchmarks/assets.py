"""Asset rigs: time and memory per scene against strand count, and image error against a
dense-hair reference (speed against error). Prints Markdown for docs/performance.md.

    .venv/bin/python benchmarks/assets.py [--image 256] [--spp 16] [--views 2]
                                          [--densities 64 128 256 512 1024 2048] [--identity 0]

Hair, beard, brow and lash counts scale with the *asset resolution* (normally the render
size; here swept independently while the image stays at --image pixels). For each asset
resolution: a fresh scene for the planned identity (all its assets), build time, Cycles time
per view, the process RSS after the build, the strand counts, and PSNR of the render against
the densest setting over the pixels its alpha covers (sRGB-encoded, clipped). Same Cycles
seed for every setting, denoised, so the remaining difference is the hair geometry plus a
little sampling noise (the last row's noise floor: the reference rendered again with another
seed).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from render import machine, psnr_masked, rss_mb  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--image", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--views", type=int, default=2)
    ap.add_argument("--densities", type=int, nargs="+", default=[64, 128, 256, 512, 1024, 2048])
    ap.add_argument("--identity", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    from blender_scripts import scene as bscene
    from blender_scripts.worker import IdentityScene, software_versions
    from synth.config import load_config
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan
    from synth.plan.records import RenderSettings

    with tempfile.TemporaryDirectory(prefix="synth-bench-") as d:
        tmp = Path(d)
        cfg = load_config(None, ['render.preset="preview"', f"render.resolution=[{args.image}, {args.image}]",
                                 f"render.samples={args.spp}", "dataset.expressions_per_identity=1",
                                 f"dataset.views_per_expression={max(args.views, 2)}"])
        run_plan(cfg, 1, tmp / "plan", seed=args.seed, first_identity=args.identity)
        plan = load_plan(tmp / "plan")
        hm = HeadModel(plan.model_data())
        spec = plan.shard_spec(plan.shard_ids()[0])
        ident = spec.identities[0]
        frames = ident.expressions[0].frames[: args.views]
        results = []
        for res in sorted(args.densities):
            t0 = time.perf_counter()
            sc = IdentityScene(ident, hm, RenderSettings.from_json(plan.render_settings()), spec.run_seed,
                               {"name": hm.data.name, "sha256": plan.model_sha256()}, software_versions(),
                               asset_resolution=res)
            sc.set_expression(ident.expressions[0])
            t_build = time.perf_counter() - t0
            rss = rss_mb()
            outs, t_render = [], 0.0
            for f in frames:
                out, _ = sc.render(f, tmp)
                t_render += out["render_seconds"]
                outs.append(out["rgba"])
            counts = {c: r.record().get("strands") for c, r in sc.rigs.items() if r.record().get("strands")}
            noise = None
            if res == max(args.densities):  # noise floor: same geometry, another Cycles seed
                noise = [sc.render(f, tmp, seed=f.seed + 1)[0]["rgba"] for f in frames]
            sc.close()
            bscene.reset()
            results.append((res, counts, t_build, t_render / len(frames), rss, outs, noise))
            print(f"  asset resolution {res}: {counts} build {t_build:.2f} s render {t_render / len(frames):.2f} s "
                  f"RSS {rss:.0f} MB", file=sys.stderr)
    ref = results[-1][5]
    masks = [r[..., 3] > 0.5 for r in ref]
    assets = ", ".join(f"{c}={e.id}" for c, e in ident.assets.items() if e)
    print(f"\n### Asset cost against strand count ({args.image}x{args.image}, {args.spp} spp denoised; {machine()})\n")
    print(f"Identity {args.identity} (seed {args.seed}): {assets}. {args.views} views; PSNR against asset "
          f"resolution {results[-1][0]} over its alpha > 0.5 pixels.\n")
    print("| asset resolution | hair strands | beard | brows | lashes | build s | Cycles s / view | RSS MB | PSNR dB |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for res, counts, tb, tr, rss, outs, _ in results:
        p = np.mean([psnr_masked(o, r, m) for o, r, m in zip(outs, ref, masks)])
        print(f"| {res} | {counts.get('hair', 0):,} | {counts.get('beard', 0):,} | {counts.get('eyebrows', 0):,} | "
              f"{counts.get('eyelashes', 0):,} | {tb:.2f} | {tr:.2f} | {rss:.0f} | "
              f"{'ref' if res == results[-1][0] else f'{p:.2f}'} |")
    noise = results[-1][6]
    p = np.mean([psnr_masked(o, r, m) for o, r, m in zip(noise, ref, masks)])
    print(f"\nNoise floor (reference geometry, another Cycles seed): {p:.2f} dB.")


if __name__ == "__main__":
    main()
