"""``synth validate`` against a careless or hostile dataset: symbolic links, devices, FIFOs and
stray entries are reported and never followed or opened; every read is bounded; the commit
records that signed each manifest at commit cannot be bypassed (docs/reliability.md)."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from tests.support import datasets
from tests.support import fake_frames as ff
from synth.dataset.index import read_index, repair_index
from synth.dataset.shards import open_dataset
from synth.dataset.validate import validate_dataset

pytest.importorskip("OpenEXR")
HASH = "b" * 64
S0, S1 = "shard_000000", "shard_000001"


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("hostile") / "ds"
    ff.render_dataset(open_dataset(root, HASH, ff.plan(2, 1, 2)))
    return root


@pytest.fixture
def ds(clean, tmp_path) -> Path:
    return datasets.writable_copy(clean, tmp_path / "ds")


found = datasets.defects_found


def frame(root: Path, ext: str, shard: str = S0) -> Path:
    return datasets.first_frame(root, shard)[1].with_suffix(ext)


def test_clean(ds):
    rep = validate_dataset(ds)
    assert rep.ok and rep.digest == read_index(ds)["digest"]


@pytest.mark.parametrize("ext", [".exr", ".json"])
def test_a_frame_replaced_by_a_link_to_an_identical_copy_is_refused(ds, tmp_path, ext):
    p = frame(ds, ext)
    copy = tmp_path / f"outside{ext}"
    shutil.copyfile(p, copy)
    p.unlink()
    p.symlink_to(copy)
    assert found(ds) == {(S0, p.stem, "not-a-file")}


def test_links_to_devices_and_fifos_are_never_opened(ds):
    p = frame(ds, ".json")
    p.unlink()
    p.symlink_to("/dev/zero")
    q = frame(ds, ".exr", S1)
    q.unlink()
    os.mkfifo(q)  # opening it for reading would block forever
    for quick in (True, False):
        assert found(ds, quick=quick) == {(S0, p.stem, "not-a-file"), (S1, q.stem, "not-a-file")}


def test_stray_entries_under_shards_are_reported_and_not_opened(ds, tmp_path):
    base = ds / "shards"
    (base / "notes.txt").write_text("x")
    shutil.make_archive(str(base / "evil"), "tar", root_dir=tmp_path, base_dir=".")
    (base / "link").symlink_to("/etc")
    os.mkfifo(base / "fifo")
    (base / "not a shard").mkdir()
    got = found(ds)
    assert {(s, k, kind) for s, k, kind in got if kind == "unexpected-entry"} == {(None, None, "unexpected-entry")}
    lines = [d.message for d in validate_dataset(ds).defects]
    for name in ("'notes.txt' is a regular file", "'evil.tar' is a regular file", "'link' is a symbolic link",
                 "'fifo' is a device, FIFO or socket"):
        assert any(name in x for x in lines), lines
    assert ("not a shard", None, "unexpected-shard") in got


def test_a_shard_directory_that_is_a_link_is_not_followed(ds, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    shutil.move(ds / "shards" / S1, elsewhere)
    (ds / "shards" / S1).symlink_to(elsewhere)
    got = found(ds)
    assert (None, None, "unexpected-entry") in got and (S1, None, "missing-shard") in got


def test_manifest_that_is_a_link_or_huge_or_nested(ds, tmp_path):
    m0 = ds / "shards" / S0 / "manifest.json"
    copy = tmp_path / "m.json"
    shutil.copyfile(m0, copy)
    m0.unlink()
    m0.symlink_to(copy)
    m1 = ds / "shards" / S1 / "manifest.json"
    os.chmod(m1, 0o644)
    m1.write_text(datasets_deep())
    rep = validate_dataset(ds)
    msgs = {d.shard: d.message for d in rep.defects if d.kind == "manifest"}
    assert "symbolic link" in msgs[S0] and "nested" in msgs[S1]


def datasets_deep() -> str:
    return "[" * 10_000 + "]" * 10_000


def test_nested_frame_json_is_a_defect_not_a_crash(ds):
    sd, js = datasets.first_frame(ds)
    js.write_text(datasets_deep())
    datasets.reseal(sd, js.name)
    repair_index(ds, HASH)
    rep = validate_dataset(ds)
    assert [(d.kind, "nested" in d.message) for d in rep.defects] == [("json", True)]


def test_reads_are_bounded_by_the_manifest(ds):
    """A file that grew past its declared size fails on size and is not read as JSON or EXR."""
    p = frame(ds, ".json")
    with open(p, "a") as f:
        f.write(" " * 100)
    assert found(ds) == {(S0, p.stem, "checksum")}


def test_staging_and_index_links(ds, tmp_path):
    shutil.move(ds / ".staging", tmp_path / "st")
    (ds / ".staging").symlink_to(tmp_path / "st")
    idx = ds / "index.json"
    shutil.move(idx, tmp_path / "index.json")
    idx.symlink_to(tmp_path / "index.json")
    rep = validate_dataset(ds)
    assert any(d.kind == "unexpected-entry" and ".staging is a symbolic link" in d.message for d in rep.defects)
    assert any(d.kind == "index" and "damaged" in d.message for d in rep.defects)


def test_the_index_is_never_re_signed(ds):
    """Tamper with a frame and its manifest; reopening the dataset for writing (what every
    render does) keeps the old signature, so the change stays visible."""
    js = datasets.tamper_frame(ds)
    before = (ds / "index.json").read_bytes()
    open_dataset(ds, HASH, ff.plan(2, 1, 2))
    assert (ds / "index.json").read_bytes() == before
    assert found(ds) == {(S0, None, "manifest")}
    _, changes = repair_index(ds, HASH)
    assert [(c["shard"], c["change"]) for c in changes] == [(S0, "changed")]
    assert validate_dataset(ds).ok and js.exists()


def test_digest_covers_every_manifest(ds):
    """An index entry edited by hand: its digest no longer matches, and the commit record,
    not the edited entry, is what the manifest is checked against."""
    idx = json.loads((ds / "index.json").read_text())
    idx["shards"][S1]["manifest_sha256"] = "0" * 64
    (ds / "index.json").write_text(json.dumps(idx))
    rep = validate_dataset(ds)
    assert [d.message for d in rep.defects] == ["index.json's digest does not match its entries (edited?)"]
    assert [(w.shard, w.kind) for w in rep.warnings] == [(S1, "index")]


def test_a_lost_index_is_rebuilt_from_the_commit_records_not_the_manifests(ds):
    datasets.tamper_frame(ds)
    (ds / "index.json").unlink()
    assert found(ds) == {(None, None, "index"), (S0, None, "manifest")}  # index-less: fails
    open_dataset(ds, HASH, ff.plan(2, 1, 2))  # what a resuming render does
    assert found(ds) == {(S0, None, "manifest")}  # the tampered manifest is still caught


def test_commit_records_are_checked(ds):
    (ds / ".commits" / "shard_000001.json").write_text("{}")
    (ds / ".commits" / "stray").write_text("x")
    msgs = [d.message for d in validate_dataset(ds).defects]
    assert "'stray' is not a commit record" in " ".join(msgs) and any("not a commit record of this plan" in m
                                                                      for m in msgs)


def test_a_lost_index_update_costs_nothing(ds):
    """Two commits whose read-modify-writes of index.json raced (flock not honoured across
    hosts): the later write lost the other shard's entry. The shard stays committed (its
    commit record signs it), validate only warns, and the next open puts the entry back."""
    from synth.dataset.index import new_index
    from synth.dataset.shards import load_dataset

    full = json.loads((ds / "index.json").read_text())
    (ds / "index.json").write_text(json.dumps(new_index(HASH, {S0: full["shards"][S0]})))
    assert load_dataset(ds).committed_shards() == {S0, S1}
    rep = validate_dataset(ds)
    assert rep.ok and [(w.shard, w.kind) for w in rep.warnings] == [(S1, "index")]
    open_dataset(ds, HASH, ff.plan(2, 1, 2))
    assert json.loads((ds / "index.json").read_text()) == full
