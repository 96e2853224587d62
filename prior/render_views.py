"""Whole images from a trained prior: previews while training, ``synth prior render`` (novel
views of a training identity), and the evaluation of held-out views.

Outputs per view (``write_view``): ``KEY_colour.png`` (premultiplied colour, i.e. over black,
sRGB-encoded), ``KEY_opacity.png`` (accumulated opacity), ``KEY_normals.png`` (the predicted
world-space normals, ``(n + 1) / 2``, black where the opacity is below 0.5) and
``KEY_depth.exr`` (one float channel ``Z``: planar camera z in metres like the dataset's depth,
0 where the opacity is below 0.5). ``cameras.json`` lists every view's ``K`` and
``camera_to_world`` (OpenCV convention).
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import torch

from prior.data.bounds import intersect_sphere
from prior.data.sampler import pixel_radius
from prior.rays import RayBundle
from synth.appearance.srgb import srgb8
from synth.dataset.reader import camera_rays
from synth.io import atomic_place, atomic_write_bytes, atomic_write_json
from synth.errors import SynthError

#: opacity above which a pixel counts as surface in depth and normal maps
SURFACE_ACC = 0.5


def scaled_camera(K: np.ndarray, width: int, height: int, size: int) -> np.ndarray:
    """``K`` of a (width x height) image rescaled to a ``size`` x ``size`` image (square pixels
    kept when the image is square)."""
    S = np.diag([size / width, size / height, 1.0])
    return S @ np.asarray(K, np.float64)


def orbit(c2w: np.ndarray, centre: np.ndarray, n: int) -> list[np.ndarray]:
    """``n`` camera poses spaced 360/n degrees apart, turning ``c2w`` about the vertical (world Z,
    Blender's up) axis through ``centre``; the first is ``c2w`` itself."""
    out = []
    for k in range(n):
        a = 2 * math.pi * k / n
        R = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        m = np.eye(4)
        m[:3, :3] = R @ c2w[:3, :3]
        m[:3, 3] = R @ (c2w[:3, 3] - centre) + centre
        out.append(m)
    return out


@torch.no_grad()
def render_image(model, K, c2w, width: int, height: int, code: np.ndarray, latent_id: int | None, centre,
                 radius: float, *, chunk: int = 4096, device="cpu", bf16: bool = False,
                 latent=None) -> dict[str, np.ndarray]:
    """Render one view: ``rgb`` (H, W, 3) over black, ``acc`` (H, W), ``depth`` (H, W) planar
    camera z (0 where ``acc < SURFACE_ACC``), ``normals`` (H, W, 3) unit world normals (0 there).
    The latent is the codebook row ``latent_id``, or the vector ``latent`` (a fitted face)."""
    r = camera_rays(K, c2w, width, height)
    o, d, cos_z = (x.reshape(-1, *x.shape[2:]) for x in r)
    near, far = intersect_sphere(o, d, np.asarray(centre), float(radius))
    # rays that miss the bounding sphere see nothing (zero colour, opacity, depth, normals): only
    # the others go through the field
    hit = np.flatnonzero(far > near)
    o, d, near, far = o[hit], d[hit], near[hit], far[hit]
    n = o.shape[0]
    dev = torch.device(device)
    rad = torch.full((n,), float(pixel_radius(np.asarray(K))), device=dev)
    codes = torch.as_tensor(np.asarray(code, np.float32), device=dev).expand(n, -1)
    ids = None if latent is not None else torch.full((n,), int(latent_id), dtype=torch.long, device=dev)
    rays = RayBundle.from_numpy(o, d, near, far, codes, latent_ids=ids, radii=rad, device=dev)
    if latent is not None:
        rays = rays.with_latent(torch.as_tensor(latent, dtype=torch.float32, device=dev).reshape(1, -1))
    parts: dict[str, list] = {"rgb": [], "acc": [], "depth": [], "normals": []}
    for chunk_rays in rays.chunks(chunk):
        with torch.autocast(dev.type, dtype=torch.bfloat16, enabled=bf16):
            out = model(chunk_rays, randomized=False)
        parts["rgb"].append(out["rgb"].float().clamp(0, 1))
        parts["acc"].append(out["acc"].float())
        parts["depth"].append(out["depth"].float())
        parts["normals"].append(out["normals_pred"].float())
    res = {k: np.zeros((width * height, 3) if k in ("rgb", "normals") else width * height, np.float32)
           for k in parts}
    for k, v in parts.items():
        if v:
            res[k][hit] = torch.cat(v).cpu().numpy()
    surf = res["acc"] >= SURFACE_ACC
    depth = np.where(surf, res["depth"] * cos_z, 0.0)
    nrm = res["normals"]
    nrm = np.where(surf[:, None], nrm / np.maximum(np.linalg.norm(nrm, axis=-1, keepdims=True), 1e-8), 0.0)
    return {"rgb": res["rgb"].reshape(height, width, 3), "acc": res["acc"].reshape(height, width),
            "depth": depth.reshape(height, width).astype(np.float32),
            "normals": nrm.reshape(height, width, 3).astype(np.float32)}


def png_bytes(img8: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img8).save(buf, format="PNG")
    return buf.getvalue()


def _write_depth_exr(path: Path, depth: np.ndarray) -> None:
    import OpenEXR

    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
           "depthConvention": "camera-space z (OpenCV, +z forward), metres; 0 = no surface"}
    atomic_place(path, lambda tmp: OpenEXR.File(hdr, {"Z": np.ascontiguousarray(depth, np.float32)}).write(str(tmp)))


def output_dir(path) -> Path:
    """The directory rendered views go to (``-o``), created when missing; a path that exists and
    is not a directory gives one clear line."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise SynthError("output path exists and is not a directory", str(path), "pass a directory to -o")
    path.mkdir(parents=True, exist_ok=True)
    return path


def write_view(out_dir: Path, key: str, img: dict[str, np.ndarray]) -> list[Path]:
    """The four files of one rendered view (see the module docstring), each written atomically."""
    files = {f"{key}_colour.png": png_bytes(srgb8(img["rgb"])),
             f"{key}_opacity.png": png_bytes((np.clip(img["acc"], 0, 1) * 255 + 0.5).astype(np.uint8)),
             f"{key}_normals.png": png_bytes(((img["normals"] + 1) * 0.5 * 255 + 0.5).astype(np.uint8)
                                             * (np.linalg.norm(img["normals"], axis=-1, keepdims=True) > 0))}
    for name, data in files.items():
        atomic_write_bytes(out_dir / name, data)
    _write_depth_exr(out_dir / f"{key}_depth.exr", img["depth"])
    return [out_dir / n for n in files] + [out_dir / f"{key}_depth.exr"]


def render_run(run_dir, identity: int, expression: int, out_dir, *, orbit_views: int = 8, size: int | None = None,
               device: str = "cpu", checkpoint=None) -> list[Path]:
    """Novel views of training identity ``identity`` with expression ``expression`` from the
    newest checkpoint of ``run_dir``: an orbit of ``orbit_views`` views about the vertical axis
    through the head's centre, starting at the identity's most frontal training camera."""
    from prior.train.checkpoint import latest, load
    from prior.train.setup import build_model

    path = checkpoint or latest(run_dir)
    if path is None:
        raise SynthError("run has no checkpoint", str(run_dir), "train it first (synth prior train ... --out RUN)")
    ck = load(path)
    info = ck.identities
    m = info.latent_id(identity)
    code = info.code(m, expression)
    if orbit_views < 1 or (size is not None and size < 1):
        raise SynthError("--orbit and --size must be at least 1", "synth prior render", "pass positive numbers")
    model = build_model(ck.config, ck.layout.size, len(info.identity_index), device)
    model.load_state_dict(ck.model_state)
    model.eval()
    W, H = (int(x) for x in info.front_size[m])
    K = info.front_K[m]
    if size is not None:
        K, W, H = scaled_camera(K, W, H, size), size, size
    out_dir = output_dir(out_dir)
    written, cams = [], []
    for k, c2w in enumerate(orbit(info.front_c2w[m], info.centre[m], orbit_views)):
        img = render_image(model, K, c2w, W, H, code, m, info.centre[m], float(info.radius[m]),
                           chunk=ck.config.train.render_chunk, device=device)
        key = f"id{identity:06d}_ex{expression:02d}_orbit{k:03d}"
        written += write_view(out_dir, key, img)
        cams.append({"key": key, "K": K.tolist(), "camera_to_world": c2w.tolist(), "width": W, "height": H})
    atomic_write_json(out_dir / "cameras.json", {"checkpoint": str(path), "step": ck.step, "identity": identity,
                                                  "expression": expression, "views": cams})
    return written + [out_dir / "cameras.json"]
