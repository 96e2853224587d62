"""Faults around the command line (docs/reliability.md): several renders started at once on one
directory, read-only and full file systems (a small tmpfs), paths that are not UTF-8, and the
laundering sequence (tamper, rerun, delete the index, repair). No Blender: datasets are filled
with fake frames (tests.support.datasets) and renders run tests.support.dataset_worker; the
same races with real renders are in tests/blender/test_reliability.py.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from tests.support import datasets
from tests.support.farm_helpers import ROOT, SYNTH, env
from tests.support.toy_model import write_toy_model
from synth.dataset.validate import validate_dataset

pytest.importorskip("OpenEXR")


def synth(*args, cwd: Path | None = None) -> subprocess.CompletedProcess:
    p = subprocess.run([*SYNTH, *map(str, args)], capture_output=True, text=True, env=env(), cwd=cwd or ROOT,
                       timeout=600)
    assert "Traceback" not in p.stdout + p.stderr, p.stdout + p.stderr
    return p


def error_line(p: subprocess.CompletedProcess) -> str:
    lines = [x for x in p.stderr.splitlines() if x.startswith("synth: error:")]
    assert len(lines) == 1, p.stdout + p.stderr
    return lines[0]


def listing(root: Path) -> dict[str, tuple]:
    """Every entry under ``root``: its kind and, for files, size and modification time (a
    directory's own time changes when a temporary file comes and goes)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for n in dirnames + filenames:
            p = Path(dirpath) / n
            st = os.lstat(p)
            out[os.fsdecode(p.relative_to(root))] = (st.st_mode,) + (() if n in dirnames else
                                                                      (st.st_size, st.st_mtime_ns))
    return out


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    return write_toy_model(tmp_path_factory.mktemp("model") / "toy.npz")


@pytest.fixture
def tmpfs(tmp_path):
    """A fresh 8 MiB tmpfs (root only), unmounted afterwards."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    try:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(mnt)], capture_output=True,
                           text=True)
    except FileNotFoundError:
        pytest.skip("no mount command: the file-system fault tests need a tmpfs")
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs ({r.stderr.strip()}): the file-system fault tests need root")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def remount_ro(mnt: Path) -> None:
    subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True, capture_output=True)


def fill(mnt: Path, leave: int = 0) -> None:
    """Leave about ``leave`` bytes free on ``mnt``."""
    st = os.statvfs(mnt)
    with open(mnt / "filler", "wb") as f:
        f.write(b"\0" * max(0, st.f_bavail * st.f_frsize - leave))


# -- several renders on one directory at the same moment -------------------------------------------

CONTROLLER = r"""
import json, os, sys, time
from pathlib import Path
from renderer_jobs.local import LocalBackend
from renderer_jobs.submit import prepare_plan, render_plan
from synth.cli.boundary import translate
from synth.dataset.shards import load_dataset
from tests.support import dataset_worker, datasets

out, model, n, go = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3]), Path(sys.argv[4])
while not go.exists():
    time.sleep(0.001)
try:
    pdir = prepare_plan(out, n, None, datasets.SETS, datasets.SEED, model)
    res = render_plan(out, pdir, LocalBackend(workers=1, cmd=dataset_worker.command), shards_per_worker=1,
                      quiet=True, poll_s=0.2)
except Exception as e:
    err = translate(e)
    if err is None:
        raise
    print(json.dumps({"error": str(err)}))
    sys.exit(err.exit_code)
print(json.dumps({"rendered": res["frames_rendered"], "at_exit": load_dataset(out).summary()}))
"""


@pytest.mark.slow
@pytest.mark.parametrize("runs", [2, 4])
def test_renders_started_together_share_one_plan_and_split_the_shards(tmp_path, model, runs):
    out, go, log = tmp_path / "ds", tmp_path / "go", tmp_path / "frames.log"
    e = env(FAKE_LOG=str(log), FAKE_RENDER_S="0.1")
    procs = [subprocess.Popen([sys.executable, "-c", CONTROLLER, str(out), str(model), "4", str(go)], env=e,
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(runs)]
    time.sleep(1.0)  # all of them imported and spinning on the start line
    go.touch()
    results = []
    for p in procs:
        o, err = p.communicate(timeout=600)
        assert p.returncode == 0, o + err
        results.append(json.loads(o.splitlines()[-1]))
    for r in results:  # nobody returned before every shard was committed
        assert r["at_exit"]["shards_committed"] == r["at_exit"]["shards"] == 4
    frames = Counter(log.read_text().split())
    assert len(frames) == 8 and set(frames.values()) == {1}  # every frame rendered once, by one of the runs
    assert sum(r["rendered"] for r in results) == 8
    assert sorted(n for n in os.listdir(out) if n.startswith(".")) == [".commits", ".lock", ".staging"]  # no temp plans
    assert validate_dataset(out).ok


# -- read-only and full file systems ---------------------------------------------------------------

def test_read_only_media(tmpfs, model):
    ds = datasets.fake_render(tmpfs / "ds", model, n=2)
    remount_ro(tmpfs)
    before = listing(tmpfs)
    p = synth(*datasets.render_args(2, model, ds))
    assert p.returncode == 0 and "2/2 shards committed" in p.stdout.replace("frames in ", ""), p.stdout + p.stderr
    assert synth("validate", ds).returncode == 0
    for args in (["plan", "-n", "1", "--model", model, "--out", tmpfs / "p"],
                 datasets.render_args(1, model, tmpfs / "new"),
                 ["model", "sample", "--model", model, "--out", tmpfs / "s"],
                 ["validate", "--repair-index", ds]):
        p = synth(*args)
        assert p.returncode == 2 and "read-only file system" in error_line(p), (args, p.stderr)
    assert listing(tmpfs) == before


def test_full_disk(tmpfs, model):
    ds = datasets.fake_render(tmpfs / "ds", model, n=2)
    datasets.tamper_frame(ds)  # so that a repair has something to write
    index = (ds / "index.json").read_bytes()
    fill(tmpfs)
    before = listing(tmpfs)
    for args in (["plan", "-n", "40", "--model", model, "--out", tmpfs / "p"],  # ~11 MB of plan
                 ["model", "sample", "--n", "200", "--model", model, "--out", tmpfs / "deep" / "s"],
                 ["validate", "--repair-index", ds]):
        p = synth(*args)
        line = error_line(p)
        assert p.returncode == 4 and f"out of disk space writing {args[-1]}" in line and "MiB left on" in line, line
        assert listing(tmpfs) == before, args  # nothing half-written, no directory created
    assert (ds / "index.json").read_bytes() == index
    (tmpfs / "filler").unlink()  # with space, the same commands work
    assert synth("model", "sample", "--n", "200", "--model", model, "--out", tmpfs / "deep" / "s").returncode == 0
    assert synth("validate", "--repair-index", ds).returncode == 0


# -- paths that are not UTF-8 -----------------------------------------------------------------------

def test_paths_that_are_not_utf8_work(tmp_path, model):
    base = os.fsencode(tmp_path)
    plan_dir = Path(os.fsdecode(base + b"/plan-\xff"))
    p = synth("plan", "-n", "1", "--model", model, "--out", plan_dir, "-q")
    assert p.returncode == 0 and (plan_dir / "plan.json").is_file(), p.stderr
    ds = datasets.fake_render(Path(os.fsdecode(base + b"/ds-\xe9\xff")), model, n=1)
    p = synth("validate", ds)
    assert p.returncode == 0 and "\\udcff" in p.stdout, p.stdout  # printed escaped, not refused
    p = synth(*datasets.render_args(1, model, ds))
    assert p.returncode == 0 and "1/1 shards committed" in p.stdout.replace("frames in ", ""), p.stderr


# -- integrity cannot be laundered ----------------------------------------------------------------

def test_laundering_sequence(tmp_path, model):
    ds = datasets.fake_render(tmp_path / "ds", model, n=2)
    p = synth("validate", ds)
    assert p.returncode == 0
    digest = p.stdout.split("digest ")[1].split()[0]
    datasets.tamper_frame(ds)
    p = synth("validate", ds)
    assert p.returncode == 1 and "shard_000000: manifest: manifest.json changed after commit" in p.stdout

    index = (ds / "index.json").read_bytes()  # a no-op rerun of the render never re-signs the manifest
    p = synth(*datasets.render_args(2, model, ds))
    assert p.returncode == 0, p.stderr
    assert (ds / "index.json").read_bytes() == index
    assert synth("validate", ds).returncode == 1

    (ds / "index.json").unlink()  # nor does losing the index: the commit records still sign each shard
    p = synth("validate", ds)
    assert p.returncode == 1 and "index.json is missing" in p.stdout and "changed after commit" in p.stdout
    p = synth(*datasets.render_args(2, model, ds))
    assert p.returncode == 0 and not (ds / "index.json").exists(), p.stderr  # complete: nothing written
    shutil.rmtree(ds / ".commits")  # and with every signature gone, nothing is adopted
    p = synth(*datasets.render_args(2, model, ds))
    assert p.returncode == 2 and "--repair-index" in error_line(p)

    p = synth("validate", "--repair-index", ds)  # the explicit repair signs what the manifests say, and says so
    assert p.returncode == 0, p.stdout + p.stderr
    assert "repaired index.json: added (index.json was missing)" in p.stdout
    assert "repaired shard_000000: added" in p.stdout and "repaired shard_000001: added" in p.stdout
    new_digest = p.stdout.split("digest ")[1].split()[0]
    assert new_digest != digest  # the dataset-level digest shows that a manifest changed
    logged = [json.loads(x) for x in (ds / "logs" / "index-repairs.jsonl").read_text().splitlines()]
    assert len(logged) == 1 and {c["shard"] for c in logged[0]["changes"]} == {None, "shard_000000", "shard_000001"}


def test_repair_reports_a_changed_manifest(tmp_path, model):
    ds = datasets.fake_render(tmp_path / "ds", model, n=2)
    datasets.tamper_frame(ds, "shard_000001")
    p = synth("validate", "--repair-index", ds)
    assert p.returncode == 0 and "repaired shard_000001: changed (manifest sha256 " in p.stdout, p.stdout
    assert "shard_000000" not in p.stdout.split("index.json rebuilt")[0]
    p = synth("validate", "--repair-index", ds)  # nothing left to repair
    assert "0 change(s)" in p.stdout and len((ds / "logs" / "index-repairs.jsonl").read_text().splitlines()) == 1


def test_a_shard_put_there_by_hand_is_not_adopted(tmp_path, model):
    ds = datasets.fake_render(tmp_path / "ds", model, n=2, shards=["shard_000000"])
    other = datasets.fake_render(tmp_path / "other", model, n=2)
    shutil.copytree(other / "shards" / "shard_000001", ds / "shards" / "shard_000001")
    p = synth(*datasets.render_args(2, model, ds))
    assert p.returncode == 2 and "shards/shard_000001 has no commit record" in error_line(p)
    p = synth("validate", ds)
    assert p.returncode == 1 and "shard_000001: index: no commit record" in p.stdout
