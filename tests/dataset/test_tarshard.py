"""Tar shards (dataset.shard_format = "tar"): commit, determinism, reader, WebDataset, preview,
resume after kill -9, and the formats' equivalence: the same frames committed as a directory
and as a tar give the same files, the same decoded frames and the same previews."""

from __future__ import annotations

import io
import json
import os
import tarfile
from pathlib import Path

import numpy as np
import pytest

from synth.dataset.layout import frame_key, shard_name
from synth.dataset.preview import contact_sheet, overview_sheet
from synth.dataset.reader import decode_sample, iter_frames, list_frames
from synth.dataset.shards import load_dataset, open_dataset
from synth.dataset.tarshard import tar_manifest_path, tar_path
from synth.dataset.validate import validate_dataset
from synth.errors import SynthError
from synth.io import sha256_bytes, sha256_file
from tests.dataset.test_shards import _kill_at, _sync_points, logged, run_child
from tests.support import fake_frames as ff

pytest.importorskip("OpenEXR")

HASH = "f" * 64
PLAN = ff.plan(n_shards=2, n_expr=2, n_views=3)


def make(root: Path, fmt: str | None, plan=PLAN, reverse: bool = False) -> Path:
    """Commit ``plan`` with fake frames; ``reverse`` writes each shard's frames in reverse order."""
    ds = open_dataset(root, HASH, plan, shard_format=fmt)
    for sid in ds.pending_shards():
        with ds.staging(sid) as st:
            for key in (reversed(st.expected_keys) if reverse else st.expected_keys):
                st.write_frame(key, *ff.pixels(key), ff.frame_json(key))
            st.commit(manifest_extra={"seeds": {"run": 0}})
    return root


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    base = tmp_path_factory.mktemp("tarshard")
    return make(base / "dir", None), make(base / "tar", "tar")


def frames_equal(a, b) -> None:
    assert (a.key, a.shard) == (b.key, b.shard)
    assert a.meta == b.meta
    for name in ("rgba", "depth", "normals", "segmentation"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape
        np.testing.assert_array_equal(x, y)


# -- commit: layout, manifest, headers --------------------------------------------------------


def test_commit_layout_and_manifest(pair):
    droot, troot = pair
    names = sorted(os.listdir(troot / "shards"))
    assert names == ["shard_000000.tar", "shard_000000.tar.json", "shard_000001.tar", "shard_000001.tar.json"]
    assert os.listdir(troot / ".staging") == [] or all(n.endswith(".lease") for n in os.listdir(troot / ".staging"))
    assert load_dataset(troot).shard_format == "tar" and load_dataset(droot).shard_format == "dir"
    for sid in PLAN:
        tp, mp = tar_path(troot, sid), tar_manifest_path(troot, sid)
        m = json.loads(mp.read_bytes())
        dm = json.loads((droot / "shards" / sid / "manifest.json").read_bytes())
        assert m["container"] == {"format": "tar", "file": tp.name, "sha256": sha256_file(tp), "bytes": tp.stat().st_size}
        assert m["frames"] == dm["frames"] == sorted(PLAN[sid])
        # the manifest's sha256 and sizes are the directory form's, and the stdlib's tar reader agrees
        with tarfile.open(tp) as tf:
            members = tf.getmembers()
            assert [t.name for t in members] == sorted(dm["files"])
            for t in members:
                data = tf.extractfile(t).read()
                assert data == (droot / "shards" / sid / t.name).read_bytes()
                ent = m["files"][t.name]
                assert (ent["sha256"], ent["bytes"]) == (dm["files"][t.name]["sha256"], dm["files"][t.name]["bytes"])
                assert ent["offset"] == t.offset_data
                assert t.isreg() and (t.mtime, t.uid, t.gid, t.uname, t.gname, t.mode) == (0, 0, 0, "", "", 0o444)
        assert oct(tp.stat().st_mode & 0o777) == oct(0o444) and oct(mp.stat().st_mode & 0o777) == oct(0o444)
    idx = json.loads((troot / "index.json").read_bytes())
    assert sorted(idx["shards"]) == sorted(PLAN) and idx["num_frames"] == 12
    assert idx["shards"]["shard_000000"]["manifest_sha256"] == sha256_bytes(
        tar_manifest_path(troot, "shard_000000").read_bytes())
    rep = validate_dataset(troot)
    assert rep.ok and rep.frames_checked == 12 and rep.warnings == [], [d.line() for d in rep.defects + rep.warnings]


def test_same_frames_give_the_same_tar_bytes(tmp_path, pair):
    _, troot = pair
    again = make(tmp_path / "again", "tar", reverse=True)  # other write order, other mtimes, other time
    for sid in PLAN:
        assert tar_path(again, sid).read_bytes() == tar_path(troot, sid).read_bytes()


def test_resume_treats_committed_tars_as_complete_and_format_is_fixed(tmp_path, pair):
    _, troot = pair
    ds = open_dataset(troot, HASH, PLAN)  # the recorded format
    assert ds.pending_shards() == [] and ds.committed_shards() == set(PLAN)
    assert ds.summary()["frames_committed"] == 12
    assert ds.try_staging("shard_000000") is None  # committed: not staged again
    with pytest.raises(SynthError, match="stores shards as 'tar', not 'dir'"):
        open_dataset(troot, HASH, PLAN, shard_format="dir")
    with pytest.raises(SynthError, match="unknown shard format"):
        open_dataset(tmp_path / "x", HASH, PLAN, shard_format="zip")
    assert not (tmp_path / "x").exists()


def test_orphan_tar_of_a_killed_commit_is_not_committed_and_is_replaced(tmp_path):
    plan = ff.plan(1, 1, 2)
    root = tmp_path / "d"
    ds = open_dataset(root, HASH, plan, shard_format="tar")
    sid = next(iter(plan))
    with ds.staging(sid) as st:
        for key in st.expected_keys:
            st.write_frame(key, *ff.pixels(key), ff.frame_json(key))
    # what a kill between the tar's rename and the manifest's leaves: a tar without manifest,
    # plus a temp file of an earlier attempt
    tar_path(root, sid).write_bytes(b"half a tar")
    (root / "shards" / f".{sid}.tar.123.abcd.tmp").write_bytes(b"junk")
    assert ds.pending_shards() == [sid]
    rep = validate_dataset(root, partial=True)
    assert rep.ok and {w.kind for w in rep.warnings} == {"missing-shard", "staging"}
    assert any("has no manifest" in w.message for w in rep.warnings)
    with ds.staging(sid) as st:
        assert st.frames_done() == set(plan[sid])
        st.commit()
    assert sorted(os.listdir(root / "shards")) == [f"{sid}.tar", f"{sid}.tar.json"]
    assert validate_dataset(root).ok


def test_a_shard_in_both_forms_is_a_defect(tmp_path):
    plan = ff.plan(1, 1, 1)
    droot, troot = make(tmp_path / "d", None, plan), make(tmp_path / "t", "tar", plan)
    sid = next(iter(plan))
    os.rename(tar_path(troot, sid), tar_path(droot, sid))
    os.rename(tar_manifest_path(troot, sid), tar_manifest_path(droot, sid))
    rep = validate_dataset(droot)
    assert any(d.kind == "unexpected-shard" and "committed twice" in d.message for d in rep.defects)


# -- the reader ----------------------------------------------------------------------------------


def test_reader_gives_the_same_frames_from_both_forms(pair):
    droot, troot = pair
    want = list(iter_frames(droot))
    assert len(want) == 12
    got = list(iter_frames(troot))
    for a, b in zip(want, got, strict=True):
        frames_equal(a, b)
    # random access by the manifest's offsets
    refs = list_frames(troot, shards=["shard_000001"])
    assert [r.key for r in refs] == sorted(PLAN["shard_000001"])
    frames_equal(refs[2].read(validate=True), want[6 + 2])
    assert refs[2].meta() == want[8].meta and str(refs[2].json_path).endswith("shard_000001.tar/" + refs[2].key + ".json")
    # a tar file by path (its name gives the shard) and as a raw stream (no shard)
    for a, b in zip(want[:6], iter_frames(tar_path(troot, "shard_000000")), strict=True):
        frames_equal(a, b)
    with open(tar_path(troot, "shard_000001"), "rb") as f:
        streamed = list(iter_frames(io.BufferedReader(f)))
    assert [x.shard for x in streamed] == [None] * 6
    np.testing.assert_array_equal(streamed[0].rgba, want[6].rgba)


def test_stdlib_tar_unpacks_to_the_directory_shard(tmp_path, pair):
    droot, troot = pair
    out = tmp_path / "x"
    with tarfile.open(tar_path(troot, "shard_000000")) as tf:
        tf.extractall(out, filter="data")
    d = droot / "shards" / "shard_000000"
    assert sorted(os.listdir(out)) == sorted(n for n in os.listdir(d) if n != "manifest.json")
    for n in os.listdir(out):
        assert (out / n).read_bytes() == (d / n).read_bytes()


def test_webdataset_streams_a_tar_dataset(pair):
    wds = pytest.importorskip("webdataset")
    droot, troot = pair
    urls = [str(tar_path(troot, s)) for s in sorted(PLAN)]
    samples = wds.WebDataset(urls, shardshuffle=False, empty_check=False).map(decode_sample)
    got = list(samples)
    want = list(iter_frames(droot))
    assert len(got) == len(want) == 12
    for a, b in zip(want, got, strict=True):
        frames_equal(a, b)
    # also as raw sample dicts through iter_frames
    raw = list(wds.WebDataset(urls[:1], shardshuffle=False, empty_check=False))
    assert raw[0]["__key__"] == frame_key(0, 0, 0) and {"exr", "json"} <= set(raw[0])
    frames_equal(next(iter_frames(raw)), want[0])


def test_decode_sample_refuses_decoded_or_partial_samples():
    with pytest.raises(SynthError, match="lacks 'json' or 'exr' bytes"):
        decode_sample({"__key__": "id000000_ex00_v00", "json": {"frame_id": "x"}, "exr": b"x"})
    with pytest.raises(SynthError, match="lacks 'json' or 'exr' bytes"):
        decode_sample({"__key__": "id000000_ex00_v00", "json": b"{}"})


# -- preview, report-style readers ---------------------------------------------------------------


def test_preview_is_the_same_for_both_forms(tmp_path, pair):
    from PIL import Image

    droot, troot = pair
    a = contact_sheet(droot, "shard_000001", tmp_path / "a.png")
    b = contact_sheet(troot, "shard_000001", tmp_path / "b.png")
    np.testing.assert_array_equal(np.asarray(Image.open(a)), np.asarray(Image.open(b)))
    c = overview_sheet(droot, tmp_path / "c.png", views=2)
    d = overview_sheet(troot, tmp_path / "d.png", views=2)
    np.testing.assert_array_equal(np.asarray(Image.open(c)), np.asarray(Image.open(d)))


def test_preview_of_an_unreadable_tar_member_is_a_red_tile(tmp_path):
    from PIL import Image

    plan = ff.plan(1, 1, 1)
    root = make(tmp_path / "t", "tar", plan)
    sid = next(iter(plan))
    tp = tar_path(root, sid)
    os.chmod(tp, 0o644)
    with open(tp, "r+b") as f:  # zero the first EXR's bytes (its header)
        f.seek(json.loads(tar_manifest_path(root, sid).read_bytes())["files"][f"{frame_key(0, 0, 0)}.exr"]["offset"])
        f.write(bytes(64))
    png = np.asarray(Image.open(contact_sheet(root, sid, tmp_path / "p.png", tile=16)))
    assert ((png[..., 0] == 160) & (png[..., 1] == 0)).sum() >= 16 * 16


# -- resume after kill -9 ------------------------------------------------------------------------


def test_kill9_at_the_tar_commit_steps(tmp_path):
    plan = ff.plan(1, 1, 2)
    points = _sync_points(tmp_path, plan, "tar")
    first = next(i for i, c in enumerate(points, 1) if c.startswith("replace .shard_000000.json."))
    # the dataset's creation, the first frame, then every sync point of the commit: before and
    # after its commit record (signed, not committed), before and after placing the tar (an
    # orphan tar), before and after its manifest (the commit point; after it the staging
    # directory is still there), the index update
    want = [i for i, c in enumerate(points, 1) if c.startswith(("replace .dataset.json", "replace .id000000_ex00_v00."))]
    want += list(range(first, len(points) + 1))
    assert any(points[i - 1].startswith("replace .shard_000000.tar.") for i in want), points
    assert any(points[i - 1].startswith("replace .shard_000000.tar.json.") for i in want), points
    _kill_at(tmp_path, want, plan, "tar")


def test_concurrent_tar_workers(tmp_path):
    plan = {shard_name(i): [frame_key(i, 0, 0)] for i in range(6)}
    root = tmp_path / "ds"
    open_dataset(root, HASH, plan, shard_format="tar")
    procs = [run_child(root, plan, tmp_path / f"log{j}", sleep=0.01, wait=False, fmt="tar") for j in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
    total = sum((logged(tmp_path / f"log{j}") for j in range(2)), start=logged(tmp_path / "none"))
    assert sorted(total) == sorted(k for ks in plan.values() for k in ks) and max(total.values()) == 1
    rep = validate_dataset(root)
    assert rep.ok and rep.frames_checked == 6
