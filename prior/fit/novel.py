"""Novel views of a fitted face (``synth prior render FIT``).

Cameras live in the fit's frame (the head model at rest, where the fitted input cameras are).
Either ``N`` views framed on the head (``head``, the default: :func:`head_cameras`, centred on
the fitted face at the frontal input camera's distance, over +-40 degrees of azimuth by
default), or an orbit of ``N`` views about the vertical axis (world Z) through the ray bounds'
centre, starting at the most frontal input camera, with that camera's fitted intrinsics scaled
to ``size`` x ``size`` (``input``: the photo's own framing); or the views of a ``cameras.json``
(the file ``render`` writes: per view ``K``, ``camera_to_world``, ``width``, ``height`` and
optionally ``key``).

At every view the conditioning code is interpolated from the per-image codes by inverse squared
distance between the view's camera and the input cameras (paper Eq. 8,
:func:`prior.fit.interpolate.interpolate_for_cameras`); ``w`` is the fitted latent. Outputs per
view as :func:`prior.render_views.write_view` (colour, opacity, normals PNGs, depth EXR) plus
``cameras.json`` with the interpolation weights of each view.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from prior.fit.fitdir import FittedFace, load_fit
from prior.fit.interpolate import interpolation_weights
from prior.render_views import orbit, output_dir, render_image, scaled_camera, write_view
from synth.conventions import invert_rigid, orbit_camera_to_world
from synth.errors import SynthError
from synth.io import atomic_write_json


def frontal_index(c2w: np.ndarray, centre: np.ndarray) -> int:
    """The camera nearest the front of the face (synth's heads face -Y: azimuth 0, elevation 0)."""
    d = np.asarray(c2w)[:, :3, 3] - np.asarray(centre)
    az = np.degrees(np.arctan2(d[:, 0], -d[:, 1]))
    el = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
    return int(np.argmin(np.abs(az) + np.abs(el)))


def view_code(fit: FittedFace, c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(code (C,), weights (V,)) of a target camera: Eq. 8 over the input cameras."""
    w = interpolation_weights(np.asarray(c2w)[:3, 3], fit.camera_to_world[:, :3, 3])[0]
    return (w @ fit.codes.astype(np.float64)).astype(np.float32), w


def render_fit_view(fit: FittedFace, K, c2w, width: int, height: int, *, chunk: int = 4096, device="cpu") -> dict:
    code, w = view_code(fit, c2w)
    img = render_image(fit.model, K, c2w, width, height, code, None, fit.centre, fit.radius, chunk=chunk,
                       device=device, latent=fit.latent)
    img["weights"] = w
    return img


def read_cameras(path) -> list[dict]:
    """Views of a cameras.json (as ``synth prior render`` writes it)."""
    p = Path(path)
    fix = "pass a cameras.json as written by synth prior render: {\"views\": [{\"K\", \"camera_to_world\", " \
          "\"width\", \"height\"}, ...]}"
    try:
        views = json.loads(p.read_text(encoding="utf-8"))["views"]
        out = []
        for k, v in enumerate(views):
            K, c2w = np.asarray(v["K"], np.float64), np.asarray(v["camera_to_world"], np.float64)
            W, H = int(v["width"]), int(v["height"])
            if K.shape != (3, 3) or c2w.shape != (4, 4) or W < 1 or H < 1 or not (np.isfinite(K).all()
                                                                                 and np.isfinite(c2w).all()):
                raise ValueError(f"view {k} is malformed")
            out.append({"key": str(v.get("key", f"view{k:03d}")), "K": K, "camera_to_world": c2w, "width": W,
                        "height": H})
    except FileNotFoundError:
        raise SynthError("cameras file not found", str(p), "check the --cameras path") from None
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as e:
        raise SynthError(f"cameras file is malformed ({str(e)[:80]})", str(p), fix) from None
    if not out:
        raise SynthError("cameras file lists no view", str(p), fix)
    return out


def orbit_cameras(fit: FittedFace, n: int, size: int | None) -> list[dict]:
    """The ``input`` framing: the most frontal input camera turned about the vertical axis through
    the ray bounds' centre, 360/n degrees apart, with its intrinsics."""
    i = frontal_index(fit.camera_to_world, fit.centre)
    (W, H), K = fit.size, fit.K[i]
    if size is not None:
        K, W, H = scaled_camera(K, W, H, size), size, size
    return [{"key": f"orbit{k:03d}", "K": K, "camera_to_world": c2w, "width": W, "height": H}
            for k, c2w in enumerate(orbit(fit.camera_to_world[i], fit.centre, n))]


#: the ``head`` framing's defaults: views over +-40 degrees about the frontal input camera, 0.5 m
#: across at the face (the head, hair and neck, as synth's training frames frame them)
HEAD_SPAN_DEG, HEAD_FIELD_M = 80.0, 0.5


def head_cameras(fit: FittedFace, n: int, size: int | None, span_deg: float = HEAD_SPAN_DEG,
                 field_m: float = HEAD_FIELD_M) -> list[dict]:
    """The ``head`` framing: ``n`` views looking at the fitted face's centre (its ibug68 landmarks'
    centroid) from the most frontal input camera's distance and elevation, at azimuths spread evenly
    over ``span_deg`` about that camera's (one view: its azimuth), each with the principal point at
    the image centre and a focal length that makes the image ``field_m`` wide at the face. A photo
    of a person, shoulders and all, is rendered centred on the head, whatever its own framing."""
    target = np.asarray(fit.info["face_centre"], np.float64)
    i = frontal_index(fit.camera_to_world, target)
    d = fit.camera_to_world[i][:3, 3] - target
    dist = float(np.linalg.norm(d))
    az0 = float(np.degrees(np.arctan2(d[0], -d[1])))
    el0 = float(np.degrees(np.arctan2(d[2], np.hypot(d[0], d[1]))))
    W = H = int(size) if size is not None else int(min(fit.size))
    f = W * dist / field_m
    K = np.array([[f, 0.0, W / 2.0], [0.0, f, H / 2.0], [0.0, 0.0, 1.0]])
    azimuths = [az0] if n == 1 else list(np.linspace(az0 - span_deg / 2.0, az0 + span_deg / 2.0, n))
    return [{"key": f"orbit{k:03d}", "K": K, "camera_to_world": orbit_camera_to_world(a, el0, dist, target),
             "width": W, "height": H} for k, a in enumerate(azimuths)]


FRAMINGS = ("head", "input")


def render_fit(fit_dir, out_dir, *, orbit_views: int = 8, size: int | None = None, cameras=None,
               device="cpu", framing: str = "head", span_deg: float | None = None) -> list[Path]:
    """Render novel views of a fit (see the module docstring)."""
    if orbit_views < 1 or (size is not None and size < 1):
        raise SynthError("--orbit and --size must be at least 1", "synth prior render", "pass positive numbers")
    if framing not in FRAMINGS:
        raise SynthError(f"unknown framing {framing!r}", "synth prior render --frame", f"use one of {FRAMINGS}")
    if span_deg is not None and not 0.0 <= span_deg <= 360.0:
        raise SynthError(f"--span {span_deg} is outside 0-360 degrees", "synth prior render", "pass 0 to 360")
    if span_deg is not None and framing == "input":
        raise SynthError("--span sets the head framing's arc; the input framing orbits the full circle",
                         "synth prior render", "drop --span, or use --frame head")
    fit = load_fit(fit_dir, device)
    if cameras is not None:
        views = read_cameras(cameras)
    elif framing == "head":
        views = head_cameras(fit, orbit_views, size, HEAD_SPAN_DEG if span_deg is None else span_deg)
    else:
        views = orbit_cameras(fit, orbit_views, size)
    out_dir = output_dir(out_dir)
    written, cams = [], []
    chunk = fit.render_chunk
    for v in views:
        img = render_fit_view(fit, v["K"], v["camera_to_world"], v["width"], v["height"], chunk=chunk, device=device)
        written += write_view(out_dir, v["key"], img)
        cams.append({"key": v["key"], "K": np.asarray(v["K"]).tolist(),
                     "camera_to_world": np.asarray(v["camera_to_world"]).tolist(), "width": v["width"],
                     "height": v["height"], "expression_weights": img["weights"].tolist(),
                     "world_to_camera": invert_rigid(np.asarray(v["camera_to_world"])).tolist()})
    atomic_write_json(out_dir / "cameras.json", {"fit": str(Path(fit_dir)), "views": cams})
    return written + [out_dir / "cameras.json"]
