"""Head shapes of planned identities against adult anthropometric ranges (docs/realism.md, "Head shapes").

    .venv/bin/python -m benchmarks.head_shapes [--identities 2000] [--seed 0] [--figure docs/head_shapes.png]

For the first ``--identities`` planned identities (the plan's code path:
``synth.plan.identities.planned_codes``), without the head-shape rule (``identity.head_shape =
'none'``, the sampler before it) and with the default config, measures the neutral heads
(``synth.plan.head_shapes``: head breadth and length, face height and width, cephalic and facial
index) and prints a Markdown table: the adult reference, percentiles 0.1 / 1 / 50 / 99 / 99.9,
min and max, and the share of heads outside the configured range, before and after. With
``--figure``, silhouettes (front and side, matplotlib, no Blender) of the identities whose first
draw lies farthest outside the ranges, as drawn and as the plan now has them.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

#: Adult reference: ANSUR II (Gordon et al. 2014, "2012 Anthropometric Survey of U.S. Army Personnel:
#: Methods and Summary Statistics", NATICK/TR-15/007), the public data set's 6,068 adults (4,082 men,
#: 1,986 women) pooled, since a plan has no sex: mean, SD, smallest, largest (mm). The indices are
#: not in the survey's tables; their entry is the ratio of the means.
ANSUR2 = {
    "head_breadth_mm": ("head breadth (eu-eu)", 152.18, 6.24, 131.0, 180.0),
    "head_length_mm": ("head length (g-op)", 196.33, 8.49, 168.0, 225.0),
    "face_height_mm": ("face height (sellion-menton)", 119.52, 7.88, 91.0, 156.0),
    "face_width_mm": ("face width (zy-zy)", 139.72, 7.31, 116.0, 174.0),
    "cephalic_index": ("cephalic index", 100.0 * 152.18 / 196.33, None, None, None),
    "facial_index": ("facial index", 100.0 * 119.52 / 139.72, None, None, None),
}
PERCENTILES = (0.1, 1.0, 50.0, 99.0, 99.9)


def planned(model, cfg, seed: int, n: int, rule: bool) -> np.ndarray:
    from synth.plan import identities

    c = cfg if rule else dataclasses.replace(cfg, head_shape="none")
    return identities.planned_codes(seed, np.arange(n), model, c)


def table(before: dict, after: dict, bounds: dict) -> str:
    from synth.plan.head_shapes import NAMES

    head = ["measure", "adults (ANSUR II)", "range kept", "sampler",
            *[f"p{p:g}" for p in PERCENTILES], "min", "max", "outside"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for n in NAMES:
        label, mean, sd, lo, hi = ANSUR2[n]
        ref = f"{mean:.1f}" + (f" ± {sd:.1f} ({lo:.0f}-{hi:.0f})" if sd is not None else " (at the means)")
        for which, m in (("before", before), ("after", after)):
            v = m[n]
            out = float(np.mean((v < bounds[n][0]) | (v > bounds[n][1]))) * 100.0
            cells = [label if which == "before" else "", ref if which == "before" else "",
                     f"{bounds[n][0]:g}-{bounds[n][1]:g}" if which == "before" else "", which,
                     *[f"{x:.1f}" for x in np.percentile(v, PERCENTILES)], f"{v.min():.1f}", f"{v.max():.1f}",
                     f"{out:.2f} %"]
            rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def figure(model, first: np.ndarray, final: np.ndarray, ids: np.ndarray, excess: np.ndarray, path: Path,
           count: int = 4) -> list[int]:
    """Front and side silhouettes of the ``count`` identities with the largest ``excess`` of their
    first draw: top row as drawn, bottom row as planned. Returns the identity indices shown."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    from synth.model.head import HeadModel
    from synth.plan.head_shapes import measure_codes

    pick = [int(i) for i in np.argsort(-excess, kind="stable")[:count]]
    hm = HeadModel(model, np.float64)
    shoulders = set(np.asarray(model.regions.get("shoulders", []), np.int64).tolist())
    tri = np.array([t for t in model.triangles.tolist() if not shoulders.intersection(t)], np.int64)

    def verts(code):
        return hm.evaluate(code, np.zeros(model.expression_dims), np.zeros((hm.J, 3)), landmarks=False).vertices[0]

    fig, axes = plt.subplots(2, 2 * count, figsize=(2.0 * count * 2, 5.0))
    for col, j in enumerate(pick):
        for row, code in enumerate((first[j], final[j])):
            v = verts(code)
            m = {n: float(x[0]) for n, x in measure_codes(model, code[None]).items()}
            notes = (f"B {m['head_breadth_mm']:.0f} L {m['head_length_mm']:.0f} CI {m['cephalic_index']:.0f}",
                     f"FH {m['face_height_mm']:.0f} FW {m['face_width_mm']:.0f} FI {m['facial_index']:.0f}")
            for k, (a, b, name) in enumerate(((0, 2, "front"), (1, 2, "side"))):
                ax = axes[row, 2 * col + k]
                ax.add_collection(PolyCollection(v[tri][:, :, [a, b]], facecolors="0.25", edgecolors="0.25", linewidths=0.3))
                ax.set_xlim(-0.13, 0.13) if a == 0 else ax.set_xlim(-0.2, 0.08)
                ax.set_ylim(0.56, 0.88)
                ax.set_xlabel(notes[k], fontsize=6.5)
                ax.set_aspect("equal")
                ax.set_xticks([])
                ax.set_yticks([])
                if row == 0:
                    ax.set_title(f"id {int(ids[j])} {name}", fontsize=8)
        axes[0, 2 * col].set_ylabel("drawn" if col == 0 else "", fontsize=8)
        axes[1, 2 * col].set_ylabel("planned" if col == 0 else "", fontsize=8)
    fig.suptitle("identities farthest outside the adult ranges: first draw (top), planned (bottom); B/L head breadth/"
                 "length, FH/FW face height/width (mm), CI/FI cephalic/facial index", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [int(ids[j]) for j in pick]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--identities", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--figure", type=Path, default=None)
    a = ap.parse_args(argv)
    from synth.config import load_config
    from synth.model.default import load_default_model
    from synth.plan import head_shapes as hs

    model = load_default_model()
    cfg = load_config().identity
    bounds = hs.bounds_of(cfg)
    sets = hs.measure_sets(model)
    first = planned(model, cfg, a.seed, a.identities, rule=False)
    final = planned(model, cfg, a.seed, a.identities, rule=True)
    before, after = hs.measure_codes(model, first, sets), hs.measure_codes(model, final, sets)
    template = hs.measure(model.template, sets)
    print(f"{a.identities} planned identities, seed {a.seed}, neutral heads; outside any range: "
          f"before {100.0 * float(np.mean(~hs.inside(before, bounds))):.1f} %, "
          f"after {100.0 * float(np.mean(~hs.inside(after, bounds))):.1f} %; "
          f"redrawn {100.0 * float(np.mean(np.any(first != final, axis=1))):.1f} %\n")
    print("template: " + ", ".join(f"{n} {float(template[n]):.1f}" for n in hs.NAMES) + "\n")
    print(table(before, after, bounds))
    if a.figure is not None:
        shown = figure(model, first, final, np.arange(a.identities), hs.excess(before, bounds), a.figure)
        print(f"\nfigure: {a.figure} (identities {shown})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
