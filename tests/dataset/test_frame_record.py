"""The frame-record builder (synth.dataset.frame_json.build_frame_record), without Blender."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np

from tests.support import fake_frames as ff
from synth.assets.classes import RECORD_ORDER
from synth.conventions import project
from synth.dataset.frame_json import (ModelEvaluation, RenderRecord, SceneRecord, build_frame_record,
                                     validate_frame_json)
from synth.dataset.layout import frame_key
from synth.io import dumps_json
from synth.plan.records import CameraSampling, Expression, Frame

#: A frame JSON written by the bpy worker (`synth render --identities 2 --expressions 2 --views 3
#: --preset ci --seed 7`, before the builder moved out of the worker), bytes as stored.
RENDERED = Path(__file__).resolve().parents[1] / "data" / "frame_ci_seed7_id000001_ex01_v02.json"

ORDER = ["frame_id", "identity_index", "expression_index", "view_index", "seed", "camera", "shard_id", "image",
         "model", "landmarks_3d", "landmarks_2d", "landmarks_visible", "assets", "skin", "lighting", "render",
         "software"]
MODEL_ORDER = ["name", "sha256", "identity", "expression", "expression_preset", "expression_kind",
               "joint_rotations", "pose", "head_pose"]


def _arguments(fj: dict) -> tuple[Frame, ModelEvaluation, SceneRecord, RenderRecord]:
    """Take a rendered frame JSON apart into what the worker has: the plan's frame and
    expression records (the expression with the plan's other keys, which must not leak into
    the record), numpy arrays."""
    m, r = fj["model"], fj["render"]
    frame = Frame.from_json({k: fj[k] for k in ORDER[:6]}, "frame")
    expression = Expression(fj["expression_index"], m["expression_kind"], m["expression_preset"],
                            tuple(m["expression"]), {}, m["pose"], CameraSampling(400, 0), None, (frame,))
    model = ModelEvaluation({"name": m["name"], "sha256": m["sha256"]}, np.array(m["identity"]), expression,
                            np.array(m["expression"]), {n: np.array(v) for n, v in m["joint_rotations"].items()},
                            np.array(m["head_pose"]), np.array(fj["landmarks_3d"]), np.array(fj["landmarks_2d"]),
                            np.array(fj["landmarks_visible"]))
    render = RenderRecord(fj["shard_id"], fj["image"]["width"], fj["image"]["height"], r["preset"],
                          {k: v for k, v in r.items() if k not in ("preset", "resolution", "seed")}, fj["software"])
    return frame, model, SceneRecord(fj["assets"], fj["skin"], fj["lighting"]), render


def test_rebuilds_a_rendered_frame_byte_for_byte():
    data = RENDERED.read_bytes()
    fj = json.loads(data)
    frame, model, scene, render = _arguments(fj)
    record = build_frame_record(frame, model, scene, render)
    assert list(record) == ORDER and list(record["model"]) == MODEL_ORDER
    assert dumps_json(record, indent=None) == data  # what StagingShard.write_frame stores
    assert validate_frame_json(record) == []
    record["camera"]["K"][0][0] = -1.0
    assert frame.camera.K[0][0] > 0  # the plan's frame is copied, not changed


def test_a_new_frame_validates_and_is_plain_json():
    key = frame_key(3, 1, 4)
    size = 32
    cam = ff.camera(size)
    frame = Frame.from_json({"frame_id": key, "identity_index": 3, "expression_index": 1, "view_index": 4, "seed": 99,
                             "camera": {**{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in cam.items()},
                                        "target": [0.0, 0.0, 0.0]}}, "frame")
    rng = np.random.default_rng(0)
    lm3 = rng.uniform(-0.08, 0.08, (68, 3)).astype(np.float32)  # any float dtype: stored as float64 values
    uv, z = project(cam["K"], cam["world_to_camera"], lm3)
    expression = Expression(1, "preset", "smile", (1.0, 1.0, 1.0), {}, {}, None, None, (frame,))
    model = ModelEvaluation({"name": "toy", "sha256": "0" * 64}, np.zeros(4, np.float32), expression, np.ones(3),
                            {"jaw": np.array([0.1, 0.0, 0.0]), "head": np.zeros(3)}, np.eye(4), lm3,
                            uv.astype(np.float32), z > 0)
    scene = SceneRecord({c: None for c in RECORD_ORDER}, {"melanin": 0.1},
                        {"environment": "uniform", "strength": 1.0, "color": (1.0, 1.0, 1.0)})
    render = RenderRecord("shard_000003", size, size, "ci",
                          {"engine": "CYCLES", "samples": 4, "denoiser": None, "device": "cpu"},
                          {"synth": "0", "blender": "none", "python": "3.11"})
    record = build_frame_record(frame, model, scene, render)
    assert validate_frame_json(record) == []
    assert record["image"] == {"width": size, "height": size, "file": f"{key}.exr",
                               "layers": ff.frame_json(key)["image"]["layers"]}
    assert record["render"] == {"preset": "ci", "resolution": [size, size], "seed": 99, "engine": "CYCLES",
                                "samples": 4, "denoiser": None, "device": "cpu"}
    assert record["model"]["expression_kind"] == "preset"
    assert list(record["model"]["joint_rotations"]) == ["jaw", "head"]
    assert record["landmarks_3d"][0] == [float(x) for x in lm3[0]]
    assert record["lighting"]["color"] == [1.0, 1.0, 1.0]
    json.dumps(record, allow_nan=False)  # plain JSON types only: no numpy, no tuples left
    assert record == json.loads(json.dumps(record))


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
