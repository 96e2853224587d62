"""Plan-or-resume and batching (renderer_jobs.submit) with a fake backend that writes fake
frames through the dataset API: no bpy. What is done is read from the dataset's files."""

from __future__ import annotations

import os

from tests.support import fake_frames as ff
import pytest
from tests.support.toy_model import write_toy_model

from renderer_jobs.backend import Backend, Batch, Job, Run
from renderer_jobs.events import BatchEnd, Commit, Frame
from renderer_jobs.submit import make_batches, prepare_plan, render_plan
from synth.dataset.shards import open_dataset
from synth.errors import SynthError
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
            for attempt, rc in enumerate(b.returncodes):
                yield BatchEnd(batch=batch.index, shards=batch.shards, attempt=attempt, returncode=rc,
                               log_tail=f"log of batch {batch.index}", retry=attempt + 1 < len(b.returncodes))

    def cancel(self):
        self.backend.cancelled = True


class FakeBackend(Backend):
    name = "fake"

    def __init__(self, lie=False, returncodes=(0,), interrupt=False):
        self.lie, self.returncodes, self.interrupt = lie, returncodes, interrupt
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
    assert be.jobs[1].batches == ()
    assert (again["frames_before"], again["frames_rendered"], again["frames_committed"]) == (12, 0, 12)


def test_done_is_read_from_the_dataset_not_from_events(planned):
    out, pdir = planned
    be = FakeBackend(lie=True)
    res = render_plan(out, pdir, be, shards_per_worker=1, quiet=True)
    assert res["frames_rendered"] == 3  # what the events said
    assert (res["frames_committed"], res["shards_committed"]) == (0, 0)  # what the files say
    render_plan(out, pdir, be, shards_per_worker=1, quiet=True)
    assert be.jobs[1].batches == be.jobs[0].batches  # so the next run does it all again


def test_a_retried_batch_that_then_succeeds_is_no_failure(planned):
    out, pdir = planned
    res = render_plan(out, pdir, FakeBackend(returncodes=(1, 0)), shards_per_worker=3, quiet=True)
    assert res["frames_committed"] == 12 and res["worker_starts"] == 2


def test_a_failed_batch_fails_the_run_with_one_line(planned, capsys):
    out, pdir = planned
    with pytest.raises(SynthError) as ei:
        render_plan(out, pdir, FakeBackend(returncodes=(1, -9)), shards_per_worker=2, quiet=True)
    msg = str(ei.value)
    assert "\n" not in msg
    assert msg.startswith("2 worker(s) failed; first: worker for shard_000000,shard_000001 exited with code -9:")
    err = capsys.readouterr().err
    assert "log of batch 0" in err and "worker for shard_000002 exited with code -9" in err


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
