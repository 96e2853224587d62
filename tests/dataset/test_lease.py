"""Lease files: shard claims that hold across hosts (synth.dataset.lease)."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import platform
import subprocess
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import pytest

from synth.dataset import lease as L


def write_holder(path: Path, h: L.Holder) -> None:
    path.write_text(json.dumps(asdict(h)))


def me(token="t0", **kw) -> L.Holder:
    pid = os.getpid()
    base = L.Holder(host=platform.node(), boot_id=L._boot_id(), pid=pid, start=L.process_start(pid), token=token,
                    heartbeat=time.time(), ttl=60.0)
    return replace(base, **kw)


def test_take_release_and_busy_in_the_same_process(tmp_path):
    p = tmp_path / "s.lease"
    a = L.Lease.acquire(p, ttl=30)
    assert a.held() and L.read_holder(p) == a.holder
    assert a in L.held_leases()
    with pytest.raises(L.LeaseBusy) as e:
        L.Lease.acquire(p)  # our own live PID holds it
    assert str(os.getpid()) in str(e.value)
    a.release()
    assert not p.exists() and a not in L.held_leases()
    b = L.Lease.acquire(p)
    b.release()
    assert sorted(os.listdir(tmp_path)) == []  # no temp files left


def test_lease_of_a_dead_process_on_this_host_is_broken_at_once(tmp_path):
    p = tmp_path / "s.lease"
    code = ("import os, sys; from synth.dataset.lease import Lease; "
            f"Lease.acquire(__import__('pathlib').Path({str(p)!r}), ttl=3600); os._exit(9)")
    subprocess.run([sys.executable, "-c", code], check=False, env={**os.environ, "PYTHONPATH": os.getcwd()})
    dead = L.read_holder(p)
    assert dead is not None and dead.pid != os.getpid() and not dead.alive()
    a = L.Lease.acquire(p)  # no waiting for the hour-long ttl
    assert L.read_holder(p).token == a.holder.token
    a.release()


def test_a_reused_pid_does_not_keep_a_lease(tmp_path):
    p = tmp_path / "s.lease"
    write_holder(p, me(start="1"))  # our PID, but started at another time: another process
    assert not L.read_holder(p).alive()
    L.Lease.acquire(p).release()


def test_other_host_lease_is_broken_only_after_its_ttl(tmp_path):
    p = tmp_path / "s.lease"
    other = me(host="elsewhere", boot_id="b", pid=1, start="5", ttl=60.0)
    write_holder(p, other)
    with pytest.raises(L.LeaseBusy, match="elsewhere pid 1"):
        L.Lease.acquire(p)
    write_holder(p, replace(other, heartbeat=time.time() - 61.0))
    a = L.Lease.acquire(p)
    assert a.holder.host == platform.node()
    a.release()


def test_refresh_moves_the_heartbeat_and_notices_a_lost_lease(tmp_path):
    p = tmp_path / "s.lease"
    a = L.Lease.acquire(p)
    t0 = a.holder.heartbeat
    time.sleep(0.01)
    assert a.refresh() and L.read_holder(p).heartbeat > t0
    write_holder(p, me(token="someone-else"))  # broken and taken by another process
    assert not a.refresh() and not a.held()
    assert L.read_holder(p).token == "someone-else"  # refresh wrote nothing
    a.release()  # not ours: left alone
    assert L.read_holder(p).token == "someone-else"


def test_breaking_puts_back_a_fresh_lease_taken_in_between(tmp_path):
    p = tmp_path / "s.lease"
    stale = me(host="elsewhere", boot_id="b", token="stale", heartbeat=0.0)
    write_holder(p, me(token="fresh"))  # what is there by the time we break
    L.break_lease(p, stale)
    assert L.read_holder(p).token == "fresh"
    write_holder(p, stale)
    L.break_lease(p, stale)
    assert not p.exists()
    assert os.listdir(tmp_path) == []


def test_unreadable_lease_counts_as_held_until_it_is_old(tmp_path):
    p = tmp_path / "s.lease"
    p.write_text("not json")
    with pytest.raises(L.LeaseBusy):
        L.Lease.acquire(p)
    old = time.time() - L.DEFAULT_TTL_S - 5
    os.utime(p, (old, old))
    L.Lease.acquire(p).release()


def _race(path: str, barrier, results) -> None:
    barrier.wait()
    try:
        L.Lease.acquire(Path(path))
        results.put("won")
        time.sleep(1.5)  # hold it while the others try
    except L.LeaseBusy:
        results.put("busy")


def test_one_winner_when_many_break_a_stale_lease_at_once(tmp_path):
    p = tmp_path / "s.lease"
    write_holder(p, me(host="elsewhere", boot_id="b", token="stale", heartbeat=0.0))
    ctx = mp.get_context("fork")
    n = 6
    barrier, results = ctx.Barrier(n), ctx.Queue()
    procs = [ctx.Process(target=_race, args=(str(p), barrier, results)) for _ in range(n)]
    for pr in procs:
        pr.start()
    for pr in procs:
        pr.join(30)
    got = sorted(results.get(timeout=5) for _ in range(n))
    assert got.count("won") == 1, got


def test_heartbeat_thread_refreshes_held_leases(tmp_path):
    p = tmp_path / "s.lease"
    a = L.Lease.acquire(p)
    t0 = a.holder.heartbeat
    beats = []
    hb = L.Heartbeat(0.05, on_beat=beats.append)
    deadline = time.monotonic() + 10
    while not beats and time.monotonic() < deadline:
        time.sleep(0.05)
    hb.stop()
    assert L.read_holder(p).heartbeat > t0 and beats[0] == [a]
    L.release_all()
    assert not p.exists() and L.held_leases() == []
