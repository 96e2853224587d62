"""Place the Blender camera from an OpenCV camera (K in pixels, world_to_camera 4x4).

All convention maths lives in synth.conventions; this module only applies it to bpy data.
"""

from __future__ import annotations

import bpy
import mathutils
import numpy as np

from synth.conventions import blender_camera_params, invert_rigid, opencv_to_blender_c2w


def make_camera(name: str = "camera"):
    cam = bpy.data.cameras.new(name)
    ob = bpy.data.objects.new(name, cam)
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.scene.camera = ob
    return ob


def set_camera(ob, K, world_to_camera, width: int, height: int, near: float, far: float) -> None:
    K = np.asarray(K, np.float64)
    if abs(K[0, 0] - K[1, 1]) > 1e-6 * K[0, 0] or abs(K[0, 1]) > 1e-9:
        raise ValueError("only square pixels without skew are supported (fx == fy, K[0,1] == 0)")
    p = blender_camera_params(K, width, height)
    cam = ob.data
    cam.type = "PERSP"
    cam.sensor_fit = p["sensor_fit"]
    cam.sensor_width = p["sensor_width_mm"]
    cam.lens = p["lens_mm"]
    cam.shift_x = p["shift_x"]
    cam.shift_y = p["shift_y"]
    cam.clip_start = float(near)
    cam.clip_end = float(far)
    c2w = opencv_to_blender_c2w(invert_rigid(np.asarray(world_to_camera, np.float64)))
    # mathutils.Matrix takes rows; a bare nested list assigned to matrix_world is read as columns
    ob.matrix_world = mathutils.Matrix(c2w.tolist())
