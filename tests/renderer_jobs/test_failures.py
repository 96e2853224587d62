"""Repeated errors (renderer_jobs.failures): workers failing alike print one line per distinct
failure; with -q that and the final error line are all, without -q no message twice."""

from __future__ import annotations

import pytest

from renderer_jobs.failures import Failure, group, report_lines, signature
from renderer_jobs.submit import RunStats, raise_on_failures
from synth.errors import DiskFull, WorkerFailed
from tests.renderer_jobs.test_local_backend import submit

ABANDONED = "(worker log abandoned: No space left on device)"


def _failed_run(tmp_path, behaviour, shards=("shard_000000", "shard_000001", "shard_000002")) -> RunStats:
    """Three real worker processes (the fake worker), one shard each, as `synth render` runs them."""
    tmp_path.mkdir(exist_ok=True)
    stats = RunStats()
    for ev in submit(tmp_path, list(shards), {s: behaviour for s in shards}, workers=3, per_worker=1).wait():
        stats.add(ev)
    return stats


def _printed(stats, quiet, capsys) -> tuple[list[str], Exception]:
    with pytest.raises(Exception) as ei:
        raise_on_failures(stats, quiet=quiet)
    return capsys.readouterr().err.splitlines(), ei.value


def test_full_disk_in_every_worker_quiet_is_two_lines(tmp_path, capsys):
    stats = _failed_run(tmp_path, "disk_full")
    lines, err = _printed(stats, True, capsys)
    assert isinstance(err, DiskFull) and err.exit_code == 4 and "out of disk space writing" in str(err)
    assert lines == ["synth render: 3 shards failed alike: shard_000000, shard_000001, shard_000002"]
    # the final error line is the only one that says "out of disk space"


def test_full_disk_without_quiet_says_nothing_twice(tmp_path, capsys):
    stats = _failed_run(tmp_path, "disk_full")
    lines, err = _printed(stats, False, capsys)
    lines.append(f"synth: error: {err}")  # what main() prints last
    assert sum("out of disk space" in x for x in lines) == 1, lines
    assert len(lines) == len(set(lines))
    for s in ("shard_000000", "shard_000001", "shard_000002"):  # each worker's own context is kept
        assert f"synth render: worker for {s} exited with code 4; its log ends:" in lines
        assert f"  worker: {s}: 1 frames in 0.5 s" in lines


def test_distinct_failures_get_a_line_each(tmp_path, capsys):
    stats = _failed_run(tmp_path / "a", "crash", shards=("a", "b"))
    for ev in submit(tmp_path, ["c"], {"c": "error"}).wait():
        stats.add(ev)
    lines, err = _printed(stats, True, capsys)
    assert str(err) == "bad input for c" and err.exit_code == 2
    assert lines == ["synth render: a: worker exited with code 1: Traceback: boom in a",
                     "synth render: b: worker exited with code 1: Traceback: boom in b"]
    lines, err = _printed(stats, False, capsys)
    assert lines.count("  Traceback: boom in a") == 1 and not any("bad input" in x for x in lines)


def test_signature_and_tails_seen_once():
    a = "out of disk space writing /d/.staging/shard_000001/id000001_ex00_v01.exr (0.3 MiB left on /d); free"
    b = "out of disk space writing /d/.staging/shard_000002/id000002_ex01_v00.exr (1.0 MiB left on /d); free"
    assert signature(a) == signature(b) != signature("HDR environment file not found (/x.exr)")
    fs = [Failure(("shard_000001",), a, 4, ("worker: shard_000001: 6 frames in 10.6 s", f"synth worker: error: {a}",
                                              ABANDONED)),
          Failure(("shard_000002",), b, 4, (f"synth worker: error: {b}", ABANDONED))]
    lines = report_lines(group(fs), a, quiet=False)
    assert lines.count(f"  {ABANDONED}") == 1 and not any("out of disk space" in x for x in lines)
    assert lines[0] == "synth render: 2 shards failed alike: shard_000001, shard_000002"
    assert report_lines(group(fs), a, quiet=True) == lines[:1]
    # a final line of another kind (WorkerFailed's summary): the failure itself is shown once
    only = report_lines(group(fs[:1]), "1 shard(s) failed", quiet=True)
    assert only == [f"synth render: shard_000001: {a}"]
    assert isinstance(WorkerFailed("x"), WorkerFailed)
