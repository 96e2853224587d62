"""prior.data.plan.read_plan: the plan's identity -> shards map, read in blocks, equals the one
from the whole parsed dataset.json; a damaged file gives one SynthError line."""

from __future__ import annotations

import pytest

from prior.data import plan as plan_mod
from synth.dataset.layout import DATASET_FORMAT, frame_key, parse_frame_key
from synth.dataset.shards import load_dataset
from synth.errors import SynthError
from synth.io import atomic_write_json


def _write(root, expected, indent=1, **extra):
    root.mkdir(parents=True, exist_ok=True)
    info = {"format": DATASET_FORMAT, "plan_hash": "c" * 64, "shard_format": "tar",
            "meta": {"config": {"x": ["id000009_ex00_v00"], "expected": {"shard_x": [1]}}}, "expected": expected,
            **extra}
    atomic_write_json(root / "dataset.json", info, durable=False, indent=indent)
    return root


def _expected():
    # identity 3 spread over two shards; shard_000002 holds identities 4 and 5
    return {"shard_000000": [frame_key(3, e, v) for e in range(2) for v in range(3)],
            "shard_000001": [frame_key(3, 2, v) for v in range(3)],
            "shard_000002": sorted([frame_key(5, 0, v) for v in range(40)] + [frame_key(4, 1, 0)])}


@pytest.mark.parametrize("indent", [1, None])
@pytest.mark.parametrize("block", [7, 64, 1 << 18])
def test_read_plan_matches_the_parsed_dataset_json(tmp_path, monkeypatch, indent, block):
    root = _write(tmp_path / "d", _expected(), indent=indent)
    monkeypatch.setattr(plan_mod, "BLOCK", block)
    ds = load_dataset(root)
    want: dict[int, list[str]] = {}
    for sid, keys in ds.expected.items():
        for k in keys:
            s = want.setdefault(parse_frame_key(k)[0], [])
            if sid not in s:
                s.append(sid)
    top, got = plan_mod.read_plan(root)
    assert got == want == {3: ["shard_000000", "shard_000001"], 4: ["shard_000002"], 5: ["shard_000002"]}
    assert top["plan_hash"] == ds.plan_hash and top["format"] == DATASET_FORMAT


@pytest.mark.parametrize("damage, says", [
    (lambda b: b[:len(b) // 2], "damaged"),
    (lambda b: b.replace(b'"id000005_ex00_v07"', b'"id5_ex0_v7"'), "bad frame key 'id5_ex0_v7'"),
    (lambda b: b.replace(b'"format": "', b'"format": "x'), "is not a synth-dataset"),
    (lambda b: b + b"{}", "text after its end"),
    (lambda b: b.replace(b'"expected"', b'"expectedx"'), "is not a synth-dataset"),
    (lambda b: b.replace(b"]", b"}", 1), "brackets do not match"),
])
def test_a_damaged_dataset_json_is_one_clear_line(tmp_path, monkeypatch, damage, says):
    root = _write(tmp_path / "d", _expected())
    p = root / "dataset.json"
    p.write_bytes(damage(p.read_bytes()))
    monkeypatch.setattr(plan_mod, "BLOCK", 16)
    with pytest.raises(SynthError) as e:
        plan_mod.read_plan(root)
    assert says in e.value.what and e.value.where == str(p)
