"""Shard claims that work across hosts: lease files (docs/farm.md, "Shared storage").

A process rendering a shard holds ``.staging/<shard>.lease``: a small JSON file naming its
host, boot id, PID, process start time, a random token and the time of its last heartbeat.

- **Taking** a lease is one atomic create: the content is written to a temp file first and
  hard-linked to the lease name, which fails if the name exists (``link(2)`` is atomic on
  local file systems and on NFS, where ``O_EXCL`` long was not), so a lease file is never seen
  half-written and two processes never both take one.
- **Holding** it means refreshing the heartbeat (:func:`start_heartbeat` runs a thread that
  does so every ``ttl / 4`` seconds for every lease this process holds).
- **Breaking** it is allowed only when the holder is certainly gone: on the same host (same
  host name and boot id) when its PID no longer runs the process that took the lease (checked
  with the process start time, so a reused PID does not count); on another host only when the
  heartbeat is older than the lease's ``ttl``. Clocks of hosts sharing a dataset must agree
  to well within ``ttl`` (NTP). A breaker renames the lease aside (one ``rename(2)``, so only
  one breaker wins) and checks that it moved the stale lease it saw, putting back a fresh one
  it moved by mistake.

Leases decide who works on a shard; they never decide what is done. The committed shard
(``shards/<id>``, made by one atomic rename) stays the single source of truth, and because a
frame's bytes depend only on the plan, two processes that both rendered a shard after a
wrongly broken lease would write the same bytes; the second commit is refused.
"""

from __future__ import annotations

import json
import os
import platform
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

from synth.dataset.layout import MAX_LEASE_BYTES
from synth.io import FileRefused, loads_json, read_bounded

#: Seconds without a heartbeat after which a lease held on another host may be broken
#: (``SYNTH_LEASE_SECONDS`` overrides it; every host sharing a dataset should use the same).
DEFAULT_TTL_S = float(os.environ.get("SYNTH_LEASE_SECONDS", "") or 120.0)
LEASE_SUFFIX = ".lease"


def _boot_id() -> str:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return ""


def process_start(pid: int) -> str:
    """An identifier of the process now running as ``pid`` (its start time in clock ticks
    since boot, from /proc), or "" when there is none, it has exited (a zombie) or it cannot
    be read."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return ""
    fields = stat[stat.rfind(")") + 2:].split()  # from field 3 (state) on
    return "" if fields[0] in ("Z", "X") else fields[19]  # field 22: starttime


@dataclass(frozen=True)
class Holder:
    """Who holds a lease, as written in the lease file."""
    host: str
    boot_id: str
    pid: int
    start: str  # process_start(pid) when the lease was taken
    token: str
    heartbeat: float  # wall-clock seconds (time.time()) of the last refresh
    ttl: float

    def describe(self) -> str:
        return f"{self.host} pid {self.pid}"

    def on_this_host(self) -> bool:
        return self.host == platform.node() and self.boot_id == _boot_id()

    def alive(self, now: float | None = None) -> bool:
        """Whether the holder may still be working (so the lease must not be broken)."""
        if self.on_this_host():
            return bool(self.start) and process_start(self.pid) == self.start
        return (time.time() if now is None else now) - self.heartbeat <= self.ttl


def read_holder(path: Path) -> Holder | None:
    """The holder named in a lease file; ``None`` when there is no (readable) lease file.
    A lease file that does not parse (written by something else) counts as held until its
    modification time is older than the default ttl."""
    try:
        mtime = path.lstat().st_mtime
        raw = read_bounded(path, MAX_LEASE_BYTES, follow_symlinks=False)
    except FileNotFoundError:
        return None
    except FileRefused:  # a symlink, a device, a huge file: not ours, treated like garbage
        raw = b""
    try:
        d = loads_json(raw)
        return Holder(host=str(d["host"]), boot_id=str(d["boot_id"]), pid=int(d["pid"]), start=str(d["start"]),
                      token=str(d["token"]), heartbeat=float(d["heartbeat"]), ttl=float(d["ttl"]))
    except (ValueError, KeyError, TypeError, AttributeError):
        return Holder(host="?", boot_id="?", pid=-1, start="", token="", heartbeat=mtime, ttl=DEFAULT_TTL_S)


class LeaseBusy(Exception):
    """The lease is held by a live process (``holder``)."""

    def __init__(self, path: Path, holder: Holder):
        super().__init__(f"{path.name} is held by {holder.describe()}")
        self.path, self.holder = path, holder


def _aside(path: Path, what: str) -> Path:
    return path.with_name(f".{path.name}.{what}.{os.getpid()}.{secrets.token_hex(4)}.tmp")


class Lease:
    """A lease this process holds. Take one with :meth:`acquire`."""

    def __init__(self, path: Path, holder: Holder):
        self.path, self.holder = path, holder

    # -- taking -------------------------------------------------------------------------------
    @classmethod
    def acquire(cls, path: Path, ttl: float = DEFAULT_TTL_S) -> Lease:
        """Take the lease at ``path`` (breaking it only if its holder is gone); raises
        :class:`LeaseBusy` when a live process holds it."""
        path = Path(path)
        pid = os.getpid()
        for _ in range(5):
            holder = Holder(host=platform.node(), boot_id=_boot_id(), pid=pid, start=process_start(pid),
                            token=secrets.token_hex(16), heartbeat=time.time(), ttl=float(ttl))
            tmp = _write_temp(path, holder)
            try:
                os.link(tmp, path)
            except FileExistsError:
                pass
            else:
                lease = cls(path, holder)
                _HELD.add(lease)
                return lease
            finally:
                os.unlink(tmp)
            other = read_holder(path)
            if other is None:
                continue  # released meanwhile
            if other.alive():
                raise LeaseBusy(path, other)
            break_lease(path, other)
        raise LeaseBusy(path, read_holder(path) or Holder("?", "?", -1, "", "", time.time(), ttl))

    # -- holding ------------------------------------------------------------------------------
    def held(self) -> bool:
        """Whether the lease file still names this lease (it was not broken and retaken)."""
        cur = read_holder(self.path)
        return cur is not None and cur.token == self.holder.token

    def refresh(self) -> bool:
        """Write a new heartbeat; ``False`` (and nothing written) when the lease was lost."""
        if not self.held():
            return False
        self.holder = Holder(**{**asdict(self.holder), "heartbeat": time.time()})
        tmp = _write_temp(self.path, self.holder)
        os.replace(tmp, self.path)
        return True

    def release(self) -> None:
        """Give the lease up (only if it is still ours)."""
        _HELD.discard(self)
        try:
            if self.held():
                os.unlink(self.path)
        except FileNotFoundError:
            pass


def _write_temp(path: Path, holder: Holder) -> Path:
    tmp = _aside(path, "new")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    try:
        os.write(fd, json.dumps(asdict(holder), sort_keys=True).encode())
        os.fsync(fd)
    finally:
        os.close(fd)
    return tmp


def break_lease(path: Path, seen: Holder) -> None:
    """Remove the lease ``seen`` (a holder found gone). One rename decides between several
    breakers; a lease taken by someone else in between is put back."""
    aside = _aside(path, "broken")
    try:
        os.rename(path, aside)
    except FileNotFoundError:
        return
    moved = read_holder(aside)
    if moved is not None and moved.token != seen.token:
        try:
            os.link(aside, path)  # a fresh lease: put it back (unless yet another was taken)
        except FileExistsError:
            pass
    os.unlink(aside)


# -- the leases this process holds, and the heartbeat that keeps them ------------------------

class _Held:
    def __init__(self):
        self._lock = threading.Lock()
        self._leases: set[Lease] = set()

    def add(self, lease: Lease) -> None:
        with self._lock:
            self._leases.add(lease)

    def discard(self, lease: Lease) -> None:
        with self._lock:
            self._leases.discard(lease)

    def all(self) -> list[Lease]:
        with self._lock:
            return list(self._leases)


_HELD = _Held()


def held_leases() -> list[Lease]:
    return _HELD.all()


def release_all() -> None:
    """Release every lease this process holds (a worker that is told to stop)."""
    for lease in _HELD.all():
        try:
            lease.release()
        except OSError:
            pass


class Heartbeat:
    """A daemon thread refreshing every lease this process holds each ``interval`` seconds,
    then calling ``on_beat(leases)``. A lease found lost is dropped from the set. ``stop()``
    ends it."""

    def __init__(self, interval: float, on_beat: Callable[[list[Lease]], None] | None = None):
        self.interval, self.on_beat = interval, on_beat
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="lease-heartbeat", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            leases = _HELD.all()
            for lease in leases:
                try:
                    if not lease.refresh():
                        _HELD.discard(lease)
                except OSError:
                    pass  # shared storage hiccup: try again next beat
            if self.on_beat is not None:
                self.on_beat(leases)

    def stop(self) -> None:
        self._stop.set()
        self.thread.join(timeout=5.0)
