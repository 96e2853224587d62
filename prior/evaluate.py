"""``synth prior eval FIT --gt DATASET``: novel views of a fitted synth identity against ground truth.

Protocol (docs/prior.md, "Few-shot fitting"):

1. The fit's inputs must be synth frames of one (identity, expression) of DATASET; their true
   cameras (from DATASET's frame JSON, never used by the fit) and the fit's cameras give the
   similarity from the fit's frame to the truth's (:mod:`prior.fit.align`).
2. Held-out views: that (identity, expression)'s other views whose camera lies in the frontal
   hemisphere (|azimuth| <= 90 degrees; the paper's "not on the back of the head"), or the view
   indices given with ``--views``.
3. Each held-out camera is taken into the fit's frame and rendered with the fit's intrinsics
   scaled to the ground-truth image size (the fitted focal length and camera distances come
   together: images fix only their ratio), the expression code interpolated by Eq. 8.
4. PSNR, SSIM and LPIPS (VGG) on the foreground (ground-truth alpha; :mod:`prior.metrics`'s
   masking rule), on sRGB-encoded colour over black; per view and the mean.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prior.data.sources import PRIOR_ENVIRONMENT
from prior.fit.align import align_cameras
from prior.fit.fitdir import load_fit
from prior.fit.novel import render_fit_view
from synth.dataset.layout import parse_frame_key_env
from synth.appearance.srgb import linear_to_srgb
from synth.errors import SynthError

FRONTAL_DEG = 90.0


def _gt_frames(gt, identity: int, expression: int) -> dict[int, object]:
    from synth.dataset.reader import list_frames

    refs = list_frames(gt)
    if not refs:
        raise SynthError("ground-truth dataset has no committed frames", str(gt), "pass a rendered synth dataset")
    out = {}
    for r in refs:
        i, e, k, v = parse_frame_key_env(r.key)
        if (i, e, k) == (identity, expression, PRIOR_ENVIRONMENT):
            out[v] = r
    if not out:
        raise SynthError(f"ground-truth dataset has no frame of identity {identity} expression {expression}",
                         str(gt), "pass the dataset the fit's input frames came from")
    return out


def _azimuth(meta: dict) -> float:
    return float(meta["camera"].get("azimuth_deg", 0.0))


def select_views(refs: dict, inputs: set[int], views) -> list[int]:
    if views is not None:
        missing = [v for v in views if v not in refs]
        if missing:
            raise SynthError(f"view(s) {missing} not in the ground truth (it has {sorted(refs)})", "--views",
                             "pick views of the fitted identity and expression")
        return list(views)
    return [v for v in sorted(refs) if v not in inputs]


def evaluate_fit(fit_dir, gt, *, views=None, device="cpu", save=None, frontal_deg: float = FRONTAL_DEG) -> dict:
    """Render and score held-out views (see the module docstring); returns the table as a dict."""
    from prior import metrics

    fit = load_fit(fit_dir, device)
    recs = fit.info["inputs"]
    if any(r.get("kind") != "frame" for r in recs):
        raise SynthError("the fit's inputs are not synth frames: there is no ground truth to compare with",
                         str(fit_dir), "evaluate fits of synth frames (KEY.exr + KEY.json)")
    pairs = {(r["identity_index"], r["expression_index"]) for r in recs}
    if len(pairs) != 1:
        raise SynthError(f"the fit's inputs show several (identity, expression) pairs {sorted(pairs)}",
                         str(fit_dir), "evaluate fits of one identity and expression")
    (ident, expr), = pairs
    refs = _gt_frames(gt, ident, expr)
    in_views = [r["view_index"] for r in recs]
    lost = [v for v in in_views if v not in refs]
    if lost:
        raise SynthError(f"input view(s) {lost} are not in the ground truth", str(gt),
                         "pass the dataset the fit's input frames came from")
    in_frames = [refs[v].read() for v in in_views]
    face_true = np.asarray(in_frames[0].meta["landmarks_3d"], np.float64).mean(0)
    sim = align_cameras(fit.camera_to_world, np.asarray(fit.info["face_centre"]),
                        np.stack([f.camera_to_world for f in in_frames]), face_true)
    chosen = select_views(refs, set(in_views), views)
    rows = []
    if save is not None:
        Path(save).mkdir(parents=True, exist_ok=True)
    W0, H0 = fit.size
    for v in chosen:
        f = refs[v].read()
        az = _azimuth(f.meta)
        if views is None and abs(az) > frontal_deg:
            continue
        K = np.diag([f.width / W0, f.height / H0, 1.0]) @ fit.K[0]
        c2w = sim.camera_to_source(f.camera_to_world)
        img = render_fit_view(fit, K, c2w, f.width, f.height, chunk=fit.render_chunk,
                              device=device)
        pred, ref = linear_to_srgb(img["rgb"]).astype(np.float32), linear_to_srgb(f.rgba[..., :3]).astype(np.float32)
        mask = np.clip(f.alpha, 0, 1)
        row = {"key": f.key, "view": v, "azimuth_deg": az, "elevation_deg": float(f.meta["camera"].get(
            "elevation_deg", 0.0)), "input": v in in_views, "psnr": float(metrics.psnr(pred, ref, mask)),
            "ssim": float(metrics.ssim(pred, ref, mask)), "lpips": float(metrics.lpips(pred, ref, mask=mask))}
        rows.append(row)
        if save is not None:
            _save_pair(Path(save), f.key, img, ref * mask[..., None])
    if not rows:
        raise SynthError("no held-out view left to evaluate (all are inputs or behind the head)", str(gt),
                         "render more views of the identity, or pass --views")
    mean = {k: float(np.mean([r[k] for r in rows])) for k in ("psnr", "ssim", "lpips")}
    return {"fit": str(fit_dir), "gt": str(gt), "identity": ident, "expression": expr, "input_views": in_views,
            "pretrained": fit.info.get("pretrained", True), "alignment": sim.to_dict(), "views": rows, "mean": mean}


def _save_pair(out: Path, key: str, img: dict, ref_srgb: np.ndarray) -> None:
    from prior.render_views import png_bytes, write_view
    from synth.io import atomic_write_bytes

    write_view(out, f"{key}_pred", img)
    atomic_write_bytes(out / f"{key}_gt.png", png_bytes((np.clip(ref_srgb, 0, 1) * 255 + 0.5).astype(np.uint8)))


def markdown(res: dict) -> str:
    lines = [f"Fit `{res['fit']}` against `{res['gt']}`: identity {res['identity']}, expression {res['expression']}, "
             f"inputs {res['input_views']}; alignment scale {res['alignment']['scale']:.4f}, "
             f"rms {1000 * res['alignment']['rms_m']:.1f} mm", "",
             "| view | azimuth ° | elevation ° | PSNR dB | SSIM | LPIPS |", "|---|---|---|---|---|---|"]
    for r in res["views"]:
        tag = " (input)" if r["input"] else ""
        lines.append(f"| {r['key']}{tag} | {r['azimuth_deg']:.1f} | {r['elevation_deg']:.1f} | {r['psnr']:.2f} | "
                     f"{r['ssim']:.4f} | {r['lpips']:.4f} |")
    m = res["mean"]
    lines.append(f"| **mean of {len(res['views'])}** | | | **{m['psnr']:.2f}** | **{m['ssim']:.4f}** | "
                 f"**{m['lpips']:.4f}** |")
    return "\n".join(lines)
