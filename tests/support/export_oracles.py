"""Oracles for the export tests (tests/export and tests/blender): the camera models of the
tools the exports feed, implemented from their documentation, not from synth.

nerfstudio (not installed; docs.nerf.studio, "Data conventions", and
docs/quickstart/data_conventions.md in its repository): cameras in OpenGL axes (+X right,
+Y up, looking down -Z); ``transform_matrix`` camera-to-world whose columns are the camera's
+X, +Y, +Z and position; intrinsics ``fl_x fl_y cx cy`` per frame or at the top of the file;
"generating a ray for pixel (0, 0) will shoot the ray through the center of that pixel" (its
ray generator adds 0.5 to the integer pixel index, then uses ``((x - cx) / fx, -(y - cy) / fy,
-1)``). Depth PNGs are millimetres (``depth_unit_scale_factor = 1e-3``), planar unless
``is_euclidean_depth``.

USD (usd-core): a UsdGeom.Camera's own GfCamera and GfFrustum matrices (row vectors), NDC in
[-1, 1] with y up.
"""

from __future__ import annotations

import numpy as np


def ns_value(meta: dict, frame: dict, key: str):
    """A frame's own value, else the file's (nerfstudio's dataparser reads them so)."""
    return frame[key] if key in frame else meta[key]


def ns_ray(meta: dict, frame: dict, col: int, row: int) -> tuple[np.ndarray, np.ndarray]:
    """Origin and unit direction of the ray nerfstudio shoots for integer pixel (col, row)."""
    fx, fy, cx, cy = (ns_value(meta, frame, k) for k in ("fl_x", "fl_y", "cx", "cy"))
    c2w = np.asarray(frame["transform_matrix"], np.float64)
    x, y = col + 0.5, row + 0.5
    d_cam = np.array([(x - cx) / fx, -(y - cy) / fy, -1.0])
    d = c2w[:3, :3] @ d_cam
    return c2w[:3, 3], d / np.linalg.norm(d)


def ns_project(meta: dict, frame: dict, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Continuous pixel coordinates (x, y) whose ray (as :func:`ns_ray` makes them, with the
    +0.5 of pixel centres included) passes through world points X, and their planar depth."""
    fx, fy, cx, cy = (ns_value(meta, frame, k) for k in ("fl_x", "fl_y", "cx", "cy"))
    c2w = np.asarray(frame["transform_matrix"], np.float64)
    p = (np.asarray(X, np.float64) - c2w[:3, 3]) @ c2w[:3, :3]  # world -> camera (R^T (X - o))
    depth = -p[:, 2]
    return np.stack([cx + fx * p[:, 0] / depth, cy - fy * p[:, 1] / depth], 1), depth


# ----------------------------------------------------------------------------- USD


def usd_project(stage, cam_path: str, time: int, X: np.ndarray, width: int, height: int) -> np.ndarray:
    """Pixel coordinates (top-left corner of the image at (0, 0)) of world points through a
    UsdGeom.Camera at a time code, by USD's own maths: view and projection matrices of the
    camera's GfFrustum (row vectors), NDC in [-1, 1] with y up."""
    from pxr import Usd, UsdGeom

    cam = UsdGeom.Camera(stage.GetPrimAtPath(cam_path))
    fr = cam.GetCamera(Usd.TimeCode(time)).frustum
    M = np.asarray(fr.ComputeViewMatrix()) @ np.asarray(fr.ComputeProjectionMatrix())
    h = np.concatenate([X, np.ones((len(X), 1))], 1) @ M
    ndc = h[:, :3] / h[:, 3:4]
    return np.stack([(ndc[:, 0] + 1) / 2 * width, (1 - ndc[:, 1]) / 2 * height], 1)


def mesh_landmarks(mesh, data, time: int) -> np.ndarray:
    """The model's ibug68 landmarks on the exported head mesh's points at a time code."""
    from pxr import Usd

    P = np.asarray(mesh.GetPointsAttr().Get(Usd.TimeCode(time)), np.float64)
    tri, bary = data.landmarks["ibug68"]
    return np.einsum("lkc,lk->lc", P[data.triangles[tri]], bary.astype(np.float64))


def check_stage(stage, frames: dict[str, dict], data) -> float:
    """Every frame's landmarks through its USD camera vs landmarks_2d; returns the worst error (px)."""
    from pxr import UsdGeom

    from synth.dataset.layout import parse_frame_key

    worst = 0.0
    for key, fj in frames.items():
        i, e, v = parse_frame_key(key)
        base = f"/World/id{i:06d}"
        X = mesh_landmarks(UsdGeom.Mesh(stage.GetPrimAtPath(f"{base}/head")), data, e)
        assert np.abs(X - np.asarray(fj["landmarks_3d"])).max() < 1e-6  # the head model, evaluated as rendered
        uv = usd_project(stage, f"{base}/cameras/v{v:02d}", e, X, fj["image"]["width"], fj["image"]["height"])
        err = np.abs(uv - np.asarray(fj["landmarks_2d"])).max()
        worst = max(worst, float(err))
    return worst


def ns_split(meta: dict, split: str, data_dir: str = "data") -> list[str]:
    """The ``file_path`` values of the images nerfstudio's own dataparser (``nerfstudio-data``,
    1.1) puts in ``split`` ("train", "val" or "test"), as it documents and does: with
    ``{split}_filenames`` in the file, the frames whose path is listed (a listed path that is no
    frame's is an error, and so is a file that lists some splits but not this one); without any,
    a fraction split: ``ceil(0.9 n)`` training images at ``linspace(0, n - 1, num_train)``
    (integer indices), the rest for both val and test."""
    import math
    import posixpath

    paths = [posixpath.normpath(posixpath.join(data_dir, f["file_path"])) for f in meta["frames"]]
    listed = {s: meta[f"{s}_filenames"] for s in ("train", "val", "test") if f"{s}_filenames" in meta}
    if split in listed:
        wanted = {posixpath.normpath(posixpath.join(data_dir, p)) for p in listed[split]}
        if wanted - set(paths):
            raise RuntimeError(f"some filenames of split {split} are not frames: {sorted(wanted - set(paths))}")
        idx = [i for i, p in enumerate(paths) if p in wanted]
    elif listed:
        raise RuntimeError(f"the list of filenames of split {split} is missing")
    else:
        n = len(paths)
        train = set(np.linspace(0, n - 1, math.ceil(n * 0.9), dtype=int).tolist())
        idx = sorted(train) if split == "train" else [i for i in range(n) if i not in train]
    return [meta["frames"][i]["file_path"] for i in idx]
