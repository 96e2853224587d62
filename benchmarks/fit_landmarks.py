"""Head-model and camera fitting to noisy 2D landmarks with known truth: accuracy and time.
Prints the Markdown table of docs/fitting.md.

    .venv/bin/python benchmarks/fit_landmarks.py [--identities 10] [--seed 7] [--noise 1.0]
                                                 [--sets ibug68 dense] [--resolutions 512 1024]

For every identity of the set (prior.fit.synthetic.make_scene: the planner's identity and
expression samplers, 3 cameras at 0 and +-45 degrees azimuth with +-5 degrees jitter, the
default 85 mm lens), landmarks with Gaussian noise of --noise px per axis are fitted three
ways: everything with K known ("fit"), everything with the focal length unknown ("fit, f
unknown"), and the cameras alone for the true codes ("oracle codes": the floor the
landmarks' noise allows). Errors are per camera, relative to the head; the table gives the
maximum and the median over all cameras of all identities.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import torch  # noqa: E402

from prior.fit.head import TorchHeadModel  # noqa: E402
from prior.fit.identity_prior import TorchGMM  # noqa: E402
from prior.fit.landmarks_fit import fit_cameras, fit_landmarks  # noqa: E402
from prior.fit.synthetic import make_scene, scene_errors  # noqa: E402
from synth.model.default import load_default_model  # noqa: E402
from synth.model.head import HeadModel  # noqa: E402


def run(args, model, hm, th, gmm, landmark_set: str, res: int, mode: str) -> dict:
    errs, times, conv = [], [], []
    for i in range(args.identities):
        sc = make_scene(model, args.seed, i, resolution=res, landmark_set=landmark_set, head=hm)
        obs = sc.observations(args.noise, args.seed, i, known_intrinsics=mode != "fit, f unknown",
                              landmark_set=landmark_set)
        t0 = time.perf_counter()
        if mode == "oracle codes":
            fit = fit_cameras(model, obs, sc.identity, sc.expression, sc.joint_rotations, head=th)
        else:
            fit = fit_landmarks(model, obs, head=th, gmm=gmm)
        times.append(time.perf_counter() - t0)
        conv.append(fit.converged)
        errs.append(scene_errors(sc, fit, hm, landmark_set))
    cat = {k: np.concatenate([e[k] for e in errs]) for k in errs[0]}
    return {"errors": cat, "time": float(np.mean(times)), "converged": f"{sum(conv)}/{len(conv)}"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--identities", type=int, default=10)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--noise", type=float, default=1.0)
    ap.add_argument("--sets", nargs="+", default=["ibug68", "dense"])
    ap.add_argument("--resolutions", type=int, nargs="+", default=[512, 1024])
    ap.add_argument("--modes", nargs="+", default=["fit", "fit, f unknown", "oracle codes"])
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = load_default_model()
    hm, th, gmm = HeadModel(model, np.float64), TorchHeadModel(model), TorchGMM.from_model(model)
    print(f"{args.identities} identities (seed {args.seed}), 3 views, noise {args.noise:g} px per axis; "
          f"{platform.machine()}, torch {torch.__version__}, 1 thread\n")
    print("| landmarks | image | fitted | rotation ° max / med | position cm max / med | "
          "scale-free position cm max / med | RMSE px (observed / true) max | converged | s per fit |")
    print("|---|---|---|---|---|---|---|---|---|")
    for ls in args.sets:
        for res in args.resolutions:
            for mode in args.modes:
                r = run(args, model, hm, th, gmm, ls, res, mode)
                e = r["errors"]

                def mm(x, k=1.0):
                    return f"{k * x.max():.2f} / {k * np.median(x):.2f}"
                print(f"| {ls} | {res}² | {mode} | {mm(e['rotation_deg'])} | {mm(e['position_m'], 100)} | "
                      f"{mm(e['position_scale_free_m'], 100)} | {e['rmse_observed_px'].max():.2f} / "
                      f"{e['rmse_true_px'].max():.2f} | {r['converged']} | {r['time']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
