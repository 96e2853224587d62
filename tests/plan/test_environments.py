"""Several lighting environments per expression (``dataset.environments_per_expression``,
``--environments``): keys, frame records, draws from indices, and a one-environment plan's bytes."""

from __future__ import annotations

import filecmp
import json

import pytest

from synth.cli.main import main
from synth.config import LightingConfig
from synth.dataset.layout import frame_key, held_out, key_environment, parse_frame_key, parse_frame_key_env
from synth.errors import SynthError
from synth.plan import assets, io
from tests.support.toy_model import write_toy_model

SMALL = ["--seed", "7", "--set", "dataset.expressions_per_identity=2", "--set", "dataset.views_per_expression=3",
         "--set", "camera.min_separation_deg=10"]


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return write_toy_model(tmp_path_factory.mktemp("model") / "toy.npz")


def _plan(out, toy, n, *extra):
    assert main(["plan", "--identities", str(n), "--out", str(out), "--model", str(toy), "-q", *SMALL, *extra]) == 0
    return io.load_plan(out)


def _same_tree(a, b) -> bool:
    cmp = filecmp.dircmp(a, b)
    files = [p.relative_to(a) for p in a.rglob("*") if p.is_file()]
    return not cmp.left_only and not cmp.right_only and all(filecmp.cmp(a / f, b / f, shallow=False) for f in files)


def test_one_environment_plans_keep_their_bytes(tmp_path, toy):
    a = _plan(tmp_path / "a", toy, 2)
    b = _plan(tmp_path / "b", toy, 2, "--environments", "1")
    c = _plan(tmp_path / "c", toy, 2, "--set", "dataset.environments_per_expression=1")
    assert _same_tree(tmp_path / "a", tmp_path / "b") and _same_tree(tmp_path / "a", tmp_path / "c")
    assert "environments_per_expression" not in a.config["dataset"] and a.environments == 1
    spec = a.shard("shard_000000")
    e = spec["identities"][0]["expressions"][0]
    assert "environments" not in e and all("environment_index" not in f for f in e["frames"])
    assert [f["frame_id"] for f in e["frames"]] == ["id000000_ex00_v00", "id000000_ex00_v01", "id000000_ex00_v02"]


def test_every_view_in_every_environment(tmp_path, toy):
    one = _plan(tmp_path / "one", toy, 2)
    three = _plan(tmp_path / "three", toy, 2, "--environments", "3")
    assert three.environments == 3 and three.config["dataset"]["environments_per_expression"] == 3
    assert three.header["num_frames"] == 2 * 2 * 3 * 3 and three.plan_hash != one.plan_hash
    assert json.loads((tmp_path / "three" / "summary.json").read_text())["frames"] == 36
    drawn = []
    for sid in three.shard_ids():
        spec = three.shard(sid, validate_spec=True)
        base = one.shard(sid)
        assert [f["frame_id"] for i in spec["identities"] for e in i["expressions"] for f in e["frames"]] \
            == three.frame_keys(sid)
        for ident, ident1 in zip(spec["identities"], base["identities"]):
            for e, e1 in zip(ident["expressions"], ident1["expressions"]):
                envs = e["environments"]
                assert len(envs) == 3 and envs[0] == ident["lighting"] == ident1["lighting"]
                assert all(x["environment"] == "studio" for x in envs)
                drawn += [x["rotation_deg"] for x in envs[1:]]
                assert len(e["frames"]) == 9
                for n, f in enumerate(e["frames"]):
                    k, v = divmod(n, 3)
                    assert (f["environment_index"], f["view_index"]) == (k, v)
                    assert f["frame_id"] == frame_key(ident["identity_index"], e["expression_index"], v, k)
                    # the same camera and render seed in every environment: the one-environment frame
                    f1 = e1["frames"][v]
                    assert {x: y for x, y in f.items() if x not in ("frame_id", "environment_index")} \
                        == {x: y for x, y in f1.items() if x != "frame_id"}
                rest = {x: y for x, y in e.items() if x not in ("frames", "environments")}
                assert rest == {x: y for x, y in e1.items() if x != "frames"}
    assert len(set(drawn)) == len(drawn) == 2 * 2 * 2  # drawn per (identity, expression, environment)
    assert all(-180.0 <= r <= 180.0 for r in drawn)


def test_environments_depend_on_indices_only(tmp_path, toy):
    whole = _plan(tmp_path / "whole", toy, 3, "--environments", "2")
    part = _plan(tmp_path / "part", toy, 1, "--environments", "2", "--start", "2")
    assert part.shard("shard_000002") == whole.shard("shard_000002")
    lc = LightingConfig(environment="hdri", hdri_files=("a.exr", "b.exr", "c.exr"), hdri_rotation_deg=(-30.0, 30.0))
    got = [assets.sample_environment(7, i, e, k, lc) for i in range(4) for e in range(3) for k in (1, 2)]
    assert got == [assets.sample_environment(7, i, e, k, lc) for i in range(4) for e in range(3) for k in (1, 2)]
    assert {g["file"] for g in got} == {"a.exr", "b.exr", "c.exr"}
    assert all(g["environment"] == "hdri" and -30.0 <= g["rotation_deg"] <= 30.0 for g in got)
    assert assets.sample_environment(8, 0, 0, 1, lc) != assets.sample_environment(7, 0, 0, 1, lc) \
        or assets.sample_environment(8, 0, 1, 1, lc) != assets.sample_environment(7, 0, 1, 1, lc)


def test_frame_keys_name_the_environment():
    assert frame_key(42, 7, 13) == "id000042_ex07_v13" and frame_key(42, 7, 13, 1) == "id000042_ex07_en01_v13"
    assert parse_frame_key("id000042_ex07_en01_v13") == (42, 7, 13)
    assert parse_frame_key_env("id000042_ex07_en01_v13") == (42, 7, 1, 13)
    assert parse_frame_key_env("id000042_ex07_v13") == (42, 7, 0, 13) and key_environment("id000042_ex07_v13") == 0
    for bad in ("id000042_ex07_en1_v13", "id000042_ex07_v13_en01", "id000042_ex07_en01"):
        with pytest.raises(SynthError, match="bad frame key"):
            parse_frame_key_env(bad)
    with pytest.raises(SynthError, match="environment 100"):
        frame_key(1, 1, 1, 100)
    keys = [frame_key(0, 0, v, k) for k in range(2) for v in range(3)]
    assert held_out(keys, 1, "--val-views", "x") == [False, False, True, False, False, True]
    with pytest.raises(SynthError, match="identity 0 expression 0 environment 1 has 1 view"):
        held_out(keys[:3] + keys[3:4], 1, "--val-views", "x")


def test_the_prior_reads_environment_0_only():
    from prior.data.sources import PRIOR_ENVIRONMENT, _wanted

    assert PRIOR_ENVIRONMENT == 0
    assert _wanted("id000001_ex00_v02", None) and _wanted("id000001_ex00_en00_v02", 1)
    assert not _wanted("id000001_ex00_en01_v02", None) and not _wanted("id000001_ex00_en00_v02", 2)
