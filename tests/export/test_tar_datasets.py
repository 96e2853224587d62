"""The exports and the report read a tar dataset (dataset.shard_format = "tar") exactly as the
directory dataset of the same frames."""

from __future__ import annotations

import json
import os

import pytest

from synth.dataset.reader import list_frames
from synth.export.nerfstudio import export_nerfstudio
from tests.support.datasets import marked_dataset, model_dataset

pytest.importorskip("OpenEXR")


def _files(root) -> dict[str, bytes]:
    return {os.path.relpath(os.path.join(d, n), root): open(os.path.join(d, n), "rb").read()
            for d, _, names in os.walk(root) for n in names}


def test_nerfstudio_export_is_byte_identical(tmp_path):
    d = marked_dataset(tmp_path / "d")
    t = marked_dataset(tmp_path / "t", shard_format="tar")
    assert sorted(os.listdir(t / "shards")) == ["shard_000000.tar", "shard_000000.tar.json", "shard_000001.tar",
                                                "shard_000001.tar.json"]
    export_nerfstudio(d, tmp_path / "nd", val_views=0)
    export_nerfstudio(t, tmp_path / "nt", val_views=0)
    a, b = _files(tmp_path / "nd"), _files(tmp_path / "nt")
    assert sorted(a) == sorted(b) and len(a) > 10
    for name in a:
        assert a[name] == b[name], name


def test_report_summary_is_the_same(tmp_path):
    from synth.report.collect import collect

    d, _ = model_dataset(tmp_path / "d", identities=2)
    t, _ = model_dataset(tmp_path / "t", identities=2, shard_format="tar")
    a, b = collect(d).summary(), collect(t).summary()
    assert a["progress"]["frames_committed"] == 12
    assert a.pop("dataset") == str(d) and b.pop("dataset") == str(t)
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def test_usd_export_of_a_tar_shard(tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd

    from synth.export.usd import export_usd
    from synth.model.format import read_model
    from tests.support.export_oracles import check_stage

    t, model = model_dataset(tmp_path / "t", identities=1, expressions=2, views=3, shard_format="tar")
    out = tmp_path / "scene.usdc"
    summary = export_usd(t, out, model=model)
    assert summary["shard"] == "shard_000000" and summary["frames"] == 6
    frames = {r.key: r.meta() for r in list_frames(t)}
    assert check_stage(Usd.Stage.Open(str(out)), frames, read_model(model)) < 0.5e-2
