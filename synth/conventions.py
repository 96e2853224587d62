"""THE one module for every convention conversion (see docs/conventions.md).

World: metres, Blender's axes, Z up; the face looks toward -Y; +X is the subject's left.

Spherical camera coordinates around a target point (degrees, metres):

- azimuth 0 puts the camera in front of the face (on -Y of the target); positive azimuth
  moves it toward the subject's left (+X); +-180 is behind the head.
- elevation 0 is level with the target, +90 straight above, -90 straight below.
- position = target + radius * (sin(az) cos(el), -cos(az) cos(el), sin(el)).

Cameras in JSON use OpenCV's convention: camera axes x right, y down, z forward (the
optical axis); ``world_to_camera`` (4x4) maps world points to camera coordinates, and
``K`` (3x3, pixels) maps camera coordinates to pixels. Pixel convention: continuous pixel
coordinates with the top-left *corner* of the image at (0, 0), so the centre of pixel
(col i, row j) is (i + 0.5, j + 0.5) and an unshifted principal point is (W/2, H/2)
(Blender's and most NeRF code's convention). :func:`k_to_integer_centres` converts K to
the "pixel centres at integers" convention (OpenCV calibration, COLMAP uses +0.5 like us).

Blender, OpenGL, USD and nerfstudio cameras look along their local -Z with +Y up:
``c2w_opengl = c2w_opencv @ diag(1, -1, -1, 1)``. OpenEXR's standard ``worldToCamera``
attribute uses x right, y up, z forward (left-handed; RenderMan's camera space).

Joint rotations of the head model are local axis-angle vectors in the world axes of the
rest pose: jaw opening is a positive rotation about +X; eye gaze yaw > 0 turns the gaze
toward the subject's left (+X), gaze pitch > 0 turns it up.
"""

from __future__ import annotations

import numpy as np

from synth.geometry import exact

#: OpenCV camera axes <-> OpenGL camera axes (flip y and z); its own inverse. Blender, USD and
#: nerfstudio cameras use the OpenGL axes (x right, y up, looking down -z).
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
CV_TO_BLENDER = CV_TO_GL
#: OpenCV camera axes -> OpenEXR/RenderMan camera axes (x right, y up, z forward: flip y).
CV_TO_EXR = np.diag([1.0, -1.0, 1.0, 1.0])


def _rad(x) -> np.ndarray:
    return np.deg2rad(np.asarray(x, dtype=np.float64))


# --------------------------------------------------------------------------- spherical


def spherical_offset(azimuth_deg, elevation_deg) -> np.ndarray:
    """(..., 3) unit vector from the target toward the camera."""
    a, e = _rad(azimuth_deg), _rad(elevation_deg)
    ce = exact.cos(e)
    return np.stack(np.broadcast_arrays(exact.sin(a) * ce, -exact.cos(a) * ce, exact.sin(e)), axis=-1)


def spherical_to_position(azimuth_deg, elevation_deg, radius, target) -> np.ndarray:
    """(..., 3) camera positions."""
    return np.asarray(target, np.float64) + np.asarray(radius, np.float64)[..., None] * spherical_offset(
        azimuth_deg, elevation_deg)


def position_to_spherical(position, target) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`spherical_to_position`: (azimuth_deg, elevation_deg, radius).
    At the poles the azimuth is undefined and returned as 0."""
    d = np.asarray(position, np.float64) - np.asarray(target, np.float64)
    r = np.linalg.norm(d, axis=-1)
    horiz = np.hypot(d[..., 0], d[..., 1])
    el = np.degrees(exact.atan2(d[..., 2], horiz))
    az = np.where(horiz > 1e-12 * np.maximum(r, 1e-300), np.degrees(exact.atan2(d[..., 0], -d[..., 1])), 0.0)
    return az, el, r


def viewing_direction(azimuth_deg, elevation_deg) -> np.ndarray:
    """(..., 3) unit viewing direction (camera -> target) for a camera looking at the target."""
    return -spherical_offset(azimuth_deg, elevation_deg)


# --------------------------------------------------------------------------- extrinsics


def _pack_c2w(x, y, z, p) -> np.ndarray:
    shape = np.broadcast_shapes(x.shape, p.shape)
    M = np.zeros(shape[:-1] + (4, 4))
    M[..., :3, 0] = x
    M[..., :3, 1] = y
    M[..., :3, 2] = z
    M[..., :3, 3] = p
    M[..., 3, 3] = 1.0
    return M


def orbit_camera_to_world(azimuth_deg, elevation_deg, radius, target, roll_deg=0.0) -> np.ndarray:
    """(..., 4, 4) OpenCV camera-to-world for a camera on the sphere looking at ``target``.

    The image "up" is the elevation tangent (-sin az sin el, cos az sin el, cos el): the
    projection of world +Z where that is defined, and still defined and continuous at
    elevation +-90 (where it points along the azimuth direction), so the look-at never
    degenerates at the poles. ``roll_deg`` rotates the camera about its optical axis (x toward y).
    """
    a, e = _rad(azimuth_deg), _rad(elevation_deg)
    sa, ca, se, ce = exact.sin(a), exact.cos(a), exact.sin(e), exact.cos(e)
    sa, ca, se, ce = np.broadcast_arrays(sa, ca, se, ce)
    z = np.stack([-sa * ce, ca * ce, -se], axis=-1)  # forward = toward the target
    up = np.stack([-sa * se, ca * se, ce], axis=-1)
    y = -up  # OpenCV y points down
    x = np.cross(y, z)  # right-handed: x = y cross z
    roll = _rad(roll_deg)
    if np.any(roll != 0):
        cr, sr = exact.cos(roll)[..., None], exact.sin(roll)[..., None]
        x, y = cr * x + sr * y, -sr * x + cr * y
    p = spherical_to_position(azimuth_deg, elevation_deg, radius, target)
    return _pack_c2w(x, y, z, np.broadcast_to(p, z.shape))


def look_at(eye, target, up=(0.0, 0.0, 1.0), eps: float = 1e-9) -> np.ndarray:
    """(..., 4, 4) OpenCV camera-to-world looking from ``eye`` at ``target`` with ``up`` as
    the image-up hint. Where the viewing direction is (anti)parallel to ``up`` the hint is
    replaced by the orbit convention's up at azimuth 0 ((0, +1, 0) looking down, (0, -1, 0)
    looking up), so the result is always a proper rotation."""
    eye = np.asarray(eye, np.float64)
    z = np.asarray(target, np.float64) - eye
    n = np.linalg.norm(z, axis=-1, keepdims=True)
    if np.any(n <= eps):
        raise ValueError("look_at: eye and target coincide")
    z = z / n
    up = np.broadcast_to(np.asarray(up, np.float64), z.shape)
    x = np.cross(z, up)  # right = forward x up (with y down: x = y cross z = -up cross z)
    xn = np.linalg.norm(x, axis=-1, keepdims=True)
    bad = xn[..., 0] <= 1e-6
    if np.any(bad):
        fallback = np.zeros(z.shape)
        vertical = np.abs(z[..., 2]) > 0.5
        fallback[..., 1] = np.where(vertical, -np.sign(z[..., 2]), 0.0)
        fallback[..., 2] = np.where(vertical, 0.0, 1.0)
        x = np.where(bad[..., None], np.cross(z, fallback), x)
        xn = np.linalg.norm(x, axis=-1, keepdims=True)
    x = x / xn
    y = np.cross(z, x)
    return _pack_c2w(x, y, z, np.broadcast_to(eye, z.shape))


def invert_rigid(M: np.ndarray) -> np.ndarray:
    """Inverse of (..., 4, 4) rigid transforms [R t; 0 1] -> [R^T -R^T t; 0 1]."""
    M = np.asarray(M, np.float64)
    out = np.zeros_like(M)
    Rt = np.swapaxes(M[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -exact.matvec3(Rt, M[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def opencv_to_opengl_c2w(c2w_cv: np.ndarray) -> np.ndarray:
    """OpenCV camera-to-world -> OpenGL camera-to-world (looks along local -Z, +Y up): Blender's
    camera ``matrix_world``, a USD camera's local-to-world transform and nerfstudio's
    ``transform_matrix``. Its own inverse."""
    return np.asarray(c2w_cv, np.float64) @ CV_TO_GL


opengl_to_opencv_c2w = opencv_to_opengl_c2w
opencv_to_blender_c2w = opencv_to_opengl_c2w
blender_to_opencv_c2w = opencv_to_opengl_c2w


# --------------------------------------------------------------------------- intrinsics


def fov_from_focal(focal_mm: float, sensor_width_mm: float) -> float:
    """Horizontal field of view (degrees) of a lens on a sensor (horizontal sensor fit)."""
    return float(np.degrees(2.0 * exact.atan(0.5 * sensor_width_mm / focal_mm)))


def intrinsics(width: int, height: int, fov_x_deg, principal_offset_px=(0.0, 0.0)) -> np.ndarray:
    """(..., 3, 3) K with square pixels: fx = fy = (W/2) / tan(fov_x/2), principal point at
    (W/2, H/2) + offset (pixel centres at integer + 0.5)."""
    f = 0.5 * width / exact.tan(0.5 * _rad(fov_x_deg))
    off = np.asarray(principal_offset_px, np.float64)
    f, ox, oy = np.broadcast_arrays(f, off[..., 0], off[..., 1])
    K = np.zeros(f.shape + (3, 3))
    K[..., 0, 0] = f
    K[..., 1, 1] = f
    K[..., 0, 2] = 0.5 * width + ox
    K[..., 1, 2] = 0.5 * height + oy
    K[..., 2, 2] = 1.0
    return K


def k_to_integer_centres(K: np.ndarray) -> np.ndarray:
    """K in our convention (pixel centres at +0.5) -> pixel centres at integer coordinates."""
    K = np.array(K, np.float64)
    K[..., 0, 2] -= 0.5
    K[..., 1, 2] -= 0.5
    return K


def blender_camera_params(K: np.ndarray, width: int, height: int, sensor_width_mm: float = 36.0) -> dict:
    """Blender camera data for a K of this module (square pixels, horizontal sensor fit).

    Blender measures ``shift_x``/``shift_y`` in units of the image width when
    ``sensor_fit == 'HORIZONTAL'``; shift_x > 0 moves the view right (principal point
    left), shift_y > 0 moves it up (principal point down in pixel rows).
    """
    K = np.asarray(K, np.float64)
    fx = float(K[0, 0])
    return {
        "lens_mm": fx * sensor_width_mm / width,
        "sensor_width_mm": float(sensor_width_mm),
        "sensor_fit": "HORIZONTAL",
        "shift_x": (0.5 * width - float(K[0, 2])) / width,
        "shift_y": (float(K[1, 2]) - 0.5 * height) / width,
    }


def nerfstudio_camera(K: np.ndarray, camera_to_world: np.ndarray) -> dict:
    """nerfstudio's camera of a frame: ``fl_x fl_y cx cy`` and ``transform_matrix``.

    nerfstudio shoots the ray of pixel (i, j) through (i + 0.5, j + 0.5) with (cx, cy) in the
    same continuous coordinates (docs.nerf.studio, "Data conventions": pixel coordinates are
    pixel centres), which is this module's convention: the intrinsics are K's numbers
    unchanged. ``transform_matrix`` is the OpenGL camera-to-world (x right, y up, looking -z).
    """
    K = np.asarray(K, np.float64)
    return {"fl_x": float(K[0, 0]), "fl_y": float(K[1, 1]), "cx": float(K[0, 2]), "cy": float(K[1, 2]),
            "transform_matrix": opencv_to_opengl_c2w(camera_to_world)}


def usd_camera_params(K: np.ndarray, width: int, height: int, sensor_width_mm: float = 36.0) -> dict:
    """UsdGeomCamera lens and filmback attributes for a K of this module on a stage in metres.

    USD measures ``focalLength``, the apertures and their offsets in tenths of a scene unit
    (decimetres here: 36 mm is 0.36). A point at OpenGL camera coordinates (x, y, z), z < 0,
    lands on the film at ``focalLength * (x, y) / -z``; the film spans the apertures centred
    on the offsets, and pixel rows grow downward, so ``fx = W focalLength / horizontalAperture``,
    ``cx = W/2 - W horizontalApertureOffset / horizontalAperture`` and
    ``cy = H/2 + H verticalApertureOffset / verticalAperture`` (square pixels: fx = fy).
    """
    K = np.asarray(K, np.float64)
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    unit = 100.0  # millimetres per tenth of a metre
    h_ap = sensor_width_mm / unit
    focal = fx * h_ap / width
    v_ap = focal * height / fy
    return {"focalLength": focal, "horizontalAperture": h_ap, "verticalAperture": v_ap,
            "horizontalApertureOffset": (0.5 * width - cx) * h_ap / width,
            "verticalApertureOffset": (cy - 0.5 * height) * v_ap / height}


def exr_world_to_camera(world_to_camera: np.ndarray) -> np.ndarray:
    """OpenEXR's ``worldToCamera`` (column-vector form): world -> x right, y up, z forward."""
    return CV_TO_EXR @ np.asarray(world_to_camera, np.float64)


def exr_world_to_ndc(K: np.ndarray, world_to_camera: np.ndarray, width: int, height: int) -> np.ndarray:
    """OpenEXR's ``worldToNDC`` (column-vector form): homogeneous world points to NDC, where
    (0, 0) and (1, 1) are the top-left and bottom-right corners of the image, so
    ``ndc = (u / W, v / H)`` for the pixel coordinates (u, v) of :func:`project`. The third
    row makes the matrix invertible: the third NDC coordinate is 1 / z (inverse planar depth)."""
    K = np.asarray(K, np.float64)
    P = np.array([[K[0, 0] / width, K[0, 1] / width, K[0, 2] / width, 0.0],
                  [0.0, K[1, 1] / height, K[1, 2] / height, 0.0],
                  [0.0, 0.0, 0.0, 1.0],
                  [0.0, 0.0, 1.0, 0.0]])
    return P @ np.asarray(world_to_camera, np.float64)


def project(K: np.ndarray, world_to_camera: np.ndarray, points) -> tuple[np.ndarray, np.ndarray]:
    """Project (..., N, 3) world points: returns (pixels (..., N, 2), depth along +z (..., N))."""
    X = np.asarray(points, np.float64)
    w2c = np.asarray(world_to_camera, np.float64)
    Xc = exact.points_times_matrix(X, np.swapaxes(w2c[..., :3, :3], -1, -2)) + w2c[..., None, :3, 3]
    uvw = exact.points_times_matrix(Xc, np.swapaxes(np.asarray(K, np.float64), -1, -2))
    return uvw[..., :2] / uvw[..., 2:3], Xc[..., 2]


# --------------------------------------------------------------------------- joints


def jaw_axis_angle(open_deg, lateral_deg=0.0) -> np.ndarray:
    """Jaw rotation: ``open_deg`` > 0 opens the mouth (about +X), ``lateral_deg`` > 0 swings
    the chin toward the subject's left (about +Z). Returned as (..., 3) axis-angle of
    Rz(lateral) @ Rx(open)."""
    return _compose_zx(lateral_deg, open_deg)


def gaze_axis_angle(yaw_deg, pitch_deg) -> np.ndarray:
    """Eye rotation for a gaze ``yaw_deg`` toward the subject's left and ``pitch_deg`` up:
    Rz(yaw) @ Rx(-pitch), as (..., 3) axis-angle."""
    return _compose_zx(yaw_deg, -np.asarray(pitch_deg, np.float64))


def _compose_zx(z_deg, x_deg) -> np.ndarray:
    from synth.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle

    zr, xr = np.broadcast_arrays(_rad(z_deg), _rad(x_deg))
    o = np.zeros_like(zr)
    Rz = axis_angle_to_matrix(np.stack([o, o, zr], -1))
    Rx = axis_angle_to_matrix(np.stack([xr, o, o], -1))
    return matrix_to_axis_angle(exact.matmul3(Rz, Rx))
