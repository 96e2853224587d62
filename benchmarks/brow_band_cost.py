"""What the eyebrow band costs: Cycles CPU seconds per frame with the band and without it
(``synth.assets.fit.eyebrows.BAND_DEPTH`` 0: no band drawn), the two in alternating order over
``--rounds`` rounds (:func:`skin_layers_cost.cpu_by_mode`; CPU time, since a shared machine
inflates wall time), and the build's own time for the band (numpy: the per-vertex brow
coordinates and the strands' depth) on the default head.

    .venv/bin/synth plan -n 2 -o PLAN --seed 8 --set 'render.preset="preview"' \\
        --set dataset.expressions_per_identity=1 --set dataset.views_per_expression=3
    .venv/bin/python benchmarks/brow_band_cost.py PLAN [--rounds 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from skin_layers_cost import cpu_by_mode  # noqa: E402


def build_seconds(resolution: int, repeats: int = 5) -> float:
    """Median wall seconds of :func:`synth.assets.fit.eyebrows.band` on the default head."""
    from synth.assets.fit import eyebrows as fe
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from tests.support.asset_scene import head_arrays

    ctx = head_arrays(HeadModel(load_default_model()), "neutral", resolution)
    entry = {"id": "natural", "params": {"thickness": 0.9, "density": 0.9}}
    g = fe.groom(ctx, entry)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fe.band(ctx, entry, g)
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan")
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()

    from synth.assets.fit import eyebrows as fe

    depth = fe.BAND_DEPTH

    def setter(d):
        def f():
            fe.BAND_DEPTH = d
        return f

    cpu = cpu_by_mode(args.plan, args.rounds, {"band": setter(depth), "none": setter(0.0)})
    on, off = np.mean(cpu["band"]), np.mean(cpu["none"])
    print("| eyebrows | frames | Cycles CPU s / frame |\n|---|---:|---:|")
    print(f"| with the band | {len(cpu['band'])} | {on:.2f} |\n| without | {len(cpu['none'])} | {off:.2f} |")
    print(f"\nratio {on / off:.3f}")
    for res in (256, 512):
        print(f"band build (numpy) at {res}: {build_seconds(res) * 1e3:.0f} ms")
    return 0


if __name__ == "__main__":
    from runner import run_cli

    run_cli(main)
