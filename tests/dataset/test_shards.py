"""Shards: layout, atomic commit, resume after kill -9, concurrent commits, plan mismatch."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from tests.support import fake_frames as ff
from synth.dataset.index import read_index, repair_index
from synth.dataset.layout import frame_key, shard_name
from synth.dataset.shards import load_dataset, open_dataset
from synth.dataset.validate import validate_dataset
from synth.errors import SynthError

pytest.importorskip("OpenEXR")

REPO = Path(__file__).resolve().parents[2]
HASH = "f" * 64

# A worker that renders fake frames into a dataset; it can SIGKILL itself at the N-th file-system
# sync point (os.replace / os.rename / os.fsync), or be killed from outside at a random moment.
CHILD = r"""
import os, signal, sys, json
sys.path.insert(0, os.environ["REPO_DIR"])
from tests.support import fake_frames as ff
from synth.dataset.shards import open_dataset

root, die_at, log = sys.argv[1], int(sys.argv[2]), sys.argv[3]
plan = json.loads(os.environ["PLAN"])
sleep = float(os.environ.get("SIM_RENDER_S", "0"))
calls = []
if die_at >= 0:
    def wrap(name, fn):
        def w(*a, **k):
            calls.append(f"{name} {os.path.basename(str(a[0])) if a else ''}")
            if len(calls) == die_at:
                os.kill(os.getpid(), signal.SIGKILL)
            return fn(*a, **k)
        return w
    for name in ("replace", "rename", "fsync"):
        setattr(os, name, wrap(name, getattr(os, name)))
def logged(key):
    with open(log, "a") as f:
        f.write(key + "\n")
ds = open_dataset(root, os.environ["PLAN_HASH"], plan, shard_format=os.environ.get("SHARD_FORMAT") or None)
for sid in ds.pending_shards():
    st = ds.try_staging(sid)
    if st is None:  # another worker holds it, or committed it meanwhile
        continue
    with st:
        ff.stage_missing(st, sleep, logged)
        st.commit(manifest_extra={"seeds": {"run": 1}})
print(json.dumps(calls))
"""


def run_child(root, plan, log, die_at=-1, sleep=0.0, wait=True, fmt=None):
    env = dict(os.environ, REPO_DIR=str(REPO), PLAN=json.dumps(plan), PLAN_HASH=HASH, SIM_RENDER_S=str(sleep),
               SHARD_FORMAT=fmt or "")
    p = subprocess.Popen([sys.executable, "-c", CHILD, str(root), str(die_at), str(log)], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if not wait:
        return p
    out, err = p.communicate(timeout=120)
    return p.returncode, out, err


def assert_consistent(root, plan, fmt=None):
    """Every committed shard verifies completely; the index matches the files once reopened."""
    ds = open_dataset(root, HASH, plan, shard_format=fmt)  # reopening repairs a stale index
    rep = validate_dataset(root, partial=True)
    assert rep.defects == [], [d.line() for d in rep.defects]
    committed = ds.committed_shards()
    assert set(read_index(root)["shards"]) == committed
    return ds


def resume(ds, log: Path) -> None:
    """What rerunning the render command does (in-process), logging every frame it renders."""
    for sid in ds.pending_shards():
        with ds.staging(sid) as st:
            done = st.frames_done()
            for key in st.expected_keys:
                if key not in done:
                    st.write_frame(key, *ff.pixels(key), ff.frame_json(key))
                    with open(log, "a") as f:
                        f.write(key + "\n")
            st.commit(manifest_extra={"seeds": {"run": 1}})


def logged(log: Path) -> Counter:
    return Counter(log.read_text().split()) if log.exists() else Counter()


# -- layout and commit -------------------------------------------------------------------------

def test_commit_layout_manifest_and_index(tmp_path):
    plan = ff.plan(2)
    ds = open_dataset(tmp_path / "ds", HASH, plan, meta={"config": {"views": 3}})
    assert ds.pending_shards() == ["shard_000000", "shard_000001"]
    ff.render_dataset(ds)
    root = tmp_path / "ds"
    assert sorted(os.listdir(root)) == [".commits", ".lock", ".staging", "dataset.json", "index.json", "shards"]
    assert sorted(os.listdir(root / ".commits")) == ["shard_000000.json", "shard_000001.json"]  # the signatures
    assert os.listdir(root / ".staging") == []  # nothing left behind (no locks either)
    info = json.loads((root / "dataset.json").read_text())
    assert info["plan_hash"] == HASH and info["expected"] == plan and info["meta"]["config"]["views"] == 3
    sd = root / "shards" / "shard_000001"
    files = sorted(os.listdir(sd))
    assert files == sorted([f"{k}.{e}" for k in plan["shard_000001"] for e in ("exr", "json")] + ["manifest.json"])
    m = json.loads((sd / "manifest.json").read_text())
    assert m["frames"] == plan["shard_000001"] and m["seeds"] == {"run": 0} and m["plan_hash"] == HASH
    assert set(m["files"]) == set(files) - {"manifest.json"}
    import hashlib

    for name, ent in m["files"].items():
        assert hashlib.sha256((sd / name).read_bytes()).hexdigest() == ent["sha256"]
        assert (sd / name).stat().st_mode & 0o222 == 0  # read-only
    idx = read_index(root)
    assert idx["num_shards"] == 2 and idx["num_frames"] == 12
    assert idx["shards"]["shard_000001"]["manifest_sha256"] == hashlib.sha256((sd / "manifest.json").read_bytes()
                                                                               ).hexdigest()
    assert repair_index(root, HASH)[0] == idx
    assert ds.committed_shards() == {"shard_000000", "shard_000001"} and ds.pending_shards() == []
    assert load_dataset(root).committed_shards() == ds.committed_shards()


def test_different_plan_is_refused(tmp_path):
    open_dataset(tmp_path, HASH, ff.plan(1))
    with pytest.raises(SynthError, match="different plan") as e:
        open_dataset(tmp_path, "0" * 64, ff.plan(1))
    assert "use a new --out or the original plan" in str(e.value)
    # same hash, different shard layout: refused too
    with pytest.raises(SynthError, match="expected shards differ"):
        open_dataset(tmp_path, HASH, ff.plan(2))


def test_non_dataset_directory_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("hi")
    with pytest.raises(SynthError, match="not empty"):
        open_dataset(tmp_path, HASH, ff.plan(1))
    with pytest.raises(SynthError, match="not a directory"):
        open_dataset(tmp_path / "notes.txt", HASH, ff.plan(1))
    with pytest.raises(SynthError, match="no dataset.json"):
        load_dataset(tmp_path)


@pytest.mark.parametrize("bad", [{}, {"shard_000000": []}, {"../x": ["id000000_ex00_v00"]},
                                 {"shard_000000": ["id0_ex0_v0"]},
                                 {"a": ["id000000_ex00_v00"], "b": ["id000000_ex00_v00"]}])
def test_bad_plans_refused(tmp_path, bad):
    with pytest.raises(SynthError):
        open_dataset(tmp_path / "ds", HASH, bad)


def test_commit_refuses_incomplete_and_repeated(tmp_path):
    plan = ff.plan(1)
    ds = open_dataset(tmp_path, HASH, plan)
    keys = plan["shard_000000"]
    with ds.staging("shard_000000") as st:
        for k in keys[:-1]:
            st.write_frame(k, *ff.pixels(k), ff.frame_json(k))
        with pytest.raises(SynthError, match="1 of 6 frame"):
            st.commit()
        assert ds.committed_shards() == set()
        k = keys[-1]
        st.write_frame(k, *ff.pixels(k), ff.frame_json(k))
        with pytest.raises(SynthError, match="differ from the plan"):
            st.commit(expected_keys=keys[:-1])
        with pytest.raises(SynthError, match="reserved"):
            st.commit(manifest_extra={"frames": []})
        st.commit(expected_keys=keys)
        with pytest.raises(SynthError, match="already committed"):
            st.commit()
        with pytest.raises(SynthError, match="already committed"):
            st.write_frame(k, *ff.pixels(k), ff.frame_json(k))
    with pytest.raises(SynthError, match="already committed"):
        ds.staging("shard_000000")
    with pytest.raises(SynthError, match="not in this dataset's plan"):
        ds.staging("shard_000009")


def test_write_frame_checks(tmp_path):
    ds = open_dataset(tmp_path, HASH, ff.plan(1))
    key = "id000000_ex00_v00"
    with ds.staging("shard_000000") as st:
        with pytest.raises(SynthError, match="not planned"):
            st.write_frame("id000005_ex00_v00", *ff.pixels(key), ff.frame_json("id000005_ex00_v00"))
        with pytest.raises(SynthError, match="frame_id"):
            st.write_frame(key, *ff.pixels(key), ff.frame_json("id000000_ex00_v01"))
        bad = ff.frame_json(key)
        del bad["landmarks_2d"]
        with pytest.raises(SynthError, match="invalid frame JSON"):
            st.write_frame(key, *ff.pixels(key), bad)
        with pytest.raises(SynthError, match="image is 32x32"):
            st.write_frame(key, *ff.pixels(key, 32), ff.frame_json(key, 16))
        rgba, depth, n, seg = ff.pixels(key)
        rgba[3, 3, 0] = np.nan
        with pytest.raises(SynthError, match="NaN"):
            st.write_frame(key, rgba, depth, n, seg, ff.frame_json(key))
        assert st.frames_done() == set()
        assert os.listdir(st.dir) == []


def test_one_process_per_shard(tmp_path):
    ds = open_dataset(tmp_path, HASH, ff.plan(1))
    with ds.staging("shard_000000"):
        other = open_dataset(tmp_path, HASH, ff.plan(1))  # as a second worker would
        with pytest.raises(SynthError, match="being rendered by another process"):
            other.staging("shard_000000")
        assert other.try_staging("shard_000000") is None
    with other.staging("shard_000000"):  # released on exit
        pass
    assert ds.summary() == {"shards": 1, "shards_committed": 0, "frames": 6, "frames_committed": 0}
    ff.render_dataset(ds)
    assert ds.try_staging("shard_000000") is None
    assert ds.summary()["frames_committed"] == 6


def test_resume_reuses_finished_frames_and_cleans_leftovers(tmp_path):
    plan = ff.plan(1)
    keys = plan["shard_000000"]
    ds = open_dataset(tmp_path, HASH, plan)
    with ds.staging("shard_000000") as st:
        for k in keys[:3]:
            st.write_frame(k, *ff.pixels(k), ff.frame_json(k))
        d = st.dir
    # what a kill -9 can leave: a temp file, an EXR whose JSON never landed
    (d / f".{keys[3]}.exr.123.abcd.tmp").write_bytes(b"partial")
    (d / f"{keys[3]}.exr").write_bytes((d / f"{keys[0]}.exr").read_bytes())
    # and damage no crash can cause, handled anyway: a JSON whose EXR is gone
    os.unlink(d / f"{keys[2]}.exr")
    ds = open_dataset(tmp_path, HASH, plan)
    with ds.staging("shard_000000") as st:
        assert st.frames_done() == set(keys[:2])
        assert sorted(os.listdir(d)) == sorted(f"{k}.{e}" for k in keys[:2] for e in ("exr", "json"))
        assert f"{keys[3]}.exr" in st.cleaned and f"{keys[2]}.json" in st.cleaned
        mtimes = {k: (d / f"{k}.exr").stat().st_mtime_ns for k in keys[:2]}
        for k in keys:
            if k not in st.frames_done():
                st.write_frame(k, *ff.pixels(k), ff.frame_json(k))
        assert {k: (d / f"{k}.exr").stat().st_mtime_ns for k in keys[:2]} == mtimes
        st.commit()
    assert validate_dataset(tmp_path).ok


# -- kill -9 -----------------------------------------------------------------------------------

def _kill_at(tmp_path, points, plan, fmt=None):
    """Kill a worker at each given sync point, check, resume; no frame is rendered twice."""
    for n in points:
        root, log = tmp_path / f"k{n}", tmp_path / f"k{n}.log"
        rc, out, err = run_child(root, plan, log, die_at=n, fmt=fmt)
        assert rc == -signal.SIGKILL, (n, rc, err)
        assert_consistent(root, plan, fmt)
        ds = assert_consistent(root, plan, fmt)
        resume(ds, log)
        ds = assert_consistent(root, plan, fmt)
        assert ds.pending_shards() == []
        assert validate_dataset(root).ok
        c = logged(log)
        assert max(c.values()) == 1, f"kill at point {n}: frames rendered twice: {[k for k, v in c.items() if v > 1]}"


def _sync_points(tmp_path, plan, fmt=None) -> list[str]:
    rc, out, err = run_child(tmp_path / "dry", plan, tmp_path / "dry.log", die_at=10**9, fmt=fmt)
    assert rc == 0, err
    return json.loads(out)


def test_kill9_at_selected_sync_points(tmp_path):
    plan = ff.plan(1, 1, 2)  # one shard of two frames
    points = _sync_points(tmp_path, plan)
    # dataset creation, the first frame's EXR and JSON renames, the manifest rename, the commit rename
    want = []
    for i, c in enumerate(points, 1):
        if c.startswith(("replace .dataset.json", "replace .id000000_ex00_v00.", "replace .manifest.json",
                         "rename shard_")):
            want.append(i)
    want.append(len(points))  # the very last fsync
    assert len(want) >= 5, points
    _kill_at(tmp_path, want, plan)


@pytest.mark.slow
def test_kill9_at_every_sync_point(tmp_path):
    plan = ff.plan(2, 1, 1)  # two shards: also kills while another shard is already committed
    points = _sync_points(tmp_path, plan)
    _kill_at(tmp_path, range(1, len(points) + 1), plan)


@pytest.mark.slow
def test_kill9_at_random_moments(tmp_path):
    plan = ff.plan(6, 2, 2)
    root, log = tmp_path / "ds", tmp_path / "log"
    rng = np.random.default_rng(1234)
    kills = 0
    for _ in range(12):
        p = run_child(root, plan, log, sleep=0.1, wait=False)
        time.sleep(float(rng.uniform(0.3, 1.2)))
        if p.poll() is not None:
            break
        p.send_signal(signal.SIGKILL)
        p.wait()
        kills += 1
        assert_consistent(root, plan)
    rc, out, err = run_child(root, plan, log)
    assert rc == 0, err
    ds = assert_consistent(root, plan)
    assert ds.pending_shards() == [] and validate_dataset(root).ok
    c = logged(log)
    assert max(c.values()) == 1, [k for k, v in c.items() if v > 1]
    assert kills >= 3


def test_concurrent_workers_keep_the_index_consistent(tmp_path):
    plan = {shard_name(i): [frame_key(i, 0, 0)] for i in range(10)}
    root = tmp_path / "ds"
    open_dataset(root, HASH, plan)
    procs = [run_child(root, plan, tmp_path / f"log{j}", sleep=0.01, wait=False) for j in range(3)]
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
    idx = read_index(root)
    assert sorted(idx["shards"]) == sorted(plan) and idx["num_frames"] == 10
    assert repair_index(root, HASH)[0] == idx
    total = sum((logged(tmp_path / f"log{j}") for j in range(3)), Counter())
    assert total == Counter(k for ks in plan.values() for k in ks)  # each frame rendered once, by one worker
    assert validate_dataset(root).ok
