"""A tiny multi-view dataset without Blender: each identity is a shaded sphere "head" seen by
cameras on a ring around it (consistent geometry, depth, alpha and cameras across views), written
as committed shards through the real dataset writer. Used by the prior's data/train/CLI tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.dataset.reader import camera_rays
from synth.dataset.shards import load_dataset, open_dataset
from tests.support import fake_frames as ff

ID_SIZE, EXPR_SIZE = 4, 3


def head(ident: int) -> tuple[np.ndarray, float]:
    return np.array([0.01 * ident, 0.02, -0.01 * ident]), 0.1 + 0.01 * ident


def camera(az_deg: float, el_deg: float, size: int, dist: float = 0.8) -> dict:
    a, e = np.radians(az_deg), np.radians(el_deg)
    C = dist * np.array([np.sin(a) * np.cos(e), -np.cos(a) * np.cos(e), np.sin(e)])
    z = -C / np.linalg.norm(C)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([x, y, z], 1)
    c2w[:3, 3] = C
    f = size * 1.6
    K = np.array([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1]])
    return {"K": K, "world_to_camera": np.linalg.inv(c2w), "camera_to_world": c2w, "width": size, "height": size,
            "near": 0.1, "far": 10.0, "azimuth_deg": float(az_deg), "elevation_deg": float(el_deg),
            "radius_m": dist}


def frame(ident: int, expr: int, view: int, views: int, size: int, id_size: int = ID_SIZE, head_model: str = "fake"):
    key = ff.frame_key(ident, expr, view)
    cam = camera((360.0 * view / views + 23.0 * expr) % 360.0 - 180.0, 15.0 - 10.0 * (view % 3), size)
    o, d, cos_z = camera_rays(cam["K"], cam["camera_to_world"], size, size, dtype=np.float64)
    c, r = head(ident)
    oc = o - c
    b = (oc * d).sum(-1)
    disc = b * b - ((oc * oc).sum(-1) - r * r)
    hit = disc > 0
    t = np.where(hit, -b - np.sqrt(np.where(hit, disc, 0)), 0.0)
    p = o + t[..., None] * d
    n = np.where(hit[..., None], (p - c) / r, 0.0)
    albedo = np.array([0.7, 0.45, 0.35]) * (1.0 + 0.1 * ident) + 0.1 * expr
    light = np.clip((n * np.array([0.3, -0.8, 0.5])).sum(-1), 0, None)
    stripes = 0.15 * np.sin(25 * p[..., 2] + 3 * expr)
    rgb = np.clip(albedo * (0.25 + 0.6 * light[..., None]) + stripes[..., None], 0, 1) * hit[..., None]
    rgba = np.concatenate([rgb, hit[..., None].astype(float)], -1).astype(np.float32)
    depth = np.where(hit, t * cos_z, 0.0).astype(np.float32)
    meta = ff.frame_json(key, size)
    meta["camera"] = cam
    lm3 = np.asarray(meta["landmarks_3d"]) + c
    pc = lm3 @ cam["world_to_camera"][:3, :3].T + cam["world_to_camera"][:3, 3]
    q = pc @ cam["K"].T
    meta["landmarks_3d"], meta["landmarks_2d"] = lm3, q[:, :2] / q[:, 2:3]
    meta["model"]["name"] = head_model
    meta["model"]["identity"] = [0.1 * ident + 0.05 * k for k in range(id_size)]
    meta["model"]["expression"] = [0.2 * expr - 0.1 * k for k in range(EXPR_SIZE)]
    meta["model"]["joint_rotations"] = {"neck": [0.0, 0.0, 0.0], "jaw": [0.05 * expr, 0.0, 0.0],
                                        "eye_l": [0.0, 0.01 * expr, 0.0], "eye_r": [0.0, -0.01 * expr, 0.0]}
    return key, (rgba, depth, n.astype(np.float32), hit.astype(np.uint32)), meta


def make_dataset(root, identities: int = 2, expressions: int = 2, views: int = 4, size: int = 16,
                 id_size: int = ID_SIZE, *, commit: int | None = None, shard_format: str = "dir",
                 head_model: str = "fake") -> Path:
    """A dataset of one shard per identity; only the first ``commit`` shards committed (default all)."""
    root = Path(root)
    expected = {f"shard_{i:06d}": [ff.frame_key(i, e, v) for e in range(expressions) for v in range(views)]
                for i in range(identities)}
    open_dataset(root, "a" * 64, expected, shard_format=shard_format)
    for i in range(identities if commit is None else commit):
        commit_identity(root, i, views=views, size=size, id_size=id_size, head_model=head_model)
    return root


def commit_identity(root, ident: int, *, views: int, size: int, id_size: int = ID_SIZE, head_model: str = "fake",
                    stage_only: bool = False):
    """Render (fake) and commit shard ``ident`` of a dataset made by :func:`make_dataset`; with
    ``stage_only`` the frames are written to its staging area and left there (not committed)."""
    ds = open_dataset(Path(root), "a" * 64, load_dataset(root).expected)
    sid = f"shard_{ident:06d}"
    st = ds.staging(sid)
    st.__enter__()
    for key in ds.expected[sid]:
        k, px, meta = frame(*ff.parse_frame_key(key), views, size, id_size, head_model)
        st.write_frame(k, *px, meta)
    if stage_only:
        return st
    st.commit(manifest_extra={"seeds": {"run": 0}, "versions": {"blender": "none"}})
    st.__exit__(None, None, None)


#: a model and batch small enough for tests that train a few steps on CPU
TINY = ["model.nerf_width=16", "model.nerf_depth=2", "model.skip_layer=1", "model.proposal_width=8",
        "model.proposal_depth=1", "model.bottleneck_width=8", "model.view_width=8", "model.pos_levels=4",
        "model.dir_levels=2", "model.latent_dim=4", "sampling.proposal_samples=[8, 8]", "sampling.nerf_samples=8",
        "train.identities_per_batch=2", "train.views_per_identity=2", "train.pixels_per_view=16",
        "train.warmup_steps=2", "train.background_steps=2", "train.log_every=1", "train.checkpoint_every=2",
        "train.preview_every=0", "train.keep_checkpoints=10"]
