"""Garment neckline smoothness and build time (docs/realism-eyes-garments.md, "Necklines").

    .venv/bin/python benchmarks/necklines.py [--worst 8]

Builds every garment id of ``tests/assets/test_fit_shells.py`` (same parameter variants, same
schedule: each hard case built, then the expression changed and ``FittedShell.follow`` run) and
measures every neckline loop (``FittedShell.edge_loops``: the torso shells' boundary loops off
the hem) with :func:`synth.assets.fit.hem.turning_angles`. Prints, per garment id: the build
time (mean over the 5 cases, fit included), the ``follow`` time (mean over the 4 expression
changes), the numbers of neckline loops per build seen (the designed openings: 1 per torso
shell, 2 with an undershirt; a tank top 3), the worst turning angle, and how far the worst
neckline vertex lies outside its rim tube (``FittedShell.rims``; the test's measure, negative:
inside); overall the fraction of loop vertices turning more than 30 degrees; then the
``--worst`` worst loops with their case.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

LIMIT = 30.0


def measure(worst_n: int = 8) -> dict:
    from synth.assets.fit.body import Body, fit_shell
    from synth.assets.fit.garment import CLEARANCE, garment_shell
    from synth.assets.fit.hem import turning_angles
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from tests.assets.test_fit_shells import GARMENTS, SCHEDULE, _rim_cover
    from tests.support import asset_scene

    hm = HeadModel(load_default_model())
    per: dict = {}
    spikes = []
    sharp = total = 0
    for k, (a, b) in enumerate(SCHEDULE):
        ctx = asset_scene.head_arrays(hm, a, resolution=256)
        body = Body.of(ctx)
        body.hem  # noqa: B018 -- computed once per body, not part of any garment's time
        shells = []
        for aid, variants in GARMENTS.items():
            t0 = time.perf_counter()
            s = fit_shell(body, garment_shell(body, {"id": aid, "params": variants[k % len(variants)]},
                                              ctx.rng("garment")), CLEARANCE)
            dt = time.perf_counter() - t0
            shells.append((aid, s))
            per.setdefault(aid, {"time": [], "follow": [], "loops": [], "worst": 0.0, "rim": None})["time"].append(dt)
        stages = [(a, "build", [(aid, s, s.P) for aid, s in shells])]
        if b != a:
            asset_scene.set_case_arrays(ctx, hm, b)
            items = []
            for aid, s in shells:
                t0 = time.perf_counter()
                items.append((aid, s, s.follow(ctx.vertices, ctx.data.triangles)))
                per[aid]["follow"].append(time.perf_counter() - t0)
            stages.append((b, "update", items))
        for case, stage, items in stages:
            for aid, s, v in items:
                r = per[aid]
                r["loops"].append(len(s.edge_loops))
                for rim in s.rims:
                    r["rim"] = max(r["rim"] if r["rim"] is not None else -1.0, float(_rim_cover(v, rim).max()))
                for lo in s.edge_loops:
                    t = turning_angles(v[lo])
                    sharp += int((t > LIMIT).sum())
                    total += len(t)
                    j = int(np.argmax(t))  # the turn at vertex lo[j + 1]
                    r["worst"] = max(r["worst"], float(t[j]))
                    spikes.append((float(t[j]), aid, case, stage, len(lo), v[lo[(j + 1) % len(lo)]].round(3).tolist()))
    spikes.sort(reverse=True)
    return {"per": per, "sharp": sharp, "total": total, "spikes": spikes[:worst_n]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worst", type=int, default=8)
    args = ap.parse_args()
    res = measure(args.worst)
    print("| garment | build s (mean of 5) | follow s (mean of 4) | loops per build | worst turning angle "
          "| worst neckline vertex outside its rim |")
    print("|---|---:|---:|---:|---:|---:|")
    for aid, r in res["per"].items():
        lo = "/".join(map(str, sorted(set(r["loops"]))))
        rim = "no rim" if r["rim"] is None else f"{1000 * r['rim']:.2f} mm"
        print(f"| {aid} | {np.mean(r['time']):.2f} | {np.mean(r['follow']):.2f} | {lo} | {r['worst']:.1f}° | {rim} |")
    print(f"\nneckline vertices turning > {LIMIT:.0f}°: {res['sharp']} of {res['total']} "
          f"({100 * res['sharp'] / max(res['total'], 1):.2f} %)")
    print("worst loops (angle, garment, case, stage, loop length, vertex position):")
    for s in res["spikes"]:
        print("  ", f"{s[0]:.1f}", *s[1:])


if __name__ == "__main__":
    main()
