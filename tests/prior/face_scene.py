"""A tiny dataset of toy-model faces without Blender, for the few-shot fitting tests.

Each identity is the toy head model (``tests/support/toy_model.py``, ~ an ellipsoid with ibug68
landmarks on its front) with seeded identity and expression codes and jaw/eye rotations. The
pixels are the ray-traced ellipsoid of the toy's rest shape (half-axes ``AXES``), shaded, with
dark eye and mouth patches at the landmarks' places; the frame JSON holds the model's true
landmarks projected by the frame's camera (visible where their triangle faces the camera) and the
model's name and file sha256, like a synth render. So a prior trained on it, the landmark fit
(with ``--model`` the toy file) and the evaluation see one consistent world.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.conventions import invert_rigid, orbit_camera_to_world, project
from synth.dataset.reader import camera_rays
from synth.dataset.shards import open_dataset
from synth.io import sha256_file
from synth.model.head import HeadModel
from tests.support import fake_frames as ff
from tests.support.toy_model import AXES, make_toy_model, write_toy_model

IDENTITY_DIMS = 6
DIST = 0.6
MODEL = make_toy_model(identity_dims=IDENTITY_DIMS)
HEAD = HeadModel(MODEL, np.float64)


def write_model(path) -> Path:
    return write_toy_model(path, identity_dims=IDENTITY_DIMS)


def codes(ident: int, expr: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """beta, psi and all joints' rotations of (identity, expression), seeded by the indices."""
    rng = np.random.default_rng([71, ident])
    beta = rng.normal(0.0, 0.6, IDENTITY_DIMS)
    rng = np.random.default_rng([72, ident, expr])
    psi = np.clip(rng.uniform(-0.2, 0.6, len(MODEL.expression_names)), 0, 1)
    rot = np.zeros((len(MODEL.joint_names), 3))
    rot[MODEL.joint_names.index("jaw")] = [0.1 * rng.uniform(), 0, 0]
    rot[MODEL.joint_names.index("eye_l")] = rot[MODEL.joint_names.index("eye_r")] = [0, 0, 0.05 * rng.uniform(-1, 1)]
    return beta, psi, rot


def view_angles(view: int, views: int, expr: int) -> tuple[float, float]:
    """Cameras spread over the frontal half (+-80 degrees) and a little above and below."""
    az = -80.0 + 160.0 * ((view * 0.618 + 0.1 * expr) % 1.0)
    return az, 12.0 - 8.0 * (view % 4)


def frame(ident: int, expr: int, view: int, views: int, size: int, model_sha: str, angles=None):
    az, el = angles if angles is not None else view_angles(view, views, expr)
    c2w = orbit_camera_to_world(az, el, DIST, np.zeros(3))
    w2c = invert_rigid(c2w)
    f = size * 1.6
    K = np.array([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1.0]])
    o, d, cos_z = camera_rays(K, c2w, size, size, dtype=np.float64)
    beta, psi, rot = codes(ident, expr)
    # ellipsoid: |(p / AXES)| = 1 along the ray
    oa, da = o / AXES, d / AXES
    a, b, c = (da * da).sum(-1), (oa * da).sum(-1), (oa * oa).sum(-1) - 1
    disc = b * b - a * c
    hit = disc > 0
    t = np.where(hit, (-b - np.sqrt(np.where(hit, disc, 0))) / a, 0.0)
    p = o + t[..., None] * d
    n = p / AXES ** 2
    n = np.where(hit[..., None], n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12), 0.0)
    lm = HEAD.landmarks(beta, psi, rot)[0]
    albedo = np.array([0.75, 0.5, 0.4]) * (1.0 + 0.08 * beta[0]) + 0.05 * psi[0]
    dark = np.zeros(p.shape[:2])
    for k in (range(36, 48), range(48, 60)):  # eyes and mouth
        for j in k:
            dark = np.maximum(dark, np.exp(-((p - lm[j]) ** 2).sum(-1) / (2 * 0.006 ** 2)))
    light = np.clip((n * np.array([0.3, -0.8, 0.5])).sum(-1), 0, None)
    stripes = 0.1 * np.sin(60 * p[..., 2] + 2 * beta[1])
    rgb = albedo * (0.3 + 0.6 * light[..., None]) * (1 - 0.7 * dark[..., None]) + stripes[..., None]
    rgb = np.clip(rgb, 0, 1) * hit[..., None]
    rgba = np.concatenate([rgb, hit[..., None]], -1).astype(np.float32)
    depth = np.where(hit, t * cos_z, 0.0).astype(np.float32)
    uv, z = project(K, w2c, lm)
    tri, _ = MODEL.landmarks["ibug68"]
    V = HEAD.vertices(beta, psi, rot)[0][MODEL.triangles[tri]]
    normal = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    visible = ((normal * (c2w[:3, 3] - lm)).sum(-1) > 0) & np.all((uv >= 0) & (uv <= size), -1) & (z > 0)
    key = ff.frame_key(ident, expr, view)
    meta = ff.frame_json(key, size)
    meta["camera"] = {"K": K, "world_to_camera": w2c, "camera_to_world": c2w, "width": size, "height": size,
                      "near": 0.05, "far": 10.0, "azimuth_deg": float(az), "elevation_deg": float(el),
                      "radius_m": DIST}
    meta["landmarks_3d"], meta["landmarks_2d"], meta["landmarks_visible"] = lm, uv, visible.tolist()
    meta["model"].update(name=MODEL.name, sha256=model_sha, identity=beta.tolist(), expression=psi.tolist(),
                         joint_rotations={j: rot[i].tolist() for i, j in enumerate(MODEL.joint_names)},
                         head_pose=np.eye(4))
    return key, (rgba, depth, n.astype(np.float32), hit.astype(np.uint32)), meta


def make_dataset(root, model_path, identities=(0,), expressions: int = 2, views: int = 6, size: int = 16,
                 angles: dict | None = None) -> Path:
    """A dataset of the given identities (one shard each); ``angles`` maps a view index to fixed
    (azimuth, elevation) degrees instead of the spread."""
    root = Path(root)
    sha = sha256_file(model_path)
    expected = {f"shard_{i:06d}": [ff.frame_key(i, e, v) for e in range(expressions) for v in range(views)]
                for i in identities}
    ds = open_dataset(root, "b" * 64, expected)
    for sid, keys in expected.items():
        with ds.staging(sid) as st:
            for key in keys:
                i, e, v = ff.parse_frame_key(key)
                k, px, meta = frame(i, e, v, views, size, sha, (angles or {}).get(v))
                st.write_frame(k, *px, meta)
            st.commit(manifest_extra={"seeds": {"run": 0}, "versions": {"blender": "none"}})
    return root


#: input views of a held-out identity: frontal and +-45 degrees (view indices 0, 1, 2), then held-out views
INPUT_ANGLES = {0: (0.0, 0.0), 1: (45.0, 5.0), 2: (-45.0, 5.0), 3: (20.0, 10.0), 4: (-25.0, -5.0), 5: (150.0, 0.0)}
