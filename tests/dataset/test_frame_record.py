"""The frame-record builder (synth.dataset.frame_json.build_frame_record), without Blender."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np

from tests.support import fake_frames as ff
from synth.assets.classes import RECORD_ORDER
from synth.conventions import project
from synth.dataset.frame_json import build_frame_record, validate_frame_json
from synth.dataset.layout import frame_key
from synth.io import dumps_json

#: A frame JSON written by the bpy worker (`synth render --identities 2 --expressions 2 --views 3
#: --preset ci --seed 7`, before the builder moved out of the worker), bytes as stored.
RENDERED = Path(__file__).resolve().parents[1] / "data" / "frame_ci_seed7_id000001_ex01_v02.json"

ORDER = ["frame_id", "identity_index", "expression_index", "view_index", "seed", "camera", "shard_id", "image",
         "model", "landmarks_3d", "landmarks_2d", "landmarks_visible", "assets", "skin", "lighting", "render",
         "software"]
MODEL_ORDER = ["name", "sha256", "identity", "expression", "expression_preset", "expression_kind",
               "joint_rotations", "pose", "head_pose"]


def _arguments(fj: dict) -> tuple[dict, dict]:
    """Take a rendered frame JSON apart into what the worker has: the plan's frame and
    expression (with the plan's other keys, which must not leak into the record), numpy arrays."""
    m, r = fj["model"], fj["render"]
    planned = {k: fj[k] for k in ORDER[:6]}
    planned_expression = {"expression_index": fj["expression_index"], "kind": m["expression_kind"],
                          "preset": m["expression_preset"], "expression_code": m["expression"], "pose": m["pose"],
                          "camera_sampling": {"candidates": 400, "restarts": 0}, "frames": [planned]}
    return planned, dict(
        shard_id=fj["shard_id"], width=fj["image"]["width"], height=fj["image"]["height"],
        model_info={"name": m["name"], "sha256": m["sha256"]}, identity_code=np.array(m["identity"]),
        planned_expression=planned_expression, expression_code=np.array(m["expression"]),
        joint_rotations={n: np.array(v) for n, v in m["joint_rotations"].items()}, head_pose=np.array(m["head_pose"]),
        landmarks_3d=np.array(fj["landmarks_3d"]), landmarks_2d=np.array(fj["landmarks_2d"]),
        landmarks_visible=np.array(fj["landmarks_visible"]), assets=fj["assets"], skin=fj["skin"],
        lighting=fj["lighting"], render_preset=r["preset"],
        render_settings={k: v for k, v in r.items() if k not in ("preset", "resolution", "seed")},
        software=fj["software"])


def test_rebuilds_a_rendered_frame_byte_for_byte():
    data = RENDERED.read_bytes()
    fj = json.loads(data)
    planned, kw = _arguments(fj)
    before = copy.deepcopy(planned)
    record = build_frame_record(planned, **kw)
    assert list(record) == ORDER and list(record["model"]) == MODEL_ORDER
    assert dumps_json(record, indent=None) == data  # what StagingShard.write_frame stores
    assert validate_frame_json(record) == []
    assert planned == before  # the plan's frame is copied, not changed


def test_a_new_frame_validates_and_is_plain_json():
    key = frame_key(3, 1, 4)
    size = 32
    cam = ff.camera(size)
    planned = {"frame_id": key, "identity_index": 3, "expression_index": 1, "view_index": 4, "seed": 99,
               "camera": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in cam.items()}}
    rng = np.random.default_rng(0)
    lm3 = rng.uniform(-0.08, 0.08, (68, 3)).astype(np.float32)  # any float dtype: stored as float64 values
    uv, z = project(cam["K"], cam["world_to_camera"], lm3)
    record = build_frame_record(
        planned, shard_id="shard_000003", width=size, height=size, model_info={"name": "toy", "sha256": "0" * 64},
        identity_code=np.zeros(4, np.float32), planned_expression={"kind": "preset", "preset": "smile", "pose": {}},
        expression_code=np.ones(3), joint_rotations={"jaw": np.array([0.1, 0.0, 0.0]), "head": np.zeros(3)},
        head_pose=np.eye(4), landmarks_3d=lm3, landmarks_2d=uv.astype(np.float32), landmarks_visible=z > 0,
        assets={c: None for c in RECORD_ORDER}, skin={"melanin": 0.1}, lighting={"environment": "uniform"},
        render_preset="ci", render_settings={"engine": "CYCLES", "samples": 4, "denoiser": None, "device": "cpu"},
        software={"synth": "0", "blender": "none", "python": "3.11"})
    assert validate_frame_json(record) == []
    assert record["image"] == {"width": size, "height": size, "file": f"{key}.exr",
                               "layers": ff.frame_json(key)["image"]["layers"]}
    assert record["render"] == {"preset": "ci", "resolution": [size, size], "seed": 99, "engine": "CYCLES",
                                "samples": 4, "denoiser": None, "device": "cpu"}
    assert record["model"]["expression_kind"] == "preset"
    assert list(record["model"]["joint_rotations"]) == ["jaw", "head"]
    assert record["landmarks_3d"][0] == [float(x) for x in lm3[0]]
    json.dumps(record, allow_nan=False)  # plain JSON types only: no numpy left


def _schema_errors(obj) -> list[str]:
    """The whole schema's messages, jsonschema over every element (no fast path)."""
    from synth.dataset import frame_json

    errs = sorted(frame_json._validator().iter_errors(obj), key=lambda e: (list(map(str, e.absolute_path)), e.message))
    return [f"{frame_json._path(e)}: {e.message if len(e.message) < 200 else e.message[:200] + '...'}" for e in errs]


def test_the_fast_path_of_plain_arrays_finds_what_the_whole_schema_finds():
    fj = json.loads(RENDERED.read_bytes())
    assert validate_frame_json(fj) == _schema_errors(fj) == []
    damage = [("landmarks_3d", 5, [0.0, 0.0]), ("landmarks_3d", 5, [0.0, True, 1.0]), ("landmarks_2d", 0, "x"),
              ("landmarks_visible", 3, 1), ("landmarks_2d", 67, [1.0, None])]
    for field, i, value in damage:
        bad = copy.deepcopy(fj)
        bad[field][i] = value
        assert validate_frame_json(bad) == _schema_errors(bad) != [], (field, value)
    for mutate in (lambda f: f["landmarks_3d"].pop(), lambda f: f["camera"]["K"][1].append(0.0),
                   lambda f: f["model"].__setitem__("identity", 3), lambda f: f["camera"].pop("K"),
                   lambda f: f["model"]["expression"].append(False), lambda f: f.__setitem__("camera", [1])):
        bad = copy.deepcopy(fj)
        mutate(bad)
        assert validate_frame_json(bad) == _schema_errors(bad) != []
