"""``synth validate``: a clean dataset passes; each kind of defect is reported with exit code 1."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.support import fake_frames as ff
from synth.cli.main import main
from synth.dataset.index import repair_index
from synth.dataset.exr import read_frame_exr
from synth.dataset.shards import open_dataset
from synth.dataset.validate import validate_dataset

OpenEXR = pytest.importorskip("OpenEXR")
HASH = "a" * 64
S0 = "shard_000000"
KEY = "id000000_ex01_v01"


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("clean") / "ds"
    ds = open_dataset(root, HASH, ff.plan(2, 2, 2))
    ff.render_dataset(ds)
    return root


@pytest.fixture
def ds(clean, tmp_path) -> Path:
    """A writable copy of the clean dataset."""
    root = tmp_path / "ds"
    shutil.copytree(clean, root)
    for p in root.rglob("*"):
        os.chmod(p, 0o755 if p.is_dir() else 0o644)
    return root


def reseal(root: Path, shard: str = S0) -> None:
    """Recompute a shard's manifest checksums and the index, isolating a pixel/JSON defect."""
    sd = root / "shards" / shard
    m = json.loads((sd / "manifest.json").read_text())
    for name in m["files"]:
        if (sd / name).exists():
            data = (sd / name).read_bytes()
            m["files"][name] = {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}
    (sd / "manifest.json").write_text(json.dumps(m))
    repair_index(root, HASH)


def write_raw_exr(path: Path, rgba, depth, normals, seg) -> None:
    """Write a frame EXR without synth's checks (to plant NaNs and bad IDs)."""
    ch = {c: np.ascontiguousarray(rgba[..., i].astype(np.float16)) for i, c in enumerate("RGBA")}
    ch["depth.Z"] = depth.astype(np.float32)
    for i, c in enumerate("XYZ"):
        ch[f"normal.{c}"] = np.ascontiguousarray(normals[..., i].astype(np.float16))
    ch["segmentation.id"] = seg.astype(np.uint32)
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, ch).write(str(path))


def run(root, *args, capsys=None):
    rc = main(["validate", str(root), *args])
    out = capsys.readouterr() if capsys else None
    return rc, out


def kinds(root, **kw) -> set[tuple[str | None, str | None, str]]:
    rep = validate_dataset(root, **kw)
    return {(d.shard, d.key, d.kind) for d in rep.defects}


def test_clean_dataset_passes(clean, capsys):
    rc, out = run(clean, capsys=capsys)
    assert rc == 0, out.out + out.err
    assert "2/2 shards, 8/8 frames checked" in out.out and "OK" in out.out
    rc, out = run(clean, "--json", "--quick", "-j", "2", capsys=capsys)
    rep = json.loads(out.out)
    assert rc == 0 and rep["ok"] and rep["frames_checked"] == 8 and rep["hashed"] is False


def test_flipped_byte_in_exr(ds, capsys):
    p = ds / "shards" / S0 / f"{KEY}.exr"
    data = bytearray(p.read_bytes())
    data[len(data) - 40] ^= 0x01
    p.write_bytes(bytes(data))
    rc, out = run(ds, capsys=capsys)
    assert rc == 1
    assert f"{S0}/{KEY}: checksum: {KEY}.exr sha256 differs" in out.out
    assert "1 defect(s) found" in out.err or "defect(s) found" in out.err


def test_missing_frame(ds, capsys):
    for ext in ("exr", "json"):
        (ds / "shards" / S0 / f"{KEY}.{ext}").unlink()
    assert kinds(ds) == {(S0, KEY, "missing-file")}
    rc, out = run(ds, capsys=capsys)
    assert rc == 1 and f"{S0}/{KEY}: missing-file: {KEY}.exr is listed but missing" in out.out


def test_frame_missing_from_manifest_is_reported(ds):
    sd = ds / "shards" / S0
    m = json.loads((sd / "manifest.json").read_text())
    m["frames"].remove(KEY)
    for ext in ("exr", "json"):
        del m["files"][f"{KEY}.{ext}"]
        (sd / f"{KEY}.{ext}").unlink()
    (sd / "manifest.json").write_text(json.dumps(m))
    repair_index(ds, HASH)
    assert kinds(ds) == {(S0, KEY, "missing-frame")}


def test_nan_pixel(ds):
    p = ds / "shards" / S0 / f"{KEY}.exr"
    px = read_frame_exr(p)
    rgba = px["rgba"].astype(np.float32)
    rgba[3, 4, 1] = np.nan
    write_raw_exr(p, rgba, px["depth"], px["normals"], px["segmentation"])
    reseal(ds)
    rep = validate_dataset(ds)
    assert [(d.kind, d.message) for d in rep.defects] == [("pixels", "RGBA has 1 NaN and 0 Inf value(s)")]


def test_inf_depth_under_alpha(ds):
    p = ds / "shards" / S0 / f"{KEY}.exr"
    px = read_frame_exr(p)
    depth = px["depth"].copy()
    depth[8, 8] = np.inf  # the centre of the fake head: alpha > 0
    write_raw_exr(p, px["rgba"], depth, px["normals"], px["segmentation"])
    reseal(ds)
    msgs = [d.message for d in validate_dataset(ds).defects]
    assert msgs == ["depth has 0 NaN and 1 Inf value(s), 1 where alpha > 0"]


def test_unknown_segmentation_id(ds):
    p = ds / "shards" / S0 / f"{KEY}.exr"
    px = read_frame_exr(p)
    seg = px["segmentation"].copy()
    seg[0, 0] = 99
    write_raw_exr(p, px["rgba"], px["depth"], px["normals"], seg)
    reseal(ds)
    rep = validate_dataset(ds)
    assert len(rep.defects) == 1 and "unknown class ID(s) [99]" in rep.defects[0].message


def test_missing_layer(ds):
    p = ds / "shards" / S0 / f"{KEY}.exr"
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {c: np.zeros((16, 16), np.float16) for c in "RGBA"}).write(str(p))
    reseal(ds)
    rep = validate_dataset(ds)
    assert [(d.key, d.kind) for d in rep.defects] == [(KEY, "exr")]
    assert "lacks channel(s) depth.Z" in rep.defects[0].message


@pytest.mark.parametrize("damage", ["unparseable", "schema", "nan"])
def test_bad_json(ds, capsys, damage):
    p = ds / "shards" / S0 / f"{KEY}.json"
    fj = json.loads(p.read_text())
    if damage == "unparseable":
        p.write_text(p.read_text()[:-20])
    elif damage == "schema":
        fj["landmarks_visible"] = fj["landmarks_visible"][:67]
        p.write_text(json.dumps(fj))
    else:
        p.write_text(p.read_text().replace('"radius_m": 1.0', '"radius_m": NaN'))
    reseal(ds)
    assert kinds(ds) == {(S0, KEY, "json")}
    rc, out = run(ds, capsys=capsys)
    assert rc == 1 and f"{S0}/{KEY}: json:" in out.out


def test_inconsistent_camera_json(ds):
    p = ds / "shards" / S0 / f"{KEY}.json"
    fj = json.loads(p.read_text())
    fj["camera"]["K"][0][2] += 1.0  # landmarks_2d no longer match K
    p.write_text(json.dumps(fj))
    reseal(ds)
    rep = validate_dataset(ds)
    assert len(rep.defects) == 1 and "landmarks_2d" in rep.defects[0].message


def test_extra_file_unplanned_shard_and_manifestless_dir(ds):
    (ds / "shards" / S0 / "notes.txt").write_text("x")
    (ds / "shards" / "shard_000099").mkdir()
    assert kinds(ds) == {(S0, "notes", "extra-file"), ("shard_000099", None, "unexpected-shard"),
                         ("shard_000099", None, "manifest")}


def test_modified_manifest_is_caught_by_the_index(ds):
    sd = ds / "shards" / S0
    m = json.loads((sd / "manifest.json").read_text())
    m["seeds"] = {"run": 42}
    (sd / "manifest.json").write_text(json.dumps(m, indent=1))
    assert kinds(ds) == {(S0, None, "manifest")}


def test_missing_shard_partial_and_staging_warnings(ds, capsys):
    shutil.rmtree(ds / "shards" / "shard_000001")
    repair_index(ds, HASH)
    (ds / ".staging" / "shard_000001").mkdir()
    (ds / ".staging" / "shard_000001" / "id000001_ex00_v00.json").write_text("{}")
    assert kinds(ds) == {("shard_000001", None, "missing-shard")}
    rc, out = run(ds, "--partial", capsys=capsys)
    assert rc == 0
    assert "warning shard_000001: missing-shard" in out.out and "warning shard_000001: staging" in out.out


def test_quick_skips_hashing_but_checks_sizes(ds):
    p = ds / "shards" / S0 / f"{KEY}.json"
    p.write_text(p.read_text() + " ")  # size changes, still valid JSON
    assert kinds(ds, quick=True) == {(S0, KEY, "checksum")}


def test_jobs_give_the_same_report(ds):
    (ds / "shards" / S0 / f"{KEY}.exr").unlink()
    assert validate_dataset(ds, jobs=2).defects == validate_dataset(ds).defects


def test_usage_errors_exit_2(tmp_path, capsys):
    rc, out = run(tmp_path / "nope", capsys=capsys)
    assert rc == 2 and "dataset directory not found" in out.err and out.err.count("\n") == 1
    rc, out = run(tmp_path, capsys=capsys)
    assert rc == 2 and "no dataset.json" in out.err
