"""Plan-or-resume and batching (renderer_jobs.submit) with a fake backend that writes fake
frames through the dataset API: no bpy. What is done is read from the dataset's files."""

from __future__ import annotations

import io
import json
import os
import platform
import subprocess
import time
from contextlib import contextmanager
from dataclasses import asdict

from tests.support import fake_frames as ff
import pytest
from tests.support.toy_model import write_toy_model

from renderer_jobs.backend import Backend, Batch, Job, Run
from renderer_jobs.events import EXIT_DISK_FULL, EXIT_INPUT, BatchEnd, Commit, Error, Frame
from renderer_jobs.submit import MAX_ROUNDS, make_batches, prepare_plan, render_plan
from renderer_jobs.progress import Progress
from synth.dataset.layout import lease_path
from synth.dataset.lease import Holder, _boot_id, process_start
from synth.dataset.shards import open_dataset
from synth.errors import DiskFull, Incomplete, SynthError, WorkerFailed
from synth.plan.io import load_plan

SETS = ["dataset.expressions_per_identity=2", "dataset.views_per_expression=2", 'render.preset="ci"']


class FakeRun(Run):
    def __init__(self, job: Job, backend: FakeBackend):
        self.job, self.backend = job, backend

    def events(self):
        b = self.backend
        plan = load_plan(self.job.plan_dir)
        ds = open_dataset(self.job.dataset, plan.plan_hash, plan.expected())
        for batch in self.job.batches:
            if b.interrupt:
                raise KeyboardInterrupt
            for sid in batch.shards:
                if not b.lie:
                    with ds.staging(sid) as st:
                        done = st.frames_done()
                        for key in st.expected_keys:
                            if key not in done:
                                st.write_frame(key, *ff.pixels(key), ff.frame_json(key))
                                yield Frame(shard=sid, key=key, render_seconds=0.25)
                        st.commit()
                else:  # claims work it never did
                    yield Frame(shard=sid, key="id000000_ex00_v00", render_seconds=0.25)
                yield Commit(shard=sid)
            if b.error:
                yield Error(shard=",".join(batch.shards), message=b.error)
            for attempt, rc in enumerate(b.returncodes):
                yield BatchEnd(batch=batch.index, shards=batch.shards, attempt=attempt, returncode=rc,
                               log_tail=f"log of batch {batch.index}", retry=attempt + 1 < len(b.returncodes))

    def cancel(self):
        self.backend.cancelled = True


class FakeBackend(Backend):
    name = "fake"

    def __init__(self, lie=False, returncodes=(0,), interrupt=False, error=None):
        self.lie, self.returncodes, self.interrupt, self.error = lie, returncodes, interrupt, error
        self.jobs: list[Job] = []
        self.cancelled = False

    def submit(self, job: Job) -> Run:
        self.jobs.append(job)
        return FakeRun(job, self)


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return write_toy_model(tmp_path_factory.mktemp("model") / "toy.npz")


@pytest.fixture
def planned(tmp_path, toy):
    out = tmp_path / "ds"
    return out, prepare_plan(out, 3, None, SETS, 7, toy)


def test_make_batches():
    ids = [f"s{i}" for i in range(5)]
    assert make_batches(ids, 2) == (Batch(0, ("s0", "s1")), Batch(1, ("s2", "s3")), Batch(2, ("s4",)))
    assert make_batches(ids, 1) == tuple(Batch(i, (s,)) for i, s in enumerate(ids))
    assert make_batches(ids, 99) == (Batch(0, tuple(ids)),)
    assert make_batches([], 2) == ()
    with pytest.raises(ValueError):
        make_batches(ids, 0)


def test_renders_what_is_missing_then_resumes_with_nothing(planned):
    out, pdir = planned
    assert pdir == out / "plan"
    plan = load_plan(pdir)
    ds = open_dataset(out, plan.plan_hash, plan.expected())
    ff.render_dataset(ds, shards=["shard_000001"])  # committed by an earlier run
    with ds.staging("shard_000002") as st:  # two frames staged by an interrupted run
        for key in st.expected_keys[:2]:
            st.write_frame(key, *ff.pixels(key), ff.frame_json(key))
    be = FakeBackend()
    res = render_plan(out, pdir, be, shards_per_worker=2, quiet=True)
    assert be.jobs[0].batches == (Batch(0, ("shard_000000", "shard_000002")),)
    assert (be.jobs[0].dataset, be.jobs[0].plan_dir, be.jobs[0].retries) == (out, pdir, 0)
    assert (res["frames"], res["frames_before"], res["frames_rendered"]) == (12, 4 + 2, 4 + 2)
    assert (res["frames_committed"], res["shards_committed"], res["shards"]) == (12, 3, 3)
    assert res["render_seconds"] == pytest.approx(6 * 0.25) and res["worker_starts"] == 1
    again = render_plan(out, pdir, be, shards_per_worker=2, quiet=True)
    assert len(be.jobs) == 1  # nothing left: nothing submitted
    assert (again["frames_before"], again["frames_rendered"], again["frames_committed"]) == (12, 0, 12)


def test_done_is_read_from_the_dataset_not_from_events(planned):
    out, pdir = planned
    be = FakeBackend(lie=True)
    with pytest.raises(Incomplete, match="3 shard.s. not committed") as ei:
        render_plan(out, pdir, be, shards_per_worker=1, quiet=True)
    assert ei.value.exit_code == 1  # never 0 unless every shard is committed
    # each round reads what is pending from the files: the work is handed out again, a few times
    assert len(be.jobs) == MAX_ROUNDS and all(j.batches == be.jobs[0].batches for j in be.jobs)
    with pytest.raises(Incomplete):
        render_plan(out, pdir, be, shards_per_worker=1, quiet=True)
    assert be.jobs[MAX_ROUNDS].batches == be.jobs[0].batches  # so the next run does it all again


def test_a_retried_batch_that_then_succeeds_is_no_failure(planned):
    out, pdir = planned
    res = render_plan(out, pdir, FakeBackend(returncodes=(1, 0)), shards_per_worker=3, quiet=True)
    assert res["frames_committed"] == 12 and res["worker_starts"] == 2


def test_a_failed_batch_fails_the_run_with_one_line(planned, capsys):
    out, pdir = planned
    be = FakeBackend(returncodes=(1, -9))
    with pytest.raises(WorkerFailed) as ei:
        render_plan(out, pdir, be, shards_per_worker=2, quiet=True)
    assert ei.value.exit_code == 3 and len(be.jobs) == 1  # failed shards are not handed out again
    msg = str(ei.value)
    assert "\n" not in msg
    assert msg.startswith("3 shard(s) failed after their retries; first: worker for shard_000000,shard_000001 "
                          "exited with code -9 (render); see the worker log")
    err = capsys.readouterr().err.splitlines()  # quiet: one line for the two workers that failed alike
    assert err == ["synth render: shard_000000, shard_000001, shard_000002: worker exited with code -9: "
                   "log of batch 0 (2 workers alike)"]


def test_interrupt_cancels_the_run(planned):
    out, pdir = planned
    be = FakeBackend(interrupt=True)
    with pytest.raises(KeyboardInterrupt):
        render_plan(out, pdir, be, shards_per_worker=1, quiet=True)
    assert be.cancelled


def test_prepare_plan_reuses_the_same_plan_and_refuses_another(planned, toy):
    out, pdir = planned
    before = {p: p.stat().st_mtime_ns for p in sorted(pdir.rglob("*"))}
    assert prepare_plan(out, 3, None, SETS, 7, toy) == pdir
    with pytest.raises(SynthError, match="different plan"):
        prepare_plan(out, 3, None, SETS, 8, toy)
    with pytest.raises(SynthError, match="different plan"):
        prepare_plan(out, 2, None, SETS, 7, toy)
    assert {p: p.stat().st_mtime_ns for p in sorted(pdir.rglob("*"))} == before
    assert sorted(os.listdir(out)) == ["plan"]  # no .plan-check leftovers


def test_out_of_disk_space_is_exit_4_with_the_workers_line(planned, capsys):
    out, pdir = planned
    line = "out of disk space writing /x/y.exr (0.0 MiB left on /x); free some space and rerun"
    with pytest.raises(DiskFull) as ei:
        render_plan(out, pdir, FakeBackend(returncodes=(EXIT_DISK_FULL,), error=line), shards_per_worker=3,
                    quiet=True)
    assert ei.value.exit_code == 4 and str(ei.value) == line


def test_a_reported_input_error_is_exit_2(planned):
    out, pdir = planned
    with pytest.raises(SynthError) as ei:
        render_plan(out, pdir, FakeBackend(returncodes=(EXIT_INPUT,), error="HDR environment file not found (x)"),
                    shards_per_worker=3, quiet=True)
    assert ei.value.exit_code == 2 and str(ei.value) == "HDR environment file not found (x)"


@contextmanager
def held(planned, shard: str, seconds: int):
    """``shard``'s lease held by a live process on this host (a ``sleep``) for ``seconds``."""
    out, pdir = planned
    plan = load_plan(pdir)
    open_dataset(out, plan.plan_hash, plan.expected())
    proc = subprocess.Popen(["sleep", str(seconds)])
    try:
        h = Holder(host=platform.node(), boot_id=_boot_id(), pid=proc.pid, start=process_start(proc.pid), token="x",
                   heartbeat=time.time(), ttl=60.0)
        lease_path(out, shard).write_text(json.dumps(asdict(h)))
        yield proc
    finally:
        proc.kill()
        proc.wait()


def test_a_shard_held_by_a_live_process_is_waited_for_then_rendered(planned):
    out, pdir = planned
    text = io.StringIO()
    be = FakeBackend()
    with held(planned, "shard_000001", 3) as holder:
        res = render_plan(out, pdir, be, shards_per_worker=3, poll_s=0.1,
                          progress=Progress(0, 0, "lines", every=3600, out=text))
    assert [j.batches for j in be.jobs] == [(Batch(0, ("shard_000000", "shard_000002")),),
                                            (Batch(0, ("shard_000001",)),)]
    assert f"waiting for 1 shard(s) held by other processes: shard_000001 ({platform.node()} pid {holder.pid})" \
        in text.getvalue()
    assert res["frames_committed"] == 12


def test_no_wait_reports_the_held_shards_and_exits_1(planned):
    out, pdir = planned
    with held(planned, "shard_000002", 60) as holder:
        with pytest.raises(Incomplete, match=f"1 shard.s. are being rendered by other processes: shard_000002 "
                                             f".{platform.node()} pid {holder.pid}.") as ei:
            render_plan(out, pdir, FakeBackend(), shards_per_worker=3, quiet=True, wait=False)
    assert ei.value.exit_code == 1
    plan = load_plan(pdir)
    assert open_dataset(out, plan.plan_hash, plan.expected()).summary()["shards_committed"] == 2


def test_progress_lines_and_json_log(planned, tmp_path):
    out, pdir = planned
    text = io.StringIO()
    log = tmp_path / "events.jsonl"
    render_plan(out, pdir, FakeBackend(returncodes=(1, 0)), shards_per_worker=3,
                progress=Progress(0, 0, "lines", every=0.0, json_log=log, out=text, workers=2))
    lines = text.getvalue().splitlines()
    assert lines[0].startswith("synth render: 1/12 frames (8.3%), ") and lines[0].endswith(", 0 failures, 2 workers")
    assert lines[-1].startswith("synth render: 12/12 frames (100.0%)")
    recs = [json.loads(x) for x in log.read_text().splitlines()]
    kinds = [r["event"] for r in recs]
    assert kinds.count("frame") == 12 and kinds.count("commit") == 3 and kinds[-1] == "summary"
    ends = [r for r in recs if r["event"] == "batch_end"]
    assert [(e["returncode"], e["retry"]) for e in ends] == [(1, True), (0, False)]
    assert all("time" in r for r in recs) and recs[-1]["frames_committed"] == 12


def test_an_error_event_from_a_batch_that_finished_still_fails_the_run(planned):
    out, pdir = planned
    with pytest.raises(WorkerFailed, match="a worker reported an error: shard_000000,shard_000001,shard_000002: "
                                           "unreadable worker event") as ei:
        render_plan(out, pdir, FakeBackend(error="unreadable worker event: protocol version 9"), shards_per_worker=3,
                    quiet=True)
    assert ei.value.exit_code == 3
