"""``synth export nerfstudio``: a dataset's frames as a nerfstudio data folder (docs/export.md).

::

    NS/transforms.json        camera_model OPENCV, w, h (+ fl_x fl_y cx cy when all frames share
                              them), one entry per frame: file_path, mask_path,
                              depth_file_path, transform_matrix (+ per-frame intrinsics);
                              train_filenames, val_filenames, test_filenames (the split)
    NS/images/KEY.png         8-bit sRGB colour with straight (un-premultiplied) alpha, RGBA
    NS/masks/KEY.png          8-bit: 255 where alpha >= 0.5 (the head), 0 elsewhere
    NS/depth/KEY.png          16-bit planar depth (z along the optical axis) in millimetres;
                              0 = no surface

Conventions (docs.nerf.studio, "Data conventions"): cameras in OpenGL axes (x right, y up,
looking down -z), ``transform_matrix`` camera-to-world in the dataset's world (metres, Z up);
intrinsics in pixels with the centre of pixel (i, j) at (i + 0.5, j + 0.5), which is the
dataset's own convention (:func:`synth.conventions.nerfstudio_camera`). nerfstudio reads
depth PNGs with ``depth_unit_scale_factor = 1e-3`` (millimetres) and treats them as planar
depth unless told ``is_euclidean_depth``; masks mark the pixels it may sample (0 = ignore).
The folder is written under a temporary name and renamed when complete.

The split: nerfstudio's dataparser reads ``train_filenames`` / ``val_filenames`` /
``test_filenames`` (the ``file_path`` values of each split) when the file has them, else it
trains on a fraction (0.9, rounded up: 6 views give no validation image). The export writes
them: the ``val_views`` highest view indices of each (identity, expression) are held out, the
views the prior holds out (``data.holdout_views``, :func:`synth.dataset.layout.held_out`),
and are both the validation and the test images; ``val_views = 0`` writes no split.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.conventions import nerfstudio_camera
from synth.dataset.layout import held_out, parse_frame_key
from synth.appearance.srgb import linear_to_srgb
from synth.errors import SynthError
from synth.export.select import check_new_output, png_bytes, select_frames
from synth.io import atomic_dir, atomic_write_json

#: Pixels with at least this coverage are in the mask.
MASK_ALPHA = 0.5
#: Depth PNG units per metre (nerfstudio's default depth_unit_scale_factor is 1e-3).
DEPTH_UNITS_PER_M = 1000.0
INTRINSICS = ("fl_x", "fl_y", "cx", "cy")



def colour_png(frame) -> bytes:
    """8-bit sRGB RGBA with straight alpha, from the frame's premultiplied scene-linear colour."""
    rgb = (linear_to_srgb(frame.rgb) * 255.0 + 0.5).astype(np.uint8)
    a = (np.clip(frame.alpha, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    return png_bytes(np.concatenate([rgb, a[..., None]], axis=-1))


def mask_png(frame) -> bytes:
    return png_bytes(np.where(frame.alpha >= MASK_ALPHA, 255, 0).astype(np.uint8))


def depth_png(frame, where: str) -> bytes:
    """16-bit millimetres; a surface nearer than 0.5 mm still reads 1 (0 means none)."""
    z = np.asarray(frame.depth, np.float64)
    if (z * DEPTH_UNITS_PER_M > 65535.0).any():
        raise SynthError(f"depth beyond {65535 / DEPTH_UNITS_PER_M:.1f} m does not fit a 16-bit millimetre PNG",
                         where, "this export is for heads at studio distances; use the EXR depth")
    mm = np.where(z > 0, np.maximum(np.rint(z * DEPTH_UNITS_PER_M), 1.0), 0.0)
    return png_bytes(mm.astype(np.uint16))


def frame_entry(frame, where: str) -> dict:
    K = frame.K
    if K[0, 1] != 0:
        raise SynthError("the camera has skew, which nerfstudio's pinhole model lacks", where,
                         "export frames rendered without skew")
    cam = nerfstudio_camera(K, frame.camera_to_world)
    ident, expr, view = parse_frame_key(frame.key)
    return {"file_path": f"images/{frame.key}.png", "mask_path": f"masks/{frame.key}.png",
            "depth_file_path": f"depth/{frame.key}.png", "transform_matrix": cam["transform_matrix"].tolist(),
            **{k: cam[k] for k in INTRINSICS}, "w": frame.width, "h": frame.height,
            "synth_key": frame.key, "identity_index": ident, "expression_index": expr, "view_index": view}


def transforms(entries: list[dict], held: list[bool] | None = None) -> dict:
    """``transforms.json``: what every frame shares goes to the top (nerfstudio reads a frame's
    own value first, then the top level); with ``held`` (one flag per entry), the split."""
    shared = {}
    for k in ("w", "h", *INTRINSICS):
        values = {e[k] for e in entries}
        if len(values) == 1:
            shared[k] = values.pop()
    frames = [{k: v for k, v in e.items() if k not in shared} for e in entries]
    split = {}
    if held is not None and any(held):
        val = [e["file_path"] for e, h in zip(entries, held) if h]
        split = {"train_filenames": [e["file_path"] for e, h in zip(entries, held) if not h],
                 "val_filenames": val, "test_filenames": list(val)}
    return {"camera_model": "OPENCV", **shared, **split, "frames": frames,
            "synth": {"format": "synth-nerfstudio/1", "world": "metres, Z up (Blender world)",
                      "depth_unit_scale_factor": 1.0 / DEPTH_UNITS_PER_M, "depth": "planar z (is_euclidean_depth false)",
                      "mask": f"255 where alpha >= {MASK_ALPHA}", "colour": "8-bit sRGB, straight alpha"}}


def export_nerfstudio(source, out, *, identity: int | None = None, expression: int | None = None,
                      environment: int = 0, val_views: int = 1, progress=None) -> dict:
    """Write the selected committed frames of ``source`` as a nerfstudio folder ``out`` (new or
    empty), holding out the ``val_views`` highest views of each scene. One lighting environment
    (``environment``; 0, the only one unless the dataset was planned with more) is exported,
    since a radiance field assumes fixed lighting. Returns a summary:
    frames, scenes ((identity, expression) pairs), val (held-out frame keys), out."""
    out = Path(out)
    check_new_output(out, "nerfstudio")
    if val_views < 0:
        raise SynthError(f"--val-views {val_views} is negative", "--val-views", "pass 0 or more")
    refs = select_frames(source, identity=identity, expression=expression, environment=environment)
    held = held_out([r.key for r in refs], val_views, "--val-views", str(source))
    entries = []
    with atomic_dir(out) as tmp:
        for d in ("images", "masks", "depth"):
            (tmp / d).mkdir()
        for ref in refs:
            frame = ref.read()
            where = str(ref.json_path)
            entries.append(frame_entry(frame, where))
            (tmp / "images" / f"{frame.key}.png").write_bytes(colour_png(frame))
            (tmp / "masks" / f"{frame.key}.png").write_bytes(mask_png(frame))
            (tmp / "depth" / f"{frame.key}.png").write_bytes(depth_png(frame, where))
            if progress:
                progress(frame.key)
        atomic_write_json(tmp / "transforms.json", transforms(entries, held), indent=1)
    scenes = sorted({(e["identity_index"], e["expression_index"]) for e in entries})
    return {"out": str(out), "frames": len(entries), "scenes": [list(s) for s in scenes],
            "val": [e["synth_key"] for e, h in zip(entries, held) if h]}
