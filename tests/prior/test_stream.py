"""prior.data prepare / stream: incremental prepare, the buffer bound, ranks, training while the
farm renders, damaged and foreign shards, tar shards and brace patterns."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import torch

from prior.data import Loader, RaySampler, build_table, open_source, prepare
from prior.data.prepare import MERGED_FILE, Merged
from prior.data import sources as sources_mod
from prior.data.sources import expand_braces
from prior.train import checkpoint as ckpt
from prior.train.loop import Trainer
from prior.train.run import prepare as run_prepare
from synth.errors import SynthError
from tests.prior import scene

pytest.importorskip("OpenEXR")
JOINTS = ("jaw", "eye_l", "eye_r")
VIEWS, SIZE = 4, 16


def _loader(src, prep, **kw):
    table = build_table(prepare(src, prep), joints=JOINTS, margin=0.05, planned=src.planned_identities)
    lines = []
    opts = dict(seed=0, read_ahead=1, refresh_steps=1, prepare_dir=prep, warn=lines.append)
    ld = Loader(src, table, **{**opts, **kw})
    return ld, lines


def _steps(ld, n, seed=0, identities=2, views=2):
    s = RaySampler(ld, seed=seed, identities=identities, views=views, pixels=4, rank=ld.rank)
    seen = []
    for step in range(n):
        s.batch(step)
        s.step_done()
        seen.append(tuple(ld.slots.tolist()))
    return seen


def test_prepare_is_incremental_atomic_and_a_noop_when_nothing_is_new(tmp_path):
    ds = scene.make_dataset(tmp_path / "d", identities=3, views=VIEWS, size=SIZE, commit=2)
    src, prep = open_source(ds), ds / ".prior" / "prepare"
    r1 = prepare(src, prep)
    assert (r1.written, r1.reused) == (2, 0)
    assert sorted(os.listdir(prep)) == ["shard_000000.npz", "shard_000001.npz", MERGED_FILE]
    before = {n: os.stat(prep / n).st_mtime_ns for n in os.listdir(prep)}
    r2 = prepare(src, prep)
    assert (r2.written, r2.reused) == (0, 2)
    assert {n: os.stat(prep / n).st_mtime_ns for n in os.listdir(prep)} == before  # nothing written
    scene.commit_identity(ds, 2, views=VIEWS, size=SIZE)
    r3 = prepare(src, prep)
    assert (r3.written, r3.reused) == (1, 2)
    old = {n: t for n, t in before.items() if n != MERGED_FILE}
    assert {n: os.stat(prep / n).st_mtime_ns for n in old} == old  # old shards not redone
    assert not [n for n in os.listdir(prep) if not n.endswith(".npz") and n != MERGED_FILE]  # no temporary left
    table = build_table(r3, joints=JOINTS, margin=0.05, planned=src.planned_identities)
    assert table.frames.tolist() == [2 * VIEWS] * 3
    assert len(Merged.load(prep / MERGED_FILE)) == 3  # the merged table holds the new record too
    # a merged table cut short is rebuilt from the records; a record cut short (a crash elsewhere)
    # is not trusted: it is recomputed
    (prep / MERGED_FILE).write_bytes(b"PK\x03\x04 cut")
    r4 = prepare(src, prep)
    assert (r4.written, r4.reused) == (0, 3) and len(Merged.load(prep / MERGED_FILE)) == 3
    (prep / "shard_000001.npz").write_bytes(b"PK\x03\x04 cut")
    os.unlink(prep / MERGED_FILE)
    r4 = prepare(src, prep)
    assert (r4.written, r4.reused) == (1, 2)
    t4 = build_table(r4, joints=JOINTS, margin=0.05, planned=src.planned_identities)
    np.testing.assert_array_equal(t4.info.radius, table.info.radius)
    # two worker processes write the same records
    r5 = prepare(src, tmp_path / "two", workers=2)
    assert r5.written == 3
    t5 = build_table(r5, joints=JOINTS, margin=0.05, planned=src.planned_identities)
    for k, v in table.info.arrays().items():
        np.testing.assert_array_equal(t5.info.arrays()[k], v)


def test_buffer_bound_holds_and_identities_swap(tmp_path):
    ds = scene.make_dataset(tmp_path / "d", identities=4, views=VIEWS, size=SIZE)
    src, prep = open_source(ds), ds / ".prior" / "prepare"
    full, _ = _loader(src, prep)
    full.start()
    per_identity = max(d.nbytes for d in full.held.values())
    assert full.nbytes == sum(d.nbytes for d in full.held.values()) and len(full.held) == 4
    ld, _ = _loader(src, prep, buffer_identities=1, views_per_load=0.5, read_ahead=1)
    ld.start()
    held, peak = set(), 0
    for step in range(24):
        _steps(ld, 1)
        peak = max(peak, ld.nbytes + sum(f.result().nbytes for f in ld.pending.values()))
        assert len(ld.held) == 1
        held |= set(ld.held)
    assert held == {0, 1, 2, 3} and ld.epoch >= 2  # every identity visited, several epochs
    assert peak <= 2 * per_identity  # the buffer (1) plus the read-ahead (1)
    # a buffer that holds every identity never swaps
    assert set(_steps(full, 10)) == {(0, 1, 2, 3)} and full.epoch == 0


def test_ranks_read_disjoint_shards(tmp_path, monkeypatch):
    ds = scene.make_dataset(tmp_path / "d", identities=5, views=VIEWS, size=SIZE)
    src, prep = open_source(ds), ds / ".prior" / "prepare"
    prepare(src, prep)
    read: dict[int, set] = {0: set(), 1: set()}
    real = sources_mod.read_shard
    for rank in (0, 1):
        monkeypatch.setattr("prior.data.stream.read_shard", lambda ref, ident=None, r=rank: (read[r].add(ref.shard),
                                                                                            real(ref, ident))[1])
        ld, _ = _loader(src, prep, rank=rank, world=2, buffer_identities=1, views_per_load=0.5, read_ahead=0)
        ld.start()
        _steps(ld, 12, identities=1)
    assert read[0] == {"shard_000000", "shard_000002", "shard_000004"}
    assert read[1] == {"shard_000001", "shard_000003"}


def test_training_while_rendering_takes_new_commits_never_staged(tmp_path, monkeypatch):
    ds = scene.make_dataset(tmp_path / "d", identities=5, views=VIEWS, size=SIZE, commit=2)
    src, prep = open_source(ds), ds / ".prior" / "prepare"
    touched = []
    real = sources_mod.read_shard
    monkeypatch.setattr("prior.data.stream.read_shard", lambda ref, ident=None: (touched.append(ref.path),
                                                                                 real(ref, ident))[1])
    ld, lines = _loader(src, prep, buffer_identities=1, views_per_load=0.5)
    ld.start()
    assert ld.table.info.identity_index.tolist() == [0, 1, 2, 3, 4]  # the plan's identities: latent ids fixed
    assert set().union(*_steps(ld, 6)) == {0, 1}
    staged = scene.commit_identity(ds, 3, views=VIEWS, size=SIZE, stage_only=True)  # the farm is rendering 3
    scene.commit_identity(ds, 2, views=VIEWS, size=SIZE)  # ... has committed 2
    scene.commit_identity(ds, 4, views=VIEWS, size=SIZE, head_model="another")  # ... and 4 with another head
    seen = set().union(*_steps(ld, 16))
    assert 2 in seen and 3 not in seen and 4 not in seen and ld.table.frames.tolist() == [8, 8, 8, 0, 0]
    assert ld.table.info.radius[2] > 0 and ld.table.info.radius[3] == 0
    assert not [p for p in touched if ".staging" in str(p)]
    assert len(lines) == 1 and "shard_000004" in lines[0] and "'another'" in lines[0]  # once, not per epoch
    assert ld.state_dict()["skipped"] == lines
    staged.__exit__(None, None, None)


def _corrupt_one_exr(shard_dir):
    exr = sorted(shard_dir.glob("*.exr"))[0]
    data = bytearray(exr.read_bytes())
    data[len(data) // 2] ^= 0xFF
    os.chmod(exr, 0o644)
    exr.write_bytes(bytes(data))


def test_damaged_shard_is_skipped_with_one_line_and_training_goes_on(tmp_path, capsys):
    ds = scene.make_dataset(tmp_path / "d", identities=3, views=VIEWS, size=SIZE)
    run = tmp_path / "run"
    sets = [*scene.TINY, "data.buffer_identities=1", "data.views_per_load=0.5", "train.identities_per_batch=1"]
    s = run_prepare(ds, run, sets=sets, steps=8)  # the prepare records are written ...
    _corrupt_one_exr(ds / "shards" / "shard_000001")  # ... then a shard is damaged on disk
    assert Trainer(s, torch.device("cpu"), tty=False, tensorboard=False).run() == 0
    out = capsys.readouterr()
    lines = [x for x in (out.out + out.err).splitlines() if "warning" in x]
    assert len(lines) == 1 and "shard_000001" in lines[0] and "sha256" in lines[0]
    metrics = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
    assert metrics[-1]["skipped_shards"] == 1 and metrics[-1]["step"] == 8
    # and the prepare pass skips a damaged shard with one line too
    lines2 = []
    r = prepare(open_source(ds), tmp_path / "fresh", warn=lines2.append)
    assert len(r.records) == 2 and len(lines2) == 1 and "shard_000001" in lines2[0]


@pytest.mark.parametrize("other", [dict(size=24), dict(head_model="another")])
def test_resume_on_another_head_model_or_resolution_is_refused(tmp_path, other):
    ds = scene.make_dataset(tmp_path / "d", identities=2, views=VIEWS, size=SIZE)
    run = tmp_path / "run"
    s = run_prepare(ds, run, sets=scene.TINY, steps=2)
    assert Trainer(s, torch.device("cpu"), tty=False, tensorboard=False).run() == 0
    ds2 = scene.make_dataset(tmp_path / "d2", identities=2, views=VIEWS, **{"size": SIZE, **other})
    before = sorted((p.relative_to(tmp_path), p.stat().st_mtime_ns) for p in tmp_path.rglob("*") if "d2" not in p.parts)
    with pytest.raises(SynthError, match="24x24|head model 'another'") as e:
        run_prepare(ds2, run, resume=True, steps=4)
    assert "\n" not in str(e.value)
    after = sorted((p.relative_to(tmp_path), p.stat().st_mtime_ns) for p in tmp_path.rglob("*") if "d2" not in p.parts)
    assert after == before and not (ds2 / ".prior").exists()


def test_tar_shards_by_brace_pattern_read_like_the_directory(tmp_path):
    ds = scene.make_dataset(tmp_path / "d", identities=3, views=VIEWS, size=SIZE, shard_format="tar")
    pattern = str(ds / "shards" / "shard_{000000..000002}.tar")
    assert expand_braces("a{08..10}b{x,y}") == ["a08bx", "a08by", "a09bx", "a09by", "a10bx", "a10by"]
    a, _ = _loader(open_source(ds), tmp_path / "pa")
    b, _ = _loader(open_source([pattern]), tmp_path / "pb")
    a.start()
    b.start()
    assert b.source.root is None and len(b.source.paths) == 3
    np.testing.assert_array_equal(a.table.info.radius, b.table.info.radius)
    for m in range(3):
        assert a.held[m].keys == b.held[m].keys
        np.testing.assert_array_equal(a.held[m].rgba, b.held[m].rgba)
    with pytest.raises(SynthError, match="not a tar shard"):
        open_source([str(ds / "shards" / "shard_{000000..000003}.tar")])


def test_an_identity_over_two_shards_gets_a_sphere_holding_both(tmp_path):
    ds = scene.make_dataset(tmp_path / "d", identities=1, views=VIEWS, size=SIZE)
    src = open_source(ds)
    res = prepare(src, ds / ".prior" / "prepare")
    one = build_table(res, joints=JOINTS, margin=0.0)
    rec = dict(res.records[0])  # the same identity's frames again, in a second shard, moved 5 cm along x
    shift = np.array([0.05, 0.0, 0.0])
    rec["box"], rec["centre"] = rec["box"] + shift, rec["centre"] + shift
    res.records.append(rec)
    res.refs.append(res.refs[0]._replace(shard="shard_000001"))
    two = build_table(res, joints=JOINTS, margin=0.0)
    assert two.frames.tolist() == [2 * one.frames[0]] and len(two.shards_of[0]) == 2
    c, r = two.info.centre[0], two.info.radius[0]
    box = np.concatenate([res.records[0]["box"][0], rec["box"][0]])
    np.testing.assert_allclose(c, 0.5 * (box.min(0) + box.max(0)))  # the merged box's centre
    for cs in (one.info.centre[0], one.info.centre[0] + shift):  # both spheres inside
        assert np.linalg.norm(cs - c) + one.info.radius[0] <= r + 1e-9


def _same_tables(a, b):
    for k, v in a.info.arrays().items():
        np.testing.assert_array_equal(b.info.arrays()[k], v, err_msg=k)
    np.testing.assert_array_equal(a.frames, b.frames)
    assert a.shards_of == b.shards_of and a.layout == b.layout and a.size == b.size and a.head_model == b.head_model


def test_the_merged_table_builds_the_table_the_records_build(tmp_path, monkeypatch):
    import importlib

    prep_mod = importlib.import_module("prior.data.prepare")  # the package exports the function of that name
    from prior.data.prepare import MergedRecord, PrepareResult, _read_record

    ds = scene.make_dataset(tmp_path / "d", identities=4, views=VIEWS, size=SIZE)
    src = open_source(ds)
    monkeypatch.setattr(prep_mod, "MERGE_IN_CHILD_AT", 1)  # the merged table written by a child process
    res = prepare(src, tmp_path / "p")
    assert all(isinstance(r, MergedRecord) for r in res.records) and (tmp_path / "p" / MERGED_FILE).is_file()
    merged = build_table(res, joints=JOINTS, margin=0.05, planned=src.planned_identities)
    files = PrepareResult([_read_record(tmp_path / "p" / f"{r.shard}.npz") for r in res.refs], list(res.refs))
    one_by_one = build_table(files, joints=JOINTS, margin=0.05, planned=src.planned_identities)
    _same_tables(merged, one_by_one)
    # records of the merged table mixed with records read from their files, in shard order
    mixed = PrepareResult([res.records[0], dict(files.records[1]), files.records[2], res.records[3]], list(res.refs))
    _same_tables(build_table(mixed, joints=JOINTS, margin=0.05, planned=src.planned_identities), one_by_one)
    # a rank that does not write the merged table (not rank 0) reads the records and writes nothing
    prepare(src, tmp_path / "q", workers=1)
    os.unlink(tmp_path / "q" / MERGED_FILE)
    before = sorted(os.listdir(tmp_path / "q"))
    other = prepare(src, tmp_path / "q", write_merged=False)
    assert sorted(os.listdir(tmp_path / "q")) == before and other.reused == 4
    _same_tables(build_table(other, joints=JOINTS, margin=0.05, planned=src.planned_identities), one_by_one)
    # a missing joint names the identity, the shard and what the frames have
    with pytest.raises(SynthError, match=r"identity 0 have no rotation for joint\(s\) head \(they have: "
                                         r"eye_l, eye_r, jaw, neck\)"):
        build_table(res, joints=(*JOINTS, "head"), margin=0.05)


def test_the_identity_code_is_held_once_per_identity_and_saved_as_full_rows(tmp_path):
    ds = scene.make_dataset(tmp_path / "d", identities=3, views=VIEWS, size=SIZE)
    src = open_source(ds)
    res = prepare(src, tmp_path / "p")
    t = build_table(res, joints=JOINTS, margin=0.05, planned=src.planned_identities)
    info, size = t.info, t.layout.identity_size
    assert info.codes is None and info.identity_codes.shape == (3, size)  # every row of an identity agrees
    full = info.arrays()["codes"]
    assert full.dtype == np.float32 and full.shape == (len(info.code_keys), t.layout.size)
    for q, (m, e) in enumerate(info.code_keys.tolist()):
        np.testing.assert_array_equal(info.code(m, e), full[q])
    # an identity whose expressions carry different identity codes keeps full rows, exactly
    rec = dict(res.records[1])
    rec["beta"] = rec["beta"].copy()
    rec["beta"][1] += 0.5
    res.records[1] = rec
    t2 = build_table(res, joints=JOINTS, margin=0.05, planned=src.planned_identities)
    assert t2.info.codes is not None and t2.info.identity_codes is None
    rows = t2.info.code_keys[:, 0] == 1
    np.testing.assert_array_equal(t2.info.codes[rows][1, :size], rec["beta"][1])
    np.testing.assert_array_equal(t2.info.codes[~rows], full[~rows])
