"""The worker's side of its own life: stop promptly when told, die with whoever started it.

Used by every render worker (``blender_scripts/worker.py``; the stand-in in the tests too),
whichever backend started it:

- :func:`install` blocks SIGTERM, SIGINT and SIGHUP in the calling (main) thread, so in every
  thread started after it (Blender's render threads too), and waits for them in one thread of
  its own (``sigwait``). When one arrives that thread releases every shard lease the process
  holds, writes one line to stderr and ends the process with ``os._exit(128 + signal)``.
  Nothing runs inside Blender's render call or its exit path (a ``sys.exit`` from a signal
  handler there deadlocks Blender), and a busy Cycles does not delay it: Cycles renders
  without holding Python's GIL. (A child process would inherit the blocked mask: start one
  with ``preexec_fn=unblock_signals``.) Frames already staged are complete files (atomic renames);
  the frame in flight is redone on resume.
- The kernel sends SIGTERM when the process that started the worker dies
  (``prctl(PR_SET_PDEATHSIG)``, Linux), and the worker checks the parent PID the backend put in
  ``SYNTH_PARENT_PID`` at start (a parent that died before the prctl) and on every heartbeat,
  so a worker never outlives its controller holding a shard.
- :func:`heartbeat` refreshes the leases and emits a ``heartbeat`` event every few seconds,
  also mid-render: a backend's watchdog stops a worker that stopped answering.
- :func:`finish` flushes and leaves with ``os._exit``: Blender's own exit path can hang
  (a condition variable destroyed while its thread still waits on it).
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
from collections.abc import Callable

from renderer_jobs.events import Heartbeat, emit

#: Environment variable holding the PID of the process that started the worker.
PARENT_ENV = "SYNTH_PARENT_PID"
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
_PR_SET_PDEATHSIG = 1


def set_parent_death_signal(sig: int = signal.SIGTERM) -> bool:
    """Ask the kernel to send ``sig`` when our parent dies (Linux only; False elsewhere)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def parent_gone() -> bool:
    """Whether the process named in SYNTH_PARENT_PID is no longer our parent."""
    want = os.environ.get(PARENT_ENV, "")
    return want.isdigit() and os.getppid() != int(want)


def stop_now(signum: int, why: str) -> None:
    """Release every lease, say why on stderr, and end the process at once (128 + signum)."""
    from synth.dataset.lease import release_all

    try:
        release_all()
    finally:
        try:
            sys.stderr.write(f"synth worker: stopped ({why}); shard claims released, staged frames kept\n")
            sys.stderr.flush()
            sys.stdout.flush()
        except (OSError, ValueError):
            pass
        os._exit(128 + int(signum))


def unblock_signals() -> None:
    """For ``subprocess.Popen(preexec_fn=...)``: a child of the worker would inherit the
    blocked stop signals (the mask survives ``exec``); this gives it the default mask."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)


def install() -> threading.Thread:
    """Block the stop signals here (and in threads started later) and handle them in a thread
    of their own; then arm the parent-death signal and check the parent is still there."""
    signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)

    def wait_for_signal():
        sig = signal.sigwait(STOP_SIGNALS)
        stop_now(sig, signal.Signals(sig).name)

    t = threading.Thread(target=wait_for_signal, name="stop-signals", daemon=True)
    t.start()
    set_parent_death_signal(signal.SIGTERM)
    if parent_gone():
        stop_now(signal.SIGTERM, "the process that started it is gone")
    return t


def heartbeat(interval: float, shards: Callable[[], tuple[str, ...]] = lambda: ()):
    """Refresh held leases and emit a ``heartbeat`` event every ``interval`` seconds; stop the
    worker if its parent is gone. Returns the :class:`synth.dataset.lease.Heartbeat`."""
    from synth.dataset.lease import Heartbeat as LeaseHeartbeat

    def beat(_leases):
        if parent_gone():
            stop_now(signal.SIGTERM, "the process that started it is gone")
        emit(Heartbeat(shards=tuple(shards())))

    return LeaseHeartbeat(interval, on_beat=beat)


def finish(returncode: int) -> None:
    """Flush stdout/stderr and end the process with ``returncode`` (skipping interpreter and
    Blender shutdown)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(int(returncode))
