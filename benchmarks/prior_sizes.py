"""Does more data help? The paper's dataset-size ablation (Cafca Table 2 a.i-a.iv: no pre-training,
1, 15 and 1,500 subjects) at this machine's scale, on ``benchmarks/prior_claim.py``'s pipeline.

    .venv/bin/python benchmarks/prior_sizes.py all --work W [--profile cpu|tiny] [--figure docs/prior_sizes.png]
    .venv/bin/python benchmarks/prior_sizes.py render|train|report --work W [...]          # one stage
    .venv/bin/python benchmarks/prior_sizes.py fit --work W --rungs 1,15 --wait            # fits, as priors finish

Stages (each resumable: finished outputs are kept and skipped):

1. render: prior_claim's training set of the largest rung's identities (the rungs are its first
   identities) and its synthetic held-out test set (fixed cameras: inputs at 0 and +-45 degrees,
   6 held-out views); then the ICT-FaceKit test set in ``W/ict``: the sample in ``--ict`` imported
   with ``synth model import ict-facekit``, planned with that model (neutral expression) and every
   identity code replaced by a one-hot code (scene k is the sample's ``identity00k.obj`` head;
   identity indices after the synthetic test ones, so no scene shares a training identity's
   assets), the same fixed cameras, rendered the same way. The ICT model is read by the benchmark
   only; the priors and fits use the embedded head model.
2. train: one prior per rung, prior_claim's ``train`` (same steps for every rung).
3. fit: every prior (0 = no pre-training, from the largest rung's configuration) on every test
   scene of both sets, from 3 and from 1 input views, evaluated on the 6 held-out views
   (prior_claim's ``fit``). ``--rungs`` and ``--views`` pick rows (several processes can share the fits);
   a prior still training is skipped, or waited for with ``--wait``.
4. report: per set, prior size and view count the mean PSNR/SSIM/LPIPS in the face mask and the
   per-scene PSNRs (markdown, ``W/sizes.json``); the plot with ``--figure``.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import prior_claim as pc  # noqa: E402

PROFILES = {
    # the run in docs/prior.md: 600 training frames (60 identities x 2 expressions x 5 views at 32^2),
    # prior_claim's cpu training (1,000 steps of 256 rays) and fitting settings
    "cpu": dict(pc.PROFILES["cpu"], rungs=[1, 15, 60], expressions=2, views=5, test_ids=3, ict_ids=3),
    # a few minutes end to end: checks the script, proves nothing
    "tiny": dict(pc.PROFILES["tiny"], rungs=[1, 2], expressions=1, views=4, test_ids=1, ict_ids=1),
}
VIEW_COUNTS = (3, 1)
SETS = ("synthetic", "ict")
METRICS = ("psnr", "ssim", "lpips")
ICT_DEFAULT = Path(os.environ.get("SYNTH_ICT_FACEKIT_DIR", Path(__file__).resolve().parents[2] / "shared" /
                                  "ict-facekit"))


def set_dir(work: Path, name: str) -> Path:
    """The directory prior_claim's fit works in for a test set: ``W`` itself, or ``W/ict`` (its own
    ``ds_test`` and ``fits``, ``runs`` linked to ``W/runs``)."""
    return work if name == "synthetic" else work / name


def rows(p: dict, rungs=None, views=None) -> list[tuple[str, int, int]]:
    """(name, rung, views) of prior_claim's fit rows; rung 0 (no pre-training) runs from the largest
    rung's configuration. 3-view rows first: a run cut short has them for every prior."""
    big = max(p["rungs"])
    out = []
    for v in [v for v in VIEW_COUNTS if views is None or v in views]:
        for n in [0, *p["rungs"]]:
            if rungs is None or n in rungs:
                out.append((f"none_views{v}" if n == 0 else f"ids{n}_views{v}", n or big, v))
    return out


def rung_of(name: str) -> int:
    return 0 if name.startswith("none") else int(name[3:].split("_")[0])


# --------------------------------------------------------------------------- render


def one_hot_plan(src: Path, dst: Path) -> None:
    """``src`` (a plan) with identity k's code replaced by the one-hot code on dimension k (the
    model's ``identity_k``; k counted from the plan's first identity) and its look-at target
    recomputed for that head the planner's way (``camera.target``)."""
    from synth.model.format import read_model
    from synth.plan import io
    from synth.plan.identities import look_at_targets
    from synth.plan.planner import _rn

    plan = io.load_plan(src)
    model = read_model(plan.checked_model_path())
    cam = plan.config["camera"]
    first = plan.header["first_identity"]
    specs = []
    for sid in plan.shard_ids():
        spec = plan.shard(sid)
        for ident in spec["identities"]:
            k = ident["identity_index"] - first
            code = np.zeros(len(ident["identity_code"]))
            code[k] = 1.0
            ident["identity_code"] = _rn(code)
            ident["target"] = _rn(look_at_targets(model, code, cam["target"], cam["target_offset_m"])[0])
        specs.append((sid, spec))
    header = {k: v for k, v in plan.header.items() if k not in ("shards", "plan_hash")}
    summary = json.loads((src / io.SUMMARY_FILE).read_text())
    summary["note"] = "identity codes one-hot (identity k = the model's identity_k) by benchmarks/prior_sizes.py"
    io.write_plan(dst, header, lambda tmp: (io.write_shards(tmp, specs), summary))


def render_ict(work: Path, p: dict, ict: Path, times: pc.Times) -> None:
    if "render_ict" in times.data:
        return
    t0 = time.perf_counter()
    d, n = work / "ict", p["ict_ids"]
    d.mkdir(exist_ok=True)
    if not (d / "runs").exists():
        (d / "runs").symlink_to(Path("..") / "runs")
    pc.log(f"render: ICT-FaceKit test set, {n} heads x 1 x {len(pc.TEST_VIEWS)} at {p['test_res']}^2")
    if not (work / "ict.npz").is_file():
        pc.synth("model", "import", "ict-facekit", ict, "-o", work / "ict.npz")
    if not (d / "plan_test").is_dir():
        tres = f"render.resolution=[{p['test_res']},{p['test_res']}]"
        if not (d / "plan_ict0").is_dir():
            pc.synth("plan", "-n", n, "--start", max(p["rungs"]) + p["test_ids"], "--seed", 1, "--model",
                     work / "ict.npz", "--out", d / "plan_ict0", "--set", "render.preset=\"preview\"", "--set", tres,
                     "--set", "expression.neutral_weight=1", "--set", "expression.preset_weight=0",
                     "--set", "expression.random_weight=0", "--set", "dataset.expressions_per_identity=1",
                     "--set", f"dataset.views_per_expression={len(pc.TEST_VIEWS)}",
                     "--set", "camera.min_separation_deg=0")
        if not (d / "plan_ict1").is_dir():
            one_hot_plan(d / "plan_ict0", d / "plan_ict1")
        pc.fixed_camera_plan(d / "plan_ict1", d / "plan_test")
    pc.synth("render", "--plan", d / "plan_test", "--out", d / "ds_test", "-q")
    times.record("render_ict", t0, frames=n * len(pc.TEST_VIEWS))


# --------------------------------------------------------------------------- fit


def prior_ready(work: Path, n: int, steps: int) -> bool:
    from prior.train.checkpoint import latest, load

    ck = latest(work / "runs" / f"ids{n:03d}")
    return ck is not None and load(ck).step >= steps


def pending(work: Path, rws) -> list:
    """The rows some test scene of some set still lacks an evaluation for."""
    out = []
    for r in rws:
        for s in SETS:
            d = set_dir(work, s)
            if any(not (d / "fits" / r[0] / f"id{i:06d}_ex{e:02d}" / "eval.json").is_file() for i, e in pc.scenes(d)):
                out.append(r)
                break
    return out


def fit(work: Path, p: dict, scale: float, device: str, times: pc.Times, rungs=None, views=None,
        wait: bool = False) -> None:
    """Every row on every scene of both sets, scene by scene (synthetic scene k, then ICT scene k);
    rows whose prior has not finished training are left for a later pass (``wait``) or run."""
    steps = max(1, round(p["train_steps"] * scale))
    t0 = time.perf_counter()
    todo = pending(work, rows(p, rungs, views))
    while todo:
        ready = [r for r in todo if prior_ready(work, r[1], steps)]
        n_scenes = max(len(pc.scenes(set_dir(work, s))) for s in SETS)
        for k in range(n_scenes):
            for s in SETS:
                d = set_dir(work, s)
                if ready and k < len(pc.scenes(d)):
                    pc.fit(d, p, scale, device, times if s == "synthetic" else pc.Times(d), rows=ready, only=[k])
        todo = pending(work, todo)
        if not todo or not wait:
            break
        if not ready:
            pc.log(f"fit: waiting for the priors of {sorted({rung_of(r[0]) for r in todo})} identities")
            time.sleep(60)
    if todo:
        pc.log(f"fit: {len(todo)} rows left: their priors are not trained yet")
    times.record("fit_sizes" + ("" if rungs is None else "_rungs" + "_".join(map(str, rungs)))
                 + ("" if views is None else "_views" + "_".join(map(str, views))), t0)


# --------------------------------------------------------------------------- report


def collect(work: Path, p: dict) -> dict:
    """{set: {row name: {rung, views, scenes, psnr, ssim, lpips, per_scene: {scene: {metric: value}}}}}."""
    out = {}
    for s in SETS:
        res = {}
        for name, rung, nviews in rows(p):
            evs = [json.loads(f.read_text()) for f in sorted((set_dir(work, s) / "fits" / name).glob("*/eval.json"))]
            if not evs:
                continue
            res[name] = {"rung": rung_of(name), "views": nviews, "scenes": len(evs),
                         **{k: float(np.mean([e["mean"][k] for e in evs])) for k in METRICS},
                         "fit_s": float(np.mean([e["times"]["fit_total_s"] for e in evs])),
                         "per_scene": {f"id{e['identity']}": {k: e["mean"][k] for k in METRICS} for e in evs}}
        out[s] = res
    return out


def table(res: dict, p: dict) -> str:
    frames = p["expressions"] * p["views"]
    lines = ["| test set | training identities | training frames | input views | PSNR dB | SSIM | LPIPS | "
             "PSNR per scene |", "|---|---|---|---|---|---|---|---|"]
    for s in SETS:
        for v in VIEW_COUNTS:
            for name, r in res[s].items():
                if r["views"] != v:
                    continue
                per = " / ".join(f"{x['psnr']:.2f}" for x in r["per_scene"].values())
                lines.append(f"| {'ICT-FaceKit' if s == 'ict' else s} | {r['rung'] or 'none'} | "
                             f"{r['rung'] * frames} | {v} | {r['psnr']:.2f} | {r['ssim']:.4f} | {r['lpips']:.4f} | "
                             f"{per} |")
    return "\n".join(lines)


def plot(res: dict, path: Path) -> None:
    """Metric against training identities (log x; no pre-training drawn at 0.5), one line per
    test set and view count, error bars the smallest and largest scene."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(METRICS), figsize=(12, 3.6))
    style = {("synthetic", 3): ("C0", "-"), ("synthetic", 1): ("C0", "--"), ("ict", 3): ("C3", "-"),
             ("ict", 1): ("C3", "--")}
    ticks = set()
    for (s, v), (colour, ls) in style.items():
        pts = sorted((r["rung"], r) for r in res.get(s, {}).values() if r["views"] == v)
        if not pts:
            continue
        x = np.array([n or 0.5 for n, _ in pts], float)
        ticks |= {n for n, _ in pts}
        for ax, m in zip(axes, METRICS):
            y = np.array([r[m] for _, r in pts])
            lo = y - np.array([min(q[m] for q in r["per_scene"].values()) for _, r in pts])
            hi = np.array([max(q[m] for q in r["per_scene"].values()) for _, r in pts]) - y
            ax.errorbar(x * (1.04 if s == "ict" else 0.96), y, yerr=[lo, hi], color=colour, ls=ls, marker="o",
                        ms=4, capsize=2, label=f"{'ICT-FaceKit' if s == 'ict' else 'synthetic'}, {v} view"
                        f"{'s' if v > 1 else ''}")
    for ax, m in zip(axes, METRICS):
        ax.set_xscale("log")
        ax.set_xticks([n or 0.5 for n in sorted(ticks)], [str(n) if n else "none" for n in sorted(ticks)])
        ax.minorticks_off()
        ax.set_xlabel("training identities")
        ax.set_title({"psnr": "PSNR dB (higher is better)", "ssim": "SSIM (higher is better)",
                      "lpips": "LPIPS (lower is better)"}[m], fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("few-shot fits of held-out heads: mean over scenes, bars from the worst to the best scene",
                 fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    pc.log(f"figure: {path}")


def report(work: Path, p: dict, times: pc.Times, figure: Path | None) -> dict:
    res = collect(work, p)
    print(table(res, p))
    summary = {"profile": p, "sets": res, "times": times.data, "ict_times": pc.Times(work / "ict").data}
    pc.atomic_write_json(work / "sizes.json", summary)
    if figure is not None:
        plot(res, figure)
    return summary


def main(argv=None) -> int:
    ap = pc.stage_arguments(__doc__.splitlines()[0], ["all", "render", "train", "fit", "report"], PROFILES)
    ap.add_argument("--ict", type=Path, default=ICT_DEFAULT,
                    help="ICT-FaceKit checkout or sample (default: $SYNTH_ICT_FACEKIT_DIR or ../shared/ict-facekit)")
    ap.add_argument("--rungs", default=None, help="fit: only these priors (training identities, 0 = none; e.g. 1,15)")
    ap.add_argument("--views", default=None, help="fit: only these input view counts (e.g. 3)")
    ap.add_argument("--wait", action="store_true", help="fit: wait for priors still training instead of leaving "
                    "their rows")
    ap.add_argument("--figure", type=Path, default=None, help="report: write the plot here (e.g. docs/prior_sizes.png)")
    a = ap.parse_args(argv)
    p, times = pc.stage_start(a, PROFILES)
    if a.stage in ("all", "render"):
        if not (a.ict / "FaceXModel").is_dir() and not any(a.ict.glob("identity*.obj")):
            raise SystemExit(f"{a.ict}: no ICT-FaceKit sample here (pass --ict DIR)")
        pc.render(a.work, p, times)
        render_ict(a.work, p, a.ict, times)
    if a.stage in ("all", "train"):
        pc.train(a.work, p, a.scale, a.device, times)
    if a.stage in ("all", "fit"):
        rungs = None if a.rungs is None else [int(x) for x in a.rungs.split(",")]
        views = None if a.views is None else [int(x) for x in a.views.split(",")]
        fit(a.work, p, a.scale, a.device, times, rungs=rungs, views=views, wait=a.wait)
    if a.stage in ("all", "report"):
        report(a.work, p, times, a.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
