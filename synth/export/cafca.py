"""``synth export cafca``: a dataset in the layout of the Cafca release (docs/export.md), so
code written for that dataset reads ours.

::

    OUT/SUBJECT/EXP_ENV/cameras_json/Cvv.json       K, world2cam, cam2world, P, position,
                                                    orientation, and each parameter alone
    OUT/SUBJECT/EXP_ENV/color_image/Cvv.png         8-bit sRGB RGB, the colour over black
    OUT/SUBJECT/EXP_ENV/color_image/environment.json  the environment of these images
    OUT/SUBJECT/EXP_ENV/foreground_mask/Cvv.png     8-bit coverage (alpha * 255)
    OUT/SUBJECT/EXP_ENV/segmentation/Cvv.png        16-bit grey: synth's class ids (0 background)

``SUBJECT`` is the identity index and ``EXP`` the expression index as 5 digits, ``ENV`` the
environment as 3 digits, ``Cvv`` the view index. ``ENV`` is the frame's ``environment_index``:
000 only, unless the dataset was planned with ``dataset.environments_per_expression`` N > 1,
when each expression has the folders 000 .. N-1 (000 the fixed environment, the others drawn;
``lighting`` in the frame JSON and ``environment.json`` say which). Cameras are
OpenCV's (x right, y down, z forward), as the release's; ``orientation``'s rows are the camera's
x, y and z axes in the world, ``position`` its centre. The folder is written under a temporary
name and renamed when complete.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from synth.appearance.srgb import linear_to_srgb
from synth.errors import SynthError
from synth.export.select import check_new_output, png_bytes, select_frames
from synth.io import atomic_dir

FOLDERS = ("cameras_json", "color_image", "foreground_mask", "segmentation")



def camera_json(frame) -> dict:
    """The release's camera record of a frame (OpenCV; metres; pixels)."""
    K, w2c, c2w = (np.asarray(m, np.float64) for m in (frame.K, frame.world_to_camera, frame.camera_to_world))
    return {"K": K.tolist(), "world2cam": w2c.tolist(), "cam2world": c2w.tolist(), "P": (K @ w2c[:3]).tolist(),
            "position": c2w[:3, 3].tolist(), "orientation": w2c[:3, :3].tolist(),
            "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "skew": K[0, 1],
            "width": frame.width, "height": frame.height,
            "synth": {"frame_id": frame.key, "pixel_centres": "pixel (i, j) is centred at (i + 0.5, j + 0.5)"}}


def environment_name(meta: dict) -> str:
    light = meta.get("lighting") or {}
    kind = str(light.get("environment", "unknown"))
    return Path(str(light["file"])).name if kind == "hdri" and light.get("file") else kind


def export_cafca(source, out, *, identity: int | None = None, progress=None) -> dict:
    """Write the committed frames of ``source`` (optionally one identity) in the Cafca release's
    layout under ``out`` (new or empty). Returns a summary: frames, scenes, out."""
    out = Path(out)
    check_new_output(out, "cafca")
    refs = select_frames(source, identity=identity)
    scenes: dict[Path, dict] = {}
    with atomic_dir(out) as tmp:
        for ref in refs:
            f = ref.read()
            scene = Path(f"{f.identity_index:05d}") / f"{f.expression_index:05d}_{f.environment_index:03d}"
            if scene not in scenes:
                for d in FOLDERS:
                    (tmp / scene / d).mkdir(parents=True)
                scenes[scene] = {"environment": environment_name(f.meta), "environment_index": f.environment_index,
                                 "synth_lighting": f.meta.get("lighting")}
            cam = f"C{f.view_index:02d}"
            seg = np.asarray(f.segmentation)
            if seg.size and int(seg.max()) > 65535:
                raise SynthError("a segmentation id does not fit a 16-bit PNG", str(ref.json_path),
                                 "export frames whose class ids are below 65536")
            rgb = (linear_to_srgb(np.clip(f.rgb_premultiplied, 0.0, 1.0)) * 255.0 + 0.5).astype(np.uint8)
            (tmp / scene / "color_image" / f"{cam}.png").write_bytes(png_bytes(rgb))
            mask = (np.clip(f.alpha, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
            (tmp / scene / "foreground_mask" / f"{cam}.png").write_bytes(png_bytes(mask))
            (tmp / scene / "segmentation" / f"{cam}.png").write_bytes(png_bytes(seg.astype(np.uint16)))
            (tmp / scene / "cameras_json" / f"{cam}.json").write_text(json.dumps(camera_json(f), indent=1))
            if progress:
                progress(f.key)
        for scene, env in scenes.items():
            (tmp / scene / "color_image" / "environment.json").write_text(json.dumps(env, indent=1))
    return {"out": str(out), "frames": len(refs), "scenes": [str(s) for s in sorted(scenes)]}
