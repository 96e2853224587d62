"""Fake but valid frames (pixels + frame JSON) for the dataset tests. No Blender needed."""

from __future__ import annotations

import time

import numpy as np

from synth.assets.classes import RECORD_ORDER
from synth.dataset.exr import CHANNELS, camera_attributes
from synth.dataset.layout import frame_key, parse_frame_key, shard_name


def camera(size: int, radius: float = 1.0) -> dict:
    """A camera at (0, -radius, 0) looking at the origin along +Y (Blender world, Z up)."""
    R = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # world -> OpenCV camera
    C = np.array([0.0, -radius, 0.0])
    w2c = np.eye(4)
    w2c[:3, :3] = R
    w2c[:3, 3] = -R @ C
    f = size * 1.5
    K = np.array([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1]])
    return {"K": K, "world_to_camera": w2c, "camera_to_world": np.linalg.inv(w2c), "width": size, "height": size,
            "near": 0.1, "far": 10.0, "azimuth_deg": 0.0, "elevation_deg": 0.0, "radius_m": radius}


def frame_json(key: str, size: int = 16) -> dict:
    ident, expr, view = parse_frame_key(key)
    rng = np.random.default_rng([ident, expr, view])
    cam = camera(size)
    lm3 = rng.uniform(-0.08, 0.08, (68, 3))
    pc = lm3 @ cam["world_to_camera"][:3, :3].T + cam["world_to_camera"][:3, 3]
    p = pc @ cam["K"].T
    lm2 = p[:, :2] / p[:, 2:3]
    assets = {k: None for k in RECORD_ORDER}
    assets["hair"] = {"id": "hair_short_01", "params": {"melanin": 0.4}}
    return {
        "frame_id": key, "identity_index": ident, "expression_index": expr, "view_index": view,
        "seed": int(rng.integers(0, 2**31)),
        "image": {"width": size, "height": size, "layers": list(CHANNELS), "file": f"{key}.exr"},
        "camera": cam,
        "model": {"name": "fake", "sha256": "0" * 64, "identity": [0.1, -0.2], "expression": [0.0, 0.3],
                  "expression_preset": None, "joint_rotations": {"jaw": [0.1, 0.0, 0.0]}, "head_pose": np.eye(4)},
        "landmarks_3d": lm3, "landmarks_2d": lm2, "landmarks_visible": [True] * 68,
        "assets": assets, "skin": {"albedo": [0.8, 0.6, 0.5]},
        "render": {"preset": "test", "resolution": [size, size], "samples": 1, "denoiser": None, "device": "CPU",
                   "seed": 7, "engine": "fake"},
        "software": {"synth": "0.1.0", "blender": "none", "python": "3.11"},
    }


def pixels(key: str, size: int = 16):
    """rgba, depth, normals, segmentation of a small sphere 'head' (deterministic per key)."""
    ident, expr, view = parse_frame_key(key)
    rng = np.random.default_rng([ident, expr, view, 1])
    v, u = np.mgrid[0:size, 0:size]
    x = (u + 0.5) / size * 2 - 1
    y = (v + 0.5) / size * 2 - 1
    inside = x * x + y * y < 0.36
    z = np.sqrt(np.clip(0.36 - x * x - y * y, 0, None)) / 0.6
    n = np.stack([x / 0.6, -y / 0.6, z], -1) * inside[..., None]
    rgb = (0.3 + 0.5 * z)[..., None] * np.array([0.8, 0.55, 0.45]) * (1 + 0.05 * rng.standard_normal((size, size, 3)))
    rgba = np.concatenate([rgb * inside[..., None], inside[..., None].astype(float)], -1)
    depth = np.where(inside, 1.0 - 0.1 * z, 1e10)
    seg = np.where(inside, np.where(y < -0.2, 5, 1), 0)
    return rgba.astype(np.float32), depth.astype(np.float32), n.astype(np.float32), seg.astype(np.uint32)


def plan(n_shards: int = 2, n_expr: int = 2, n_views: int = 3, first_identity: int = 0) -> dict[str, list[str]]:
    """shard_{i:06d} -> the keys of identity i (all expressions and views)."""
    return {shard_name(i): [frame_key(i, e, v) for e in range(n_expr) for v in range(n_views)]
            for i in range(first_identity, first_identity + n_shards)}


def stage_missing(st, sleep: float = 0.0, on_frame=None) -> None:
    """Write the fake frames the staging shard ``st`` still lacks, sleeping ``sleep`` seconds before
    each (as a render would) and calling ``on_frame(key)`` after each one is staged."""
    done = st.frames_done()
    for key in st.expected_keys:
        if key in done:
            continue
        time.sleep(sleep)
        st.write_frame(key, *pixels(key), frame_json(key))
        if on_frame is not None:
            on_frame(key)


def render_dataset(ds, size: int = 16, shards=None) -> None:
    """Write and commit every (or the given) pending shard of ``ds`` with fake frames."""
    for sid in shards or ds.pending_shards():
        with ds.staging(sid) as st:
            done = st.frames_done()
            for key in st.expected_keys:
                if key not in done:
                    fj = frame_json(key, size)
                    cam = fj["camera"]
                    st.write_frame(key, *pixels(key, size), fj,
                                   exr_header=camera_attributes(cam["K"], cam["world_to_camera"], size, size))
            st.commit(manifest_extra={"seeds": {"run": 0}, "versions": {"blender": "none"}})
