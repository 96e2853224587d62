"""Tar shards under the reliability rules (docs/reliability.md): a tar shard is signed at
commit like a directory shard (its ``<id>.tar.json``, which holds the tar's sha256), so a
tampered tar cannot be laundered by a rerun or a lost index; only ``--repair-index`` signs it
again; a tar shard copied in by hand is not adopted; links, FIFOs and stray files among the
tar shards are reported and never opened; reads stay bounded."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from synth.dataset.index import read_index, repair_index
from synth.dataset.shards import load_dataset, open_dataset
from synth.dataset.tarshard import tar_manifest_path, tar_path
from synth.dataset.validate import validate_dataset
from synth.errors import SynthError
from tests.support import datasets
from tests.support import fake_frames as ff

pytest.importorskip("OpenEXR")

HASH = "c" * 64
PLAN = ff.plan(2, 1, 2)
S0, S1 = "shard_000000", "shard_000001"
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("tarint") / "ds"
    ff.render_dataset(open_dataset(root, HASH, PLAN, shard_format="tar"))
    return root


@pytest.fixture
def ds(clean, tmp_path) -> Path:
    return datasets.writable_copy(clean, tmp_path / "ds")


found = datasets.defects_found


def tamper_tar(root: Path, shard: str = S0) -> str:
    """Change one byte of the first frame JSON inside the tar (same size, so the offsets hold)
    and reseal the manifest (member and container sha256), as a tamperer who wants the
    per-file checks to pass would. Returns the changed member's name."""
    tp, mp = tar_path(root, shard), tar_manifest_path(root, shard)
    m = json.loads(mp.read_bytes())
    name = sorted(n for n in m["files"] if n.endswith(".json"))[0]
    ent = m["files"][name]
    data = bytearray(tp.read_bytes())
    member = bytes(data[ent["offset"]:ent["offset"] + ent["bytes"]])
    assert b'"seed": ' in member or b'"seed":' in member
    at = ent["offset"] + member.index(b'"seed"') + len(b'"seed"')
    while not chr(data[at]).isdigit():
        at += 1
    data[at] = ord("1") if data[at] != ord("1") else ord("2")
    tp.write_bytes(bytes(data))
    new = bytes(data[ent["offset"]:ent["offset"] + ent["bytes"]])
    ent["sha256"] = hashlib.sha256(new).hexdigest()
    m["container"].update(sha256=hashlib.sha256(bytes(data)).hexdigest(), bytes=len(data))
    mp.write_text(json.dumps(m, indent=1))
    return name


def test_clean_tar_dataset_is_signed(ds):
    rep = validate_dataset(ds)
    assert rep.ok and rep.warnings == [] and rep.digest == read_index(ds)["digest"]
    records = sorted(os.listdir(ds / ".commits"))
    assert records == [f"{S0}.json", f"{S1}.json"]
    rec = json.loads((ds / ".commits" / records[0]).read_bytes())
    assert rec["entry"]["manifest_sha256"] == hashlib.sha256(tar_manifest_path(ds, S0).read_bytes()).hexdigest()


def test_tar_laundering_sequence(ds):
    """Tamper (tar and manifest agree with each other), reopen as a rerun does, lose the index,
    lose every signature: the change stays visible until the explicit repair signs it."""
    tamper_tar(ds)
    assert validate_dataset(ds, quick=False).defects and found(ds) == {(S0, None, "manifest")}
    msg = [d.message for d in validate_dataset(ds).defects][0]
    assert msg.startswith(f"{S0}.tar.json changed after commit")

    before = (ds / "index.json").read_bytes()
    assert open_dataset(ds, HASH, PLAN).pending_shards() == []  # a rerun: nothing to do, nothing re-signed
    assert (ds / "index.json").read_bytes() == before and found(ds) == {(S0, None, "manifest")}

    (ds / "index.json").unlink()  # rebuilt from the commit records, not from the manifests
    assert found(ds) == {(None, None, "index"), (S0, None, "manifest")}
    open_dataset(ds, HASH, PLAN)
    assert found(ds) == {(S0, None, "manifest")}

    shutil.rmtree(ds / ".commits")
    (ds / "index.json").unlink()
    with pytest.raises(SynthError, match=f"shards/{S0}.tar.json has no commit record") as e:
        open_dataset(ds, HASH, PLAN).pending_shards()
    assert "--repair-index" in e.value.fix

    idx, changes = repair_index(ds, HASH)  # the one way to sign the tar shards as they are
    assert sorted((c["shard"], c["change"]) for c in changes if c["shard"]) == [(S0, "added"), (S1, "added")]
    assert sorted(idx["shards"]) == [S0, S1] and sorted(os.listdir(ds / ".commits")) == [f"{S0}.json", f"{S1}.json"]
    assert validate_dataset(ds).ok


def test_repair_reports_a_changed_tar_manifest(ds):
    old = read_index(ds)
    tamper_tar(ds, S1)
    idx, changes = repair_index(ds, HASH)
    assert [(c["shard"], c["change"]) for c in changes] == [(S1, "changed")]
    assert changes[0]["old"] == old["shards"][S1]["manifest_sha256"] != changes[0]["new"]
    assert idx["digest"] != old["digest"] and validate_dataset(ds).ok
    assert repair_index(ds, HASH)[1] == []  # nothing left to sign


def test_a_tar_shard_copied_in_by_hand_is_not_adopted(tmp_path, clean):
    root = tmp_path / "part"
    ff.render_dataset(open_dataset(root, HASH, PLAN, shard_format="tar"), shards=[S0])
    for p in (tar_path(clean, S1), tar_manifest_path(clean, S1)):
        shutil.copyfile(p, root / "shards" / p.name)
    with pytest.raises(SynthError, match=f"shards/{S1}.tar.json has no commit record"):
        load_dataset(root).committed_shards()
    rep = validate_dataset(root)
    assert [(d.shard, d.kind) for d in rep.defects] == [(S1, "index")] and "no commit record" in rep.defects[0].message


def test_links_fifos_and_strays_among_tar_shards_are_never_opened(ds, tmp_path):
    base = ds / "shards"
    copy = tmp_path / "m.json"
    shutil.copyfile(tar_manifest_path(ds, S0), copy)  # S0's manifest: a link to an identical copy
    tar_manifest_path(ds, S0).unlink()
    tar_manifest_path(ds, S0).symlink_to(copy)
    tar_path(ds, S1).unlink()  # S1's tar: a FIFO (opening it for reading would block)
    os.mkfifo(tar_path(ds, S1))
    (base / "notes.txt").write_text("x")
    (base / "extra.tar").write_bytes(b"not a shard of this plan")
    (base / f"{S1}.tar.json.bak").write_bytes(tar_manifest_path(ds, S1).read_bytes())
    (base / f".{S1}.tar.1.ab.tmp").write_bytes(b"leftover")  # a killed commit's temporary tar
    rep = validate_dataset(ds)
    lines = [d.line() for d in rep.defects]
    for what in (f"'{S0}.tar.json' is a symbolic link", "'notes.txt' is a regular file",
                 "'extra.tar' is a regular file", f"'{S1}.tar.json.bak' is a regular file"):
        assert any(what in x and ": unexpected-entry: " in x for x in lines), (what, lines)
    assert any(x.startswith(f"{S1}: tar: {S1}.tar is a device, FIFO or socket") for x in lines), lines
    assert (S0, None, "missing-shard") in found(ds)
    assert [w.message for w in rep.warnings] == [f"leftover temporary file shards/.{S1}.tar.1.ab.tmp (safe to delete)"]
    with pytest.raises(SynthError, match=f"shards/{S0}.tar.json is a symbolic link, not a regular file"):
        load_dataset(ds).committed_shards()
    assert validate_dataset(ds, quick=True).defects  # also without hashing: nothing blocks on the FIFO


def test_an_orphan_tar_of_a_planned_shard_is_a_warning_not_a_defect(ds):
    """A kill between the commit record and the manifest leaves a signed but uncommitted shard
    (the record, an orphan tar): pending, never adopted, replaced by the next commit."""
    tar_manifest_path(ds, S1).unlink()
    (ds / "index.json").unlink()
    ds_ = open_dataset(ds, HASH, PLAN)
    assert ds_.pending_shards() == [S1] and sorted(read_index(ds)["shards"]) == [S0]
    rep = validate_dataset(ds, partial=True)
    assert rep.ok and any("has no manifest" in w.message for w in rep.warnings)


def test_tar_frame_json_reads_are_bounded(ds, monkeypatch):
    """A frame JSON member larger than the frame-JSON bound is reported and not read."""
    import synth.dataset.tar_validate as tv

    monkeypatch.setattr(tv, "MAX_FRAME_JSON_BYTES", 100)
    rep = validate_dataset(ds)
    msgs = [d.message for d in rep.defects if d.kind == "json"]
    assert len(msgs) == 4 and all("allowed for a frame JSON (not read)" in m for m in msgs), msgs


def test_cli_repair_index_on_a_tar_dataset(ds):
    (ds / "index.json").unlink()
    shutil.rmtree(ds / ".commits")
    manifests = {s: tar_manifest_path(ds, s).read_bytes() for s in PLAN}
    p = subprocess.run([sys.executable, "-m", "synth.cli.main", "validate", "--repair-index", str(ds)],
                       capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert p.returncode == 0, p.stdout + p.stderr
    assert f"repaired {S0}: added" in p.stdout and f"repaired {S1}: added" in p.stdout
    assert "index.json rebuilt from the manifests: 3 change(s)" in p.stdout
    assert {s: tar_manifest_path(ds, s).read_bytes() for s in PLAN} == manifests  # signed, not rewritten
    logged = [json.loads(x) for x in (ds / "logs" / "index-repairs.jsonl").read_text().splitlines()]
    assert {c["shard"] for c in logged[0]["changes"]} == {None, S0, S1}
    assert validate_dataset(ds).ok and load_dataset(ds).committed_shards() == set(PLAN)


def test_the_reader_bounds_frame_json_members(ds, monkeypatch):
    """The reader refuses a frame JSON member over the frame-JSON bound before reading it, by
    the manifest (random access) and by the header (a tar stream)."""
    import synth.dataset.reader as reader

    ref = reader.list_frames(ds)[0]
    assert ref.tar is not None and reader.loads_json(ref.json_bytes())["frame_id"] == ref.key
    monkeypatch.setattr(reader, "MAX_FRAME_JSON_BYTES", 100)
    with pytest.raises(SynthError, match="limit 100"):
        ref.json_bytes()
    with pytest.raises(SynthError, match="limit 100"):
        next(reader.iter_frames(tar_path(ds, S0)))
