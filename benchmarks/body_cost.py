"""What a frame costs, before and after a change of the body or the garments: scene build, expression
change and render, paired frame by frame (issue 42, item 2: at most +25 % per frame).

    PYTHONPATH=OLD_TREE .venv/bin/python benchmarks/body_cost.py run W/before.json [--identities 4 ...]
    PYTHONPATH=NEW_TREE .venv/bin/python benchmarks/body_cost.py run W/after.json  [--identities 4 ...]
    .venv/bin/python benchmarks/body_cost.py compare W/before.json W/after.json

``run`` (needs bpy) plans ``--identities`` identities of ``--seed`` at ``--preset`` (the worker's
presets; default ``preview``) with ``--expressions`` expressions and ``--views`` views each, and
builds and renders them as the worker does (``blender_scripts.worker.IdentityScene``), in one
process: per identity the scene build (head, materials, every asset rig), per expression the
change (head and rigs updated), per frame the render. Each is timed in wall seconds and in the
process's CPU seconds (every thread's: steadier than wall time on a shared machine). Run it from
the tree to measure (``PYTHONPATH``); the plans of both trees use the same seed and identities, so
their frames pair by frame id (the model, and with it the framing, may differ).

``compare`` prints per step the before / after means and the cost per frame: the renders' plus the
builds' and expression changes' shares, over the frames of this run and over a default dataset's
13 expressions x 30 views per identity (``--expressions-per-identity``, ``--views-per-expression``).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path


def _clock():
    return time.perf_counter(), time.process_time()


def _since(t):
    w, c = _clock()
    return w - t[0], c - t[1]


def run(args) -> None:
    import subprocess

    from blender_scripts.worker import IdentityScene, software_versions
    from synth.config import load_config
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan
    from synth.plan.records import RenderSettings

    tree = Path(__import__("synth").__file__).resolve().parents[1]
    commit = args.label or subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"],
                                          capture_output=True, text=True).stdout.strip() or "?"
    rows = {"tree": str(tree), "commit": commit, "preset": args.preset, "seed": args.seed, "identities": [],
            "frames": []}
    with tempfile.TemporaryDirectory(prefix="synth-body-cost-") as d:
        tmp = Path(d)
        cfg = load_config(None, [f'render.preset="{args.preset}"', f"dataset.expressions_per_identity={args.expressions}",
                                 f"dataset.views_per_expression={args.views}"])
        run_plan(cfg, args.identities, tmp / "plan", seed=args.seed)
        plan = load_plan(tmp / "plan")
        hm = HeadModel(plan.model_data())
        rows["model_sha256"] = plan.model_sha256()
        render_cfg = RenderSettings.from_json(plan.render_settings())
        for shard_id in plan.shard_ids():
            spec = plan.shard_spec(shard_id)
            for ident in spec.identities:
                t = _clock()
                sc = IdentityScene(ident, hm, render_cfg, spec.run_seed, {"name": hm.data.name,
                                   "sha256": plan.model_sha256()}, software_versions(), shard_id)
                bw, bc = _since(t)
                rec = {"identity": int(ident.identity_index), "build_s": bw, "build_cpu_s": bc, "expressions": []}
                for e in ident.expressions:
                    t = _clock()
                    sc.set_expression(e)
                    ew, ec = _since(t)
                    rec["expressions"].append({"wall_s": ew, "cpu_s": ec})
                    for f in e.frames:
                        t = _clock()
                        out, _ = sc.render(f, tmp)
                        fw, fc = _since(t)
                        rows["frames"].append({"frame": f.frame_id, "identity": int(ident.identity_index), "wall_s": fw,
                                               "cpu_s": fc, "cycles_s": out["render_seconds"],
                                               "cycles_cpu_s": out.get("render_cpu_seconds")})
                        print(f"{f.frame_id}: {fw:.2f} s ({fc:.2f} s CPU)", file=sys.stderr)
                sc.close()
                rows["identities"].append(rec)
                print(f"identity {rec['identity']}: build {bw:.2f} s ({bc:.2f} s CPU)", file=sys.stderr)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(rows, indent=1))
    print(f"wrote {args.out}")


def _summary(d: dict) -> dict:
    import numpy as np

    ids = d["identities"]
    ex = [e for r in ids for e in r["expressions"]]
    return {"build_s": np.mean([r["build_s"] for r in ids]), "build_cpu_s": np.mean([r["build_cpu_s"] for r in ids]),
            "expr_s": np.mean([e["wall_s"] for e in ex]), "expr_cpu_s": np.mean([e["cpu_s"] for e in ex]),
            "frames": len(d["frames"]), "identities": len(ids), "expressions": len(ex)}


def compare(args) -> None:
    import numpy as np

    a, b = (json.loads(Path(p).read_text()) for p in (args.before, args.after))
    fa = {f["frame"]: f for f in a["frames"]}
    fb = {f["frame"]: f for f in b["frames"]}
    keys = sorted(set(fa) & set(fb))
    sa, sb = _summary(a), _summary(b)
    E, V = args.expressions_per_identity, args.views_per_expression
    print(f"\n### Cost per frame at `{a['preset']}`: {a['commit']} -> {b['commit']} ({len(keys)} paired frames of "
          f"{sa['identities']} identities, seed {a['seed']})\n")
    print("| | before | after | after / before |\n|---|---:|---:|---:|")

    def row(name, x, y, fmt=".2f"):
        print(f"| {name} | {x:{fmt}} | {y:{fmt}} | {y / x:.3f} |")

    for k, name in (("wall_s", "render, wall s / frame"), ("cpu_s", "render, CPU s / frame"),
                    ("cycles_s", "Cycles' render call, wall s / frame")):
        x = np.array([fa[f][k] for f in keys])
        y = np.array([fb[f][k] for f in keys])
        row(name, x.mean(), y.mean())
        if k == "cpu_s":
            print(f"| render, CPU: paired ratio (median, min, max) | | | {np.median(y / x):.3f} "
                  f"({(y / x).min():.3f}-{(y / x).max():.3f}) |")
    row("scene build, wall s / identity", sa["build_s"], sb["build_s"])
    row("scene build, CPU s / identity", sa["build_cpu_s"], sb["build_cpu_s"])
    row("expression change, wall s", sa["expr_s"], sb["expr_s"])
    row("expression change, CPU s", sa["expr_cpu_s"], sb["expr_cpu_s"])
    for label, e_per_id, v_per_e in (("this run", sa["expressions"] / sa["identities"], sa["frames"] / sa["expressions"]),
                                     (f"a default dataset ({E} x {V})", E, V)):
        tot = []
        for s, fr in ((sa, fa), (sb, fb)):
            render = np.mean([fr[f]["cpu_s"] for f in keys])
            tot.append(render + s["expr_cpu_s"] / v_per_e + s["build_cpu_s"] / (e_per_id * v_per_e))
        row(f"all of it, CPU s / frame, {label}", tot[0], tot[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out")
    r.add_argument("--identities", type=int, default=4)
    r.add_argument("--expressions", type=int, default=2)
    r.add_argument("--views", type=int, default=2)
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--preset", default="preview")
    r.add_argument("--label", default=None, help="what the tree is (default: its git commit)")
    r.set_defaults(run=run)
    c = sub.add_parser("compare")
    c.add_argument("before")
    c.add_argument("after")
    c.add_argument("--expressions-per-identity", type=int, default=13)
    c.add_argument("--views-per-expression", type=int, default=30)
    c.set_defaults(run=compare)
    a = ap.parse_args()
    a.run(a)


if __name__ == "__main__":
    main()
