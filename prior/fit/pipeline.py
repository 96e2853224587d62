"""``synth prior fit``: few-shot reconstruction of a face from 1-3 images (Cafca Sec. 3.3).

1. read the images and their landmarks (:mod:`prior.fit.inputs`), check them and the prior run;
2. fit the head model and the cameras to the landmarks (:func:`prior.fit.landmarks_fit.fit_landmarks`:
   shared identity beta, one expression code and jaw/eye pose per image, cameras with a shared
   fitted focal length; head at rest in the model frame, the frame the prior was trained in);
3. warm-up inversion of ``w`` at the prior's resolution (:mod:`prior.fit.invert`);
4. fine-tuning of every network parameter and ``w`` at the inputs' resolution (:mod:`prior.fit.finetune`);
5. write the fit directory (:mod:`prior.fit.fitdir`) atomically.

``pretrained=False`` runs the same steps from a randomly initialised field of the prior's
configuration (the "no pre-training" baseline of the paper's Table 2 a.i). Ray bounds are the
prior's scene sphere (it holds every training identity's bounding sphere, in the model frame).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import torch

from prior.fit import config as fit_config
from prior.fit import fitdir
from prior.fit.finetune import finetune
from prior.fit.inputs import observations, read_inputs, resolve_source
from prior.fit.invert import check_patch_size, invert_latent, whole_l1
from prior.fit.views import ViewSet, face_region, prior_resolution
from prior.precision import resolve_bf16
from synth.errors import SynthError
from synth.io import atomic_dir, atomic_write_bytes, atomic_write_json


def load_prior(run) -> "object":
    """The newest checkpoint of a prior run (or a checkpoint file)."""
    from prior.train.checkpoint import latest, load

    run = Path(run)
    path = run if run.is_file() else latest(run)
    if path is None:
        raise SynthError("no prior checkpoint here", str(run), "pass the --out directory of synth prior train")
    return load(path)


def head_model(model_path=None) -> tuple[object, str]:
    """The head model to fit (None = the embedded default) and the sha256 of its file."""
    from synth.io import sha256_file
    from synth.model.default import default_model_path
    from synth.model.format import read_model

    p = Path(model_path) if model_path is not None else default_model_path()
    return read_model(p), sha256_file(p)


def check_head_model(model, sha256: str, ck, where: str) -> None:
    """The prior must have been trained on frames of this head model: same code sizes and joints,
    and (when the checkpoint records it) the same model name and file hash."""
    lay, rec = ck.layout, ck.head_model or {}
    fix = "fit with the head model the prior's dataset was rendered with (--model PATH; default: the embedded one)"
    trained = f"'{rec.get('name') or '?'}'"
    missing = [j for j in lay.joints if j not in model.joint_names]
    if (model.identity_dims, model.expression_dims) != (lay.identity_size, lay.expression_size) or missing:
        raise SynthError(f"the prior was trained on head model {trained} (identity {lay.identity_size}, expression "
                         f"{lay.expression_size}, joints {', '.join(lay.joints)}); head model '{model.name}' has "
                         f"identity {model.identity_dims}, expression {model.expression_dims}"
                         + (f" and lacks joint(s) {', '.join(missing)}" if missing else ""), where, fix)
    if rec.get("name") and rec["name"] != model.name:
        raise SynthError(f"the prior was trained on head model {trained}, not '{model.name}'", where, fix)
    if rec.get("sha256") and rec["sha256"] != sha256:
        raise SynthError(f"the prior was trained on another file of head model {trained} (sha256 "
                         f"{str(rec['sha256'])[:12]}..., this one {sha256[:12]}...)", where, fix)


def codes_from_fit(fit, model, layout) -> np.ndarray:
    """(N, C) conditioning codes beta || expression || joint rotations (the layout's joints)."""
    jidx = [list(model.joint_names).index(j) for j in layout.joints]
    N = fit.expression.shape[0]
    parts = [np.broadcast_to(fit.identity, (N, fit.identity.size)), fit.expression,
             fit.joint_rotations[:, jidx, :].reshape(N, -1)]
    return np.concatenate(parts, 1).astype(np.float32)


def exif_focal_init(inputs) -> np.ndarray | None:
    """(N,) initial focal lengths (canvas pixels) from the inputs' EXIF; an image without one takes
    the median of the others'; None when no input has one."""
    known = [im.focal_px for im in inputs if im.focal_px is not None]
    if not known:
        return None
    return np.array([float(np.median(known)) if im.focal_px is None else im.focal_px for im in inputs])


def fitted_face_centre(fit, model) -> np.ndarray:
    """Centroid of the fitted head's ibug68 landmarks (first image's expression), in the fit's frame."""
    from synth.model.head import HeadModel

    X = HeadModel(model, np.float64).landmarks(fit.identity, fit.expression[0], fit.joint_rotations[0])
    return np.asarray(X, np.float64).reshape(-1, 3).mean(0)


def _progress(log):
    marks: dict[str, int] = {}

    def report(stage, step, total, rec):
        k = max(1, total // 10)
        if step == total or step // k != marks.get(stage, -1):
            marks[stage] = step // k
            extra = f"  psnr {rec['psnr']:.2f} dB" if "psnr" in rec else ""
            log(f"{stage} {step}/{total}  loss {rec['loss']:.4g}{extra}")
    return report


def landmark_fit(inputs, source: str, model, cfg, log=print):
    """Step 2: the inputs' landmarks (``source``: json, mediapipe or dlib; photos get their masks) and the
    head model and cameras fitted to them, with the config's landmark options (EXIF focal lengths
    as the initial focal length, or a known ``landmarks.focal_px``): the observations and the fit."""
    from prior.fit.landmarks_fit import FitOptions, fit_landmarks

    lm = cfg.landmarks
    obs = observations(inputs, source, model, sigma_px=lm.sigma_px, noise_px=lm.noise_px, seed=cfg.fit.seed)
    if lm.focal_px > 0:
        W, H = inputs[0].size
        obs.K = np.broadcast_to(np.array([[lm.focal_px, 0, W / 2], [0, lm.focal_px, H / 2], [0, 0, 1.0]]),
                                (len(inputs), 3, 3)).copy()
    elif lm.exif_focal:
        obs.focal_init = exif_focal_init(inputs)
        if obs.focal_init is not None:
            log(f"initial focal length from EXIF: {', '.join(f'{f:.1f}' for f in obs.focal_init)} px")
    return obs, fit_landmarks(model, obs, FitOptions(per_image_expression=lm.per_image_expression,
                                                     focal_init_fov_deg=lm.fov_init_deg))


def fit_face(images, prior_run, out, *, landmarks: str = "auto", preset: str | None = None, config_path=None,
             sets=(), steps: int | None = None, pretrained: bool = True, model_path=None, device="cpu",
             log=print) -> Path:
    """Fit a face to ``images`` with the prior in ``prior_run``; write the fit directory ``out``."""
    from prior.train.setup import build_model, fit_scene

    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SynthError("fit output exists", str(out), "choose a new --out (a fit is never overwritten)")
    cfg = fit_config.load(preset or "small", config_path, sets)
    if steps is not None:
        if steps < 0:
            raise SynthError(f"--steps {steps} must be >= 0", "--steps", "pass a number of fine-tuning steps")
        cfg = dataclasses.replace(cfg, finetune=dataclasses.replace(cfg.finetune, steps=int(steps)))
    ck = load_prior(prior_run)
    model, model_sha = head_model(model_path)
    check_head_model(model, model_sha, ck, str(ck.path))
    inputs = read_inputs(images, cfg.fit.max_side_px)
    prior_wh = tuple(int(x) for x in ck.identities.front_size[0])
    low_wh = prior_resolution(*inputs[0].size, prior_wh, cfg.inversion.resolution_factor)
    check_patch_size(cfg.inversion, (low_wh[1], low_wh[0]))
    source = resolve_source(inputs, landmarks)
    if source == "mediapipe":
        from prior.fit.landmark_sources import require_mediapipe

        require_mediapipe()
    elif source == "dlib":
        from prior.fit.landmark_sources import require_dlib

        require_dlib()
    times = {}
    t0 = time.perf_counter()
    obs, fit = landmark_fit(inputs, source, model, cfg, log)
    times["landmarks_s"] = time.perf_counter() - t0
    log(f"landmarks: {source}, {len(inputs)} images, rmse {', '.join(f'{r:.2f}' for r in fit.rmse_px)} px, "
        f"focal {fit.K[0, 0, 0]:.1f} px, converged {fit.converged}")

    codes = codes_from_fit(fit, model, ck.layout)
    face_centre = fitted_face_centre(fit, model)
    scene = fit_scene(ck.config, ck.identities.centre, ck.identities.radius).model
    centre, radius = np.asarray(scene.scene_center, np.float64), float(scene.scene_radius)
    c2w = np.linalg.inv(fit.world_to_camera)
    W, H = inputs[0].size
    points = [np.where(obs.used[i][:, None], obs.mean[i], np.nan) for i in range(len(inputs))]
    faces = np.stack([face_region(p, W, H, cfg.fit.face_grow) for p in points])
    views = ViewSet(np.stack([im.target for im in inputs]).astype(np.float32), fit.K, c2w, codes, centre, radius,
                    faces)
    dev = torch.device(device)
    net = build_model(ck.config, ck.layout.size, len(ck.identities.identity_index), dev)
    if pretrained:
        net.load_state_dict(ck.model_state)
    w0 = net.codebook.mean_latent()

    t0 = time.perf_counter()
    low = views.resized(*low_wh)
    report = _progress(log)
    w, inv_hist = invert_latent(net, low, w0, cfg.inversion, seed=cfg.fit.seed, device=dev, progress=report)
    times["inversion_s"] = time.perf_counter() - t0
    inv_whole = [whole_l1(net, low, w0, device=dev, chunk=cfg.fit.render_chunk),
                 whole_l1(net, low, w, device=dev, chunk=cfg.fit.render_chunk)] if inv_hist else []
    if inv_whole:
        log(f"inversion: L1 over the whole {low.size[1]}x{low.size[0]} input(s) "
            f"{inv_whole[0]:.4g} -> {inv_whole[1]:.4g}")
    t0 = time.perf_counter()
    bf16, bf16_line = resolve_bf16(cfg.finetune.bf16, dev, "finetune.bf16")
    log(bf16_line)
    w, ft_hist = finetune(net, views, w, cfg.finetune, seed=cfg.fit.seed, device=dev, progress=report)
    times["finetune_s"] = time.perf_counter() - t0

    info = {"format": fitdir.FORMAT, "pretrained": bool(pretrained),
            "prior": {"run": str(Path(prior_run).resolve()), "checkpoint": str(ck.path.resolve()), "step": ck.step,
                      "head_model": ck.head_model},
            "head_model": {"name": model.name, "sha256": model_sha,
                           "path": None if model_path is None else str(Path(model_path).resolve())},
            "config": cfg.to_dict(), "landmark_source": source, "inputs": [im.record() for im in inputs],
            "masks": [im.mask_source for im in inputs],
            "landmarks_2d": [[None if not np.isfinite(q).all() else [round(float(q[0]), 3), round(float(q[1]), 3)]
                              for q in p] for p in points],
            "face_pixels": [int(f.sum()) for f in faces],
            "model_landmarks_2d": np.round(fit.landmarks_2d, 3).tolist(),
            "cameras": [{"K": fit.K[i].tolist(), "world_to_camera": fit.world_to_camera[i].tolist(),
                         "camera_to_world": c2w[i].tolist(), "width": inputs[i].size[0],
                         "height": inputs[i].size[1]} for i in range(len(inputs))],
            "layout": ck.layout.to_dict(), "codes": codes.tolist(), "identity": fit.identity.tolist(),
            "bounds": {"centre": centre.tolist(), "radius": radius}, "face_centre": face_centre.tolist(),
            "prior_size": list(prior_wh),
            "inversion_size": [low.size[1], low.size[0]]}
    rep = {"landmarks": {"source": source, "rmse_px": fit.rmse_px.tolist(), "converged": fit.converged,
                         "iterations": fit.iterations, "energy": fit.energy, "focal_px": float(fit.K[0, 0, 0])},
           "inversion": inv_hist, "inversion_whole_l1": inv_whole, "finetune": ft_hist, "finetune_bf16": bf16,
           "times": times}
    weights = fitdir.weights_bytes(net, w, ck.config, ck.layout)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_dir(out) as tmp:
        atomic_write_bytes(tmp / fitdir.WEIGHTS_FILE, weights)
        atomic_write_json(tmp / fitdir.FIT_FILE, info)
        atomic_write_json(tmp / fitdir.REPORT_JSON, rep)
        atomic_write_bytes(tmp / fitdir.REPORT_MD, report_markdown(info, rep).encode("utf-8"))
    log(f"wrote {out}")
    return out


def report_markdown(info: dict, rep: dict) -> str:
    lm, t = rep["landmarks"], rep["times"]
    inv, ft = rep["inversion"], rep["finetune"]
    lines = [f"# Fit of {len(info['inputs'])} image(s)", "",
             f"- prior: `{info['prior']['checkpoint']}` (step {info['prior']['step']}); "
             f"{'pretrained' if info['pretrained'] else 'randomly initialised (no pre-training)'}",
             f"- head model: {info['head_model']['name']}; landmarks: {lm['source']}; masks: {', '.join(info['masks'])}",
             f"- landmark fit: rmse {', '.join(f'{r:.2f}' for r in lm['rmse_px'])} px, focal {lm['focal_px']:.1f} px, "
             f"converged {lm['converged']}, iterations {lm['iterations']}",
             f"- inversion at {info['inversion_size'][1]}x{info['inversion_size'][0]}: {len(inv)} steps"
             + (f", L1 over the whole input(s) {rep['inversion_whole_l1'][0]:.4g} -> {rep['inversion_whole_l1'][1]:.4g}"
                f" (the steps' random patches: {inv[0]['loss']:.4g} first, {inv[-1]['loss']:.4g} last)"
                if inv and rep.get("inversion_whole_l1") else ""),
             f"- fine-tuning: {ft[-1]['step'] if ft else 0} steps"
             + (f", loss {ft[0]['loss']:.4g} -> {ft[-1]['loss']:.4g}, training-ray PSNR {ft[-1]['psnr']:.2f} dB"
                if ft else ""),
             f"- times: landmarks {t['landmarks_s']:.1f} s, inversion {t['inversion_s']:.1f} s, "
             f"fine-tuning {t['finetune_s']:.1f} s", "", "| input | size | kind |", "|---|---|---|"]
    lines += [f"| `{r['path']}` | {r['width']}x{r['height']} | {r.get('key', r['kind'])} |" for r in info["inputs"]]
    return "\n".join(lines) + "\n"
