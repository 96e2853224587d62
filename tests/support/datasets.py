"""Small committed datasets made without Blender, for the tests that need one.

- reliability tests (tests/cli, tests/dataset): :func:`fake_render` commits a real plan
  (``synth plan`` on the toy model) with fake frames through the dataset API, so that
  ``synth render`` with :func:`render_args` finds it complete, ``synth validate`` passes, and a
  test can damage it in one precise way (:func:`tamper_frame`, :func:`reseal`);
- export and report tests (tests/export, tests/report): :func:`marked_dataset`, frames whose
  only covered pixels are the pixels the frame's own camera projects some 3D landmarks into
  (alpha 1, grey, depth = the landmark's z), at a non-square size with an off-centre principal
  point, so the exported pixels can be checked against any camera model;
  :func:`model_dataset`, frames of the toy head model (tests/support/toy_model.py): codes,
  joint rotations, landmarks_3d and landmarks_2d as the worker computes them, cameras on an
  orbit around the head; pixels are fake_frames' sphere.

Both take ``shard_format="tar"`` to commit tar shards instead of directories.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np

from synth.appearance.skin import skin_albedo
from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
from synth.dataset.exr import camera_attributes
from synth.dataset.layout import frame_key, parse_frame_key, shard_name
from synth.dataset.shards import open_dataset
from synth.io import sha256_file
from tests.support import fake_frames
from tests.support.toy_model import make_toy_model, write_toy_model

#: Plan settings of the fake datasets: 1 expression and 2 views per identity, one shard each.
SETS = ["dataset.expressions_per_identity=1", "dataset.views_per_expression=2", 'render.preset="ci"']
SEED = 7


def render_args(n: int, model: Path, out: Path) -> list[str]:
    """``synth render`` arguments that give the plan of :func:`fake_render`."""
    args = ["render", "--identities", str(n), "--model", str(model), "--seed", str(SEED), "--out", str(out)]
    for s in SETS:
        args += ["--set", s]
    return args


def fake_render(out: Path, model: Path, n: int = 2, shards: list[str] | None = None) -> Path:
    """Plan ``n`` identities into ``out/plan`` and commit every (or the given) shard with fake
    frames, as ``synth render`` would lay the dataset out. Returns ``out``."""
    from renderer_jobs.submit import prepare_plan
    from synth.plan.io import load_plan

    pdir = prepare_plan(out, n, None, SETS, SEED, model)
    plan = load_plan(pdir)
    ds = open_dataset(out, plan.plan_hash, plan.expected(), meta={"plan_dir": "plan"})
    fake_frames.render_dataset(ds, shards=shards)
    return out


def writable_copy(src: Path, dst: Path) -> Path:
    """A copy of a dataset whose committed files may be edited."""
    shutil.copytree(src, dst, symlinks=True)
    for p in dst.rglob("*"):
        if not p.is_symlink():
            os.chmod(p, 0o755 if p.is_dir() else 0o644)
    return dst


def defects_found(root: Path, **kw) -> set[tuple]:
    """(shard, key, kind) of every defect ``synth validate`` finds in ``root`` (keyword arguments go to
    :func:`synth.dataset.validate.validate_dataset`)."""
    from synth.dataset.validate import validate_dataset

    return {(d.shard, d.key, d.kind) for d in validate_dataset(root, **kw).defects}


def first_frame(root: Path, shard: str = "shard_000000") -> tuple[Path, Path]:
    """(the shard directory, the first frame JSON in it)."""
    sd = root / "shards" / shard
    return sd, sorted(p for p in sd.glob("id*.json"))[0]


def reseal(shard_dir: Path, name: str) -> None:
    """Update the manifest entry of ``name`` to the file's current bytes (what a tamperer who
    wants ``synth validate`` to pass would do)."""
    data = (shard_dir / name).read_bytes()
    man = shard_dir / "manifest.json"
    m = json.loads(man.read_text())
    m["files"][name] = {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}
    os.chmod(man, 0o644)
    man.write_text(json.dumps(m, indent=1))


def tamper_frame(root: Path, shard: str = "shard_000000") -> Path:
    """Edit a committed frame's JSON (its size changes) and reseal its manifest entry."""
    sd, js = first_frame(root, shard)
    os.chmod(js, 0o644)
    fj = json.loads(js.read_text())
    fj["seed"] = fj["seed"] + 1000
    js.write_text(json.dumps(fj) + "   ")
    reseal(sd, js.name)
    return js


GREY = 0.2159  # linear; 8-bit sRGB 128 (0.2158 +- half-float rounding)


def _camera(key: str, W: int, H: int, radius: float = 0.9, target=(0.0, 0.0, 0.0)) -> dict:
    i, e, v = parse_frame_key(key)
    rng = np.random.default_rng([i, e, v, 7])
    K = intrinsics(W, H, 38.0, rng.uniform(-2.0, 2.0, 2))
    az, el = rng.uniform(-70, 70), rng.uniform(-30, 30)
    c2w = orbit_camera_to_world(az, el, radius, target, rng.uniform(-10, 10))
    return {"K": K, "world_to_camera": invert_rigid(c2w), "camera_to_world": c2w, "width": W, "height": H,
            "near": 0.05, "far": 10.0, "azimuth_deg": az, "elevation_deg": el, "radius_m": radius,
            "target": list(target)}


def _with_camera(fj: dict, cam: dict, lm3: np.ndarray) -> dict:
    W, H = cam["width"], cam["height"]
    uv, z = project(cam["K"], cam["world_to_camera"], lm3)
    fj["camera"] = cam
    fj["image"].update(width=W, height=H)
    fj["render"]["resolution"] = [W, H]
    fj["landmarks_3d"], fj["landmarks_2d"] = lm3, uv
    fj["landmarks_visible"] = ((z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)).tolist()
    return fj


def _commit(root: Path, keys: list[str], make, shard_format: str | None = None) -> Path:
    exp = {}
    for k in keys:
        exp.setdefault(shard_name(parse_frame_key(k)[0]), []).append(k)
    ds = open_dataset(root, "e" * 64, exp, shard_format=shard_format)
    for sid in ds.pending_shards():
        with ds.staging(sid) as st:
            for key in st.expected_keys:
                px, fj = make(key)
                cam = fj["camera"]
                st.write_frame(key, *px, fj, exr_header=camera_attributes(cam["K"], cam["world_to_camera"],
                                                                           cam["width"], cam["height"]))
            st.commit(manifest_extra={"seeds": {}, "versions": {}})
    return root


def marked_pixels(fj: dict, n: int = 14) -> list[tuple[int, int, int]]:
    """(landmark, column, row) of the first ``n`` landmarks that fall in distinct pixels inside
    the image, in front of the camera (the pixels :func:`marked_dataset` covers)."""
    cam = fj["camera"]
    uv, z = project(cam["K"], cam["world_to_camera"], np.asarray(fj["landmarks_3d"]))
    out, seen = [], set()
    for i, ((u, v), zi) in enumerate(zip(uv, z)):
        c, r = int(np.floor(u)), int(np.floor(v))
        # keep off pixel borders, so the marked pixel is unambiguous
        if zi > 0 and 0 <= c < cam["width"] and 0 <= r < cam["height"] and (c, r) not in seen \
                and min(u - c, c + 1 - u, v - r, r + 1 - v) > 0.05:
            seen.add((c, r))
            out.append((i, c, r))
        if len(out) == n:
            break
    return out


def marked_dataset(root: Path, W: int = 48, H: int = 36, views: int = 3, shard_format: str | None = None) -> Path:
    keys = [frame_key(0, 0, v) for v in range(views)] + [frame_key(0, 1, 0), frame_key(1, 0, 0)]

    def make(key):
        fj = fake_frames.frame_json(key, 16)
        lm3 = np.random.default_rng(list(parse_frame_key(key))).uniform(-0.09, 0.09, (68, 3))
        fj = _with_camera(fj, _camera(key, W, H), lm3)
        rgba = np.zeros((H, W, 4), np.float32)
        depth = np.zeros((H, W), np.float32)
        seg = np.zeros((H, W), np.uint32)
        _, z = project(fj["camera"]["K"], fj["camera"]["world_to_camera"], lm3)
        for i, c, r in marked_pixels(fj):
            rgba[r, c] = (GREY, GREY, GREY, 1.0)
            depth[r, c] = z[i]
            seg[r, c] = 1
        return (rgba, depth, np.zeros((H, W, 3), np.float32), seg), fj

    return _commit(root, keys, make, shard_format)


def model_dataset(root: Path, identities: int = 1, expressions: int = 2, views: int = 3, size: int = 24,
                  shard_format: str | None = None):
    """(dataset dir, model file). The head model file is written to ``root.parent``."""
    from synth.model.head import HeadModel

    model_path = write_toy_model(root.parent / f"{root.name}-toy.npz")
    data = make_toy_model()
    hm = HeadModel(data)
    sha = sha256_file(model_path)
    keys = [frame_key(i, e, v) for i in range(identities) for e in range(expressions) for v in range(views)]

    def make(key):
        i, e, v = parse_frame_key(key)
        rng = np.random.default_rng([i, e, 3])
        beta = np.random.default_rng([i, 5]).normal(0, 1, hm.Ki)
        psi = np.zeros(hm.Ke) if e == 0 else rng.uniform(0, 1, hm.Ke)
        rot = np.zeros((hm.J, 3))
        rot[hm.joint_index["jaw"]] = [0.2 * e, 0.0, 0.0]
        rot[hm.joint_index["head"]] = rng.normal(0, 0.05, 3)
        ev = hm.evaluate(beta, psi, rot)
        fj = fake_frames.frame_json(key, size)
        fj["model"] = {"name": data.name, "sha256": sha, "identity": beta.tolist(), "expression": psi.tolist(),
                       "expression_preset": "smile" if e == 1 else None,
                       "expression_kind": ["neutral", "preset", "random"][min(e, 2)],
                       "joint_rotations": {n: rot[j].tolist() for n, j in hm.joint_index.items()},
                       "pose": None, "head_pose": ev.joint_transforms[0, hm.joint_index["head"]].astype(np.float64)}
        fj["assets"]["hair"] = {"id": "short", "generator": "procedural:hair_strands", "params": {}, "build": {}}
        if i % 2:
            fj["assets"]["glasses"] = {"id": "round", "generator": "procedural:glasses_frame", "params": {},
                                       "build": {}}
        melanin = 0.05 + 0.1 * i
        fj["skin"] = {"melanin": melanin, "albedo_linear_srgb": list(skin_albedo(melanin, 0.02))}
        fj = _with_camera(fj, _camera(key, size, size), ev.landmarks["ibug68"][0].astype(np.float64))
        return fake_frames.pixels(key, size), fj

    return _commit(root, keys, make, shard_format), model_path
