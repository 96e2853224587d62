"""Render the current camera view with Cycles and return its passes as numpy arrays."""

from __future__ import annotations

import os
import time
from pathlib import Path

import bpy
import numpy as np

from blender_scripts.scene import VIEW_LAYER
from synth.dataset.alpha import merge_denoised_alpha
from synth.dataset.exr import BACKGROUND_DEPTH_THRESHOLD

#: Depth of background pixels (alpha == 0) in the pass arrays a render returns. A stored frame
#: EXR holds :data:`synth.dataset.exr.STORED_BACKGROUND_DEPTH` (0.0) there instead: the writer
#: maps one to the other (docs/frame-format.md).
PASS_BACKGROUND_DEPTH = np.inf


def render_view(tmp_dir: Path, seed: int) -> dict:
    """Render with the given Cycles seed; returns rgba (H,W,4), depth (H,W) camera z in metres
    (background: :data:`PASS_BACKGROUND_DEPTH`), normals (H,W,3) world space, segmentation
    (H,W) uint32 class IDs, and the time Cycles spent: wall seconds and the process's CPU seconds
    (all render threads; the cost measure that a busy machine does not inflate)."""
    import OpenEXR

    scene = bpy.context.scene
    scene.cycles.seed = int(seed) % (2 ** 31)
    path = Path(tmp_dir) / f"render_{os.getpid()}.exr"
    scene.render.filepath = str(path)
    t0, c0 = time.perf_counter(), time.process_time()
    bpy.ops.render.render(write_still=True)
    t_render, c_render = time.perf_counter() - t0, time.process_time() - c0
    ch = OpenEXR.File(str(path), separate_channels=True).channels()
    os.unlink(path)
    p = VIEW_LAYER + "."
    rgba = np.stack([ch[p + "Combined." + c].pixels for c in "RGBA"], -1)
    depth = ch[p + "Depth.Z"].pixels.astype(np.float32)
    normals = np.stack([ch[p + "Normal." + c].pixels for c in "XYZ"], -1).astype(np.float32)
    seg = np.rint(ch[p + "IndexMA.X"].pixels).astype(np.uint32)
    alpha = rgba[..., 3].copy()
    background = alpha <= 0.0  # no surface hit by any sample: the geometry passes' background
    if "Composite.Combined.R" in ch:  # the compositor's denoised alpha (scene._alpha_denoiser)
        rgba[..., 3] = merge_denoised_alpha(alpha, ch["Composite.Combined.R"].pixels)
    no_surface = background | (depth >= BACKGROUND_DEPTH_THRESHOLD)
    depth = np.where(no_surface, PASS_BACKGROUND_DEPTH, depth).astype(np.float32)
    seg[background] = 0
    normals[background] = 0.0
    return {"rgba": rgba.astype(np.float32), "depth": depth, "normals": normals, "segmentation": seg,
            "render_seconds": t_render, "render_cpu_seconds": c_render}
