"""The typed plan records (synth.plan.records, synth.assets.params): the shard spec's wire
format round-trips byte for byte, defaults come from the records, bad specs give one line."""

from __future__ import annotations

import copy

import orjson
import pytest

from synth.appearance.skin import DEFAULT_HAEMOGLOBIN
from synth.assets.params import DEFAULT_REACH, BeardParams, HairParams, IrisParams, SkinParams
from synth.cli.main import main
from synth.errors import SynthError
from synth.plan import io
from synth.plan.records import AssetPick, ShardSpec, StudioLight, lighting_from_json


@pytest.fixture(scope="module")
def plan(tmp_path_factory):
    """A real plan: 12 identities of the default model, two environments per expression."""
    out = tmp_path_factory.mktemp("records") / "plan"
    assert main(["plan", "--identities", "12", "--environments", "2", "--out", str(out), "-q"]) == 0
    return io.load_plan(out)


def test_every_shard_round_trips_byte_for_byte(plan):
    seen = set()
    for sid in plan.shard_ids():
        raw = (plan.root / "shards" / f"{sid}.json").read_bytes()
        spec = plan.shard_spec(sid)
        assert orjson.dumps(spec.to_json()) == raw
        assert ShardSpec.from_json(orjson.loads(raw)) == spec
        for ident in spec.identities:
            seen |= {c for c, e in ident.assets.items() if e is not None}
            assert ident.expressions[0].environments is not None
    assert {"skin", "iris", "hair", "garment"} <= seen


def test_defaults_are_filled_and_the_planned_values_kept(plan):
    ident = plan.shard_spec(plan.shard_ids()[0]).identities[0]
    skin = ident.skin
    assert isinstance(skin, SkinParams) and skin.planned("melanin") and skin.planned("haemoglobin")
    assert skin.pore_strength == 0.15 and not skin.planned("pore_strength")  # a default: not written back
    assert "pore_strength" not in skin.to_json()
    assert skin.noise_seed == pytest.approx(7.31 * skin.detail_variant)
    assert SkinParams().haemoglobin == DEFAULT_HAEMOGLOBIN
    assert BeardParams.of("stubble").length_m == 0.0015 and BeardParams.of("stubble").reach == DEFAULT_REACH
    assert HairParams.of("short_curly").curl == 0.9 and HairParams.of("bob").parting == "centre"
    assert IrisParams.of("x", {"melanin": 0.2}).stroma_scatter == 0.75
    assert IrisParams.of("x", {"melanin": 0.2, "stroma_scatter": 0.1}).stroma_scatter == 0.1
    pick = AssetPick.of("garment", "coat", {"colour_hsv": [0.1, 0.2, 0.3]})
    assert pick.params.colour_hsv == (0.1, 0.2, 0.3) and pick.params.fabric == "wool_felt"
    assert orjson.dumps(pick.to_json()) == b'{"id":"coat","generator":"procedural:garment_shell",' \
                                          b'"params":{"colour_hsv":[0.1,0.2,0.3]}}'


def _one_line(spec: dict) -> str:
    with pytest.raises(SynthError) as e:
        ShardSpec.from_json(spec, "shard_000000.json")
    msg = str(e.value)
    assert "\n" not in msg and "shard_000000.json" in msg
    return msg


def test_a_bad_spec_gives_one_clear_line(plan):
    good = orjson.loads((plan.root / "shards" / f"{plan.shard_ids()[0]}.json").read_bytes())
    bad = copy.deepcopy(good)
    del bad["identities"][0]["expressions"][0]["frames"][0]["seed"]
    assert "'seed' is missing" in _one_line(bad) and "frames/0" in _one_line(bad)
    bad = copy.deepcopy(good)
    bad["identities"][0]["assets"]["skin"]["params"]["roughness"] = "shiny"
    assert "not a float" in _one_line(bad)
    bad = copy.deepcopy(good)
    bad["identities"][0]["assets"]["skin"]["params"]["glow"] = 1.0
    assert "'glow'" in _one_line(bad)
    bad = copy.deepcopy(good)
    bad["identities"][0]["skin"]["melanin"] = 0.5
    assert "copy of assets.skin.params" in _one_line(bad)
    bad = copy.deepcopy(good)
    bad["identities"][0]["expressions"][0]["frames"][0]["camera"]["K"] = [[1, 0], [0, 1]]
    assert "3x3" in _one_line(bad)
    bad = copy.deepcopy(good)
    bad["format_version"] = 2
    assert "version 2" in _one_line(bad)


def test_lighting_records_keep_their_key_order():
    studio = {"environment": "studio", "strength": 1.0, "color": [1.0, 1.0, 1.0], "key_deg": [-35.0, 30.0],
              "key_size_deg": 25.0, "key_share": 0.45, "fill_deg": [60.0, 5.0], "fill_size_deg": 45.0,
              "fill_share": 0.2, "rotation_deg": 12.5}
    rec = lighting_from_json(studio, "lighting")
    assert isinstance(rec, StudioLight) and rec.studio().rotation_deg == 12.5
    assert orjson.dumps(rec.to_json()) == orjson.dumps(studio)
    with pytest.raises(SynthError, match="unknown environment"):
        lighting_from_json({"environment": "sun", "strength": 1.0}, "lighting")


def test_an_external_pick_keeps_its_pack_record():
    pick = {"id": "test_cap", "generator": "blend:caps/cap.blend", "params": {},
            "pack": {"class": "hair", "file": "caps/cap.blend", "asset_root": "/packs", "object": "Cap",
                     "sha256": "0" * 64, "anchor": "head", "reference_width_m": 0.15}}
    rec = AssetPick.from_json("hair", pick, "hair")
    assert rec.external and rec.pack.cls == "hair" and rec.pack.reference_width_m == 0.15
    assert orjson.dumps(rec.to_json()) == orjson.dumps(pick)
    with pytest.raises(SynthError, match="'object' is missing"):
        AssetPick.from_json("hair", {**pick, "pack": {k: v for k, v in pick["pack"].items() if k != "object"}}, "hair")
