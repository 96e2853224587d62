"""Render-farm benchmarks (issue 12). Prints the Markdown tables of docs/farm.md.

    .venv/bin/python benchmarks/farm.py [--identities 4 --views 3] [--backends local ray slurm]
                                        [--workers 1 2] [--projection-views 2]

throughput: the same plan (``--identities`` x 1 expression x ``--views`` at ``ci``, one shard
  per identity, one shard per worker process) rendered by each backend with 1 and 2 workers
  on this machine: frames/s, and wall time x workers over the time spent inside Cycles'
  render call (1.0 = no overhead at all). Per-shard overhead = (wall x workers - Cycles) /
  shards: worker start, bpy import, scene and asset build, writing, commit, and the backend's
  own start-up (a local Ray runtime; Slurm's scheduling), spread over the shards.
  ``slurm`` needs a running Slurm (``SLURM_CONF``; scripts/slurm_local.sh start).
projection: seconds per frame at each of ``--presets`` (preview, production, production-max) from a small local render
  (1 identity x 1 expression x ``--projection-views``; the first views of a scene pay its
  build, as a real shard's 390 frames do not, so this errs on the slow side), turned into
  hours for 1,500 identities (585,000 frames) on N machines like this one.
The machine's load average is printed with every row: other processes share its CPUs.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FRAMES_1500 = 1500 * 13 * 30


def machine() -> str:
    return f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def load() -> str:
    return "/".join(f"{x:.1f}" for x in os.getloadavg())


def render(backend_name: str, workers: int, identities: int, views: int, preset: str, seed: int = 0) -> dict:
    from renderer_jobs.backends import make_backend
    from renderer_jobs.submit import prepare_plan, render_plan, run_log_dir

    with tempfile.TemporaryDirectory(prefix="synth-farm-bench-", dir=os.environ.get("SYNTH_BENCH_DIR")) as d:
        out = Path(d) / "ds"
        pdir = prepare_plan(out, identities, None, ["dataset.expressions_per_identity=1",
                                                    f"dataset.views_per_expression={views}",
                                                    f'render.preset="{preset}"', "dataset.identities_per_shard=1"],
                            seed, None)
        load_before = load()
        t0 = time.perf_counter()
        backend = make_backend(backend_name, workers=workers,
                               array_parallelism=workers if backend_name == "slurm" else None)
        res = render_plan(out, pdir, backend, shards_per_worker=1, quiet=True, retries=0,
                          log_dir=run_log_dir(out, backend_name))
        res["wall_seconds"] = time.perf_counter() - t0  # with the backend's start-up
        res["load"] = f"{load_before} -> {load()}"
        return res


def throughput(args) -> None:
    rows = []
    for b in args.backends:
        for w in args.workers:
            r = render(b, w, args.identities, args.views, "ci")
            n, wall, cyc = r["frames_rendered"], r["wall_seconds"], r["render_seconds"]
            rows.append((b, w, n, r["shards"], wall, cyc, n / wall, wall * w / max(cyc, 1e-9),
                         (wall * w - cyc) / r["shards"], r["load"]))
            print(f"  {b} x{w}: {n} frames in {wall:.1f} s", file=sys.stderr, flush=True)
    print(f"\n### Throughput at `ci` ({args.identities} identities x 1 expression x {args.views} views, "
          f"one shard per identity; {machine()})\n")
    print("| backend | workers | frames | shards | wall s | Cycles s | frames/s | wall x workers / Cycles "
          "| overhead s / shard | load avg (1/5/15 min, before -> after) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for b, w, n, s, wall, cyc, fps, ratio, per_shard, ld in rows:
        print(f"| {b} | {w} | {n} | {s} | {wall:.1f} | {cyc:.1f} | {fps:.2f} | {ratio:.1f} | {per_shard:.1f} | {ld} |")


def projection(args) -> None:
    per_frame = {}
    for preset in args.presets:
        r = render("local", 1, 1, args.projection_views, preset)
        per_frame[preset] = (r["wall_seconds"] / r["frames_rendered"], r["render_seconds"] / r["frames_rendered"],
                             r["load"])
        print(f"  {preset}: {r['frames_rendered']} frames in {r['wall_seconds']:.1f} s", file=sys.stderr, flush=True)
    print(f"\n### Projection: 1,500 identities (585,000 frames) on N machines like this one ({machine()}, "
          "one worker each)\n")
    print("| preset | s / frame (wall) | of which Cycles | load avg | 1 machine | 10 | 100 | 500 |")
    print("|---|---|---|---|---|---|---|---|")
    for preset, (wall, cyc, ld) in per_frame.items():
        hours = [FRAMES_1500 * wall / n / 3600 for n in (1, 10, 100, 500)]
        print(f"| {preset} | {wall:.1f} | {cyc:.1f} | {ld} | " + " | ".join(f"{h:,.0f} h" if h >= 10 else f"{h:.1f} h"
                                                                            for h in hours) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", nargs="?", choices=("throughput", "projection", "all"), default="all")
    ap.add_argument("--identities", type=int, default=4)
    ap.add_argument("--views", type=int, default=3)
    ap.add_argument("--backends", nargs="+", default=["local", "ray"])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--projection-views", type=int, default=2)
    ap.add_argument("--presets", nargs="+", default=["preview", "production", "production-max"],
                    help="projection: the presets timed")
    args = ap.parse_args()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if args.what in ("throughput", "all"):
        throughput(args)
    if args.what in ("projection", "all"):
        projection(args)


if __name__ == "__main__":
    main()
