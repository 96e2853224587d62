"""What the skin rig's per-identity colour layers cost: Cycles CPU seconds per frame with the
under-eye darkening and the vellus sheen at their planned strengths and with both set to 0, the
two taken in alternating order over ``--rounds`` rounds (CPU time: a shared machine inflates wall
time, not the work done).

    .venv/bin/synth plan -n 2 -o PLAN --seed 8 --set 'render.preset="preview"' \\
        --set dataset.expressions_per_identity=1 --set dataset.views_per_expression=3
    .venv/bin/python benchmarks/skin_layers_cost.py PLAN [--rounds 2]
"""

from __future__ import annotations

import argparse
import importlib
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def cpu_by_mode(plan_path: str, rounds: int, modes: dict) -> dict[str, list[float]]:
    """Cycles CPU seconds of every frame of the plan per mode: ``modes`` maps a name to a function
    that sets the module state of that mode; the modes are taken in alternating order over
    ``rounds`` rounds (also used by benchmarks/brow_band.py ``--cost``)."""
    from blender_scripts import scene as bscene
    from blender_scripts.worker import IdentityScene, software_versions
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan
    from synth.plan.records import RenderSettings

    plan = load_plan(plan_path)
    hm = HeadModel(plan.model_data())
    names = list(modes)
    cpu: dict[str, list[float]] = {k: [] for k in names}
    with tempfile.TemporaryDirectory(prefix="synth-cost-") as d:
        for rnd in range(rounds):
            for mode in (names if rnd % 2 == 0 else names[::-1]):
                modes[mode]()
                for sid in plan.shard_ids():
                    spec = plan.shard_spec(sid)
                    ident = spec.identities[0]
                    sc = IdentityScene(ident, hm, RenderSettings.from_json(plan.render_settings()), spec.run_seed,
                                       {"name": hm.data.name, "sha256": plan.model_sha256()}, software_versions(), sid)
                    try:
                        for e in ident.expressions:
                            sc.set_expression(e)
                            cpu[mode] += [sc.render(fr, Path(d))[0]["render_cpu_seconds"] for fr in e.frames]
                    finally:
                        sc.close()
                        bscene.reset()
    return cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan")
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()

    sd = importlib.import_module("blender_scripts.assets.skin_detail")
    planned = {"on": (sd.UNDER_EYE, sd.VELLUS_SHEEN), "off": ((0.0, 0.0), (0.0, 0.0))}

    def setter(mode):
        def f():
            sd.UNDER_EYE, sd.VELLUS_SHEEN = planned[mode]
        return f

    cpu = cpu_by_mode(args.plan, args.rounds, {m: setter(m) for m in ("on", "off")})
    on, off = np.mean(cpu["on"]), np.mean(cpu["off"])
    print("| skin layers | frames | Cycles CPU s / frame |\n|---|---:|---:|")
    print(f"| planned strengths | {len(cpu['on'])} | {on:.2f} |\n| strengths 0 | {len(cpu['off'])} | {off:.2f} |")
    print(f"\nratio {on / off:.3f}")


if __name__ == "__main__":
    main()
