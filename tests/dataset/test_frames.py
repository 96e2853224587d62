"""Frame JSON: keys, schema + consistency checks, strict reader, atomic writer (round trip)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.support import fake_frames as ff
from synth.errors import SynthError
from synth.dataset.frame_json import frame_schema, jsonable, read_frame_json, validate_frame_json, write_frame_json
from synth.dataset.layout import frame_key, parse_frame_key, shard_name

KEY = "id000042_ex07_v13"


def test_keys():
    assert frame_key(42, 7, 13) == KEY and parse_frame_key(KEY) == (42, 7, 13)
    assert sorted([frame_key(1, 0, 10), frame_key(1, 0, 2), frame_key(0, 5, 0)]) == [
        "id000000_ex05_v00", "id000001_ex00_v02", "id000001_ex00_v10"]
    for bad in [(-1, 0, 0), (10**6, 0, 0), (0, 100, 0)]:
        with pytest.raises(SynthError):
            frame_key(*bad)
    for bad in ("id42_ex7_v13", "id000042_ex07_v13.json", None):
        with pytest.raises(SynthError):
            parse_frame_key(bad)
    assert shard_name(42) == "shard_000042" and shard_name(0) < shard_name(9) < shard_name(10)
    for bad in (-1, 10**6):
        with pytest.raises(SynthError):
            shard_name(bad)


def test_schema_is_valid_draft_2020_12():
    import jsonschema

    s = frame_schema()
    assert s["$schema"].endswith("2020-12/schema")
    jsonschema.Draft202012Validator.check_schema(s)


def test_fake_frame_round_trip(tmp_path):
    fj = ff.frame_json(KEY)  # holds numpy arrays: the writer converts them
    p = tmp_path / f"{KEY}.json"
    write_frame_json(p, fj)
    back = read_frame_json(p)
    assert back == json.loads(json.dumps(jsonable(fj)))
    assert validate_frame_json(back) == []
    assert [x.name for x in tmp_path.iterdir()] == [p.name]


def _mutations():
    def drop(k):
        return lambda f: f.pop(k)

    def setp(path, v):
        def m(f):
            d = f
            for k in path[:-1]:
                d = d[k]
            d[path[-1]] = v
        return m

    return {
        "missing model": (drop("model"), "model"),
        "bad key": (setp(["frame_id"], "id1_ex2_v3"), "frame_id"),
        "key vs indices": (setp(["view_index"], 14), "disagrees with the indices"),
        "67 landmarks": (lambda f: f.__setitem__("landmarks_2d", f["landmarks_2d"][:67]), "landmarks_2d"),
        "K 2x3": (setp(["camera", "K"], [[1, 0, 0], [0, 1, 0]]), "camera/K"),
        "asset missing id": (setp(["assets", "hair"], {"params": {}}), "assets/hair"),
        "asset class missing": (lambda f: f["assets"].pop("iris"), "assets"),
        "image file": (setp(["image", "file"], "id000042_ex07_v12.exr"), "image/file"),
        "layers": (setp(["image", "layers"], ["R", "G", "B"]), "image/layers"),
        "size": (setp(["camera", "width"], 99), "differs from image"),
        "near/far": (setp(["camera", "near"], 20.0), "near"),
        "not inverse": (lambda f: f["camera"]["camera_to_world"][0].__setitem__(3, 5.0), "identity"),
        "not rigid": (lambda f: f["camera"]["world_to_camera"][0].__setitem__(0, 2.0),
                      "camera/world_to_camera: not a rigid"),
        "c2w last row": (lambda f: f["camera"]["camera_to_world"][3].__setitem__(0, 0.1),
                         "camera/camera_to_world: not a rigid"),
        "head pose mirrored": (lambda f: f["model"].__setitem__("head_pose", [[-1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0],
                                                                              [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]),
                               "model/head_pose: not a rigid"),
        "lm projection": (lambda f: f["landmarks_2d"][3].__setitem__(0, f["landmarks_2d"][3][0] + 0.5),
                          "landmarks_2d"),
        "sha": (setp(["model", "sha256"], "xyz"), "model/sha256"),
        "software": (lambda f: f["software"].pop("blender"), "software"),
    }


@pytest.mark.parametrize("name", list(_mutations()))
def test_invalid_frames_are_reported(name):
    mutate, expect = _mutations()[name]
    fj = jsonable(ff.frame_json(KEY))
    assert validate_frame_json(fj) == []
    mutate(fj)
    errs = validate_frame_json(fj)
    assert errs and any(expect in e for e in errs), errs


def test_reader_refuses_nan_and_garbage(tmp_path):
    p = tmp_path / "f.json"
    p.write_text('{"a": NaN}')
    with pytest.raises(SynthError, match="does not parse"):
        read_frame_json(p, validate=False)
    p.write_text("{")
    with pytest.raises(SynthError, match="does not parse"):
        read_frame_json(p)
    p.write_text("{}")
    with pytest.raises(SynthError, match="invalid frame JSON"):
        read_frame_json(p)


def test_writer_refuses_invalid_and_non_finite(tmp_path):
    fj = ff.frame_json(KEY)
    fj["skin"] = {"roughness": np.float64("nan")}
    with pytest.raises(SynthError, match="not JSON-serialisable"):
        write_frame_json(tmp_path / "f.json", fj)
    with pytest.raises(SynthError, match="invalid frame JSON"):
        write_frame_json(tmp_path / "f.json", {"frame_id": KEY})
    assert list(tmp_path.iterdir()) == []


def test_dataset_modules_import_on_their_own():
    """Each module of the dataset package imports first in a fresh interpreter (no cycles)."""
    import subprocess
    import sys

    for mod in ("synth.dataset", "synth.dataset.layout", "synth.dataset.exr", "synth.dataset.frame_json",
                "synth.dataset.staging", "synth.dataset.shards", "synth.dataset.validate", "synth.dataset.preview"):
        r = subprocess.run([sys.executable, "-c", f"import {mod}"], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
