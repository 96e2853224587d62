"""A stand-in for blender_scripts.worker that needs no bpy: it speaks the worker protocol
(renderer_jobs.events) and misbehaves on request, for the local backend's tests.

    python tests/support/fake_worker.py --dataset DIR --plan PLAN --shards a,b

``DIR/behaviour.json`` maps a shard id to what the worker does with it:

- ``ok`` (default): bpy-like noise on stdout, two ``frame`` events and a ``commit``;
- ``crash``: a line on stderr, exit 1; ``crash_once``: the same the first time only
  (``DIR/<shard>.crashed`` marks it), then ``ok``;
- ``error``: an ``error`` event and exit 2, as the real worker does on a SynthError;
- ``disk_full``: a frame, then the real worker's stderr and ``error`` event on a full disk
  (``out of disk space writing DIR/.staging/<shard>/...``), exit 4;
- ``bad_event``: a line of another protocol version, then ``ok``;
- ``hang``: start a ``sleep`` child in the same process group (its pid in
  ``DIR/<shard>.child``), then wait for a signal; ``stubborn``: the same, ignoring SIGTERM;
- ``wait``: write its pid to ``DIR/<shard>.pid`` and wait for a signal (no child);
- ``silent_once``: the first time, say nothing and wait (a stalled worker), then ``ok``;
- ``env``: write the ``CUDA_VISIBLE_DEVICES`` it got to ``DIR/<shard>.env``, then ``ok``.

Like the real worker it runs ``renderer_jobs.guard`` (signals stop it at once, it dies with
its parent), except for ``stubborn``, which ignores SIGTERM.
"""

from __future__ import annotations

import json
import os
import platform
import signal
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from renderer_jobs import guard  # noqa: E402
from renderer_jobs.events import Commit, Error, Frame, Start, emit  # noqa: E402
from tests.support.dataset_worker import parse_args  # noqa: E402



def _publish(path: Path, text: str) -> None:
    """Write ``text`` under a temporary name and rename it into place, so a test that waits for the
    file never reads it empty."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def main() -> int:
    args = parse_args()
    root = Path(args.dataset)
    shards = args.shards.split(",")
    what = json.loads((root / "behaviour.json").read_text())
    if "stubborn" in {what.get(s) for s in shards}:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    else:
        guard.install()
    emit(Start(shards=tuple(shards), pid=os.getpid(), host=platform.node()))
    for shard in shards:
        b = what.get(shard, "ok")
        if b in ("crash_once", "silent_once"):
            marker = root / f"{shard}.{b}"
            b = "ok" if marker.exists() else b.removesuffix("_once")
            marker.touch()
        if b == "env":
            (root / f"{shard}.env").write_text(os.environ.get("CUDA_VISIBLE_DEVICES", "(unset)"))
        if b in ("wait", "silent"):
            _publish(root / f"{shard}.pid", str(os.getpid()))
            while True:
                time.sleep(1)
        if b == "crash":
            print(f"Traceback: boom in {shard}", file=sys.stderr, flush=True)
            return 1
        if b == "error":
            emit(Error(shard=args.shards, message=f"bad input for {shard}"))
            print(f"synth worker: error: bad input for {shard}", file=sys.stderr, flush=True)
            return 2
        if b == "disk_full":
            emit(Frame(shard=shard, key=f"{shard}_v0", render_seconds=0.5))
            msg = (f"out of disk space writing {root}/.staging/{shard}/{shard}_v1.exr (0.0 MiB left on {root}); "
                   "free some space (or choose another --out) and rerun the same command to resume")
            print(f"worker: {shard}: 1 frames in 0.5 s", file=sys.stderr, flush=True)
            emit(Error(shard=args.shards, message=msg))
            print(f"synth worker: error: {msg}", file=sys.stderr, flush=True)
            return 4
        if b in ("hang", "stubborn"):
            child = subprocess.Popen(["sleep", "600"], preexec_fn=guard.unblock_signals)
            _publish(root / f"{shard}.child", str(child.pid))
            while True:
                time.sleep(1)
        if b == "bad_event":
            print('{"v": 99, "event": "frame"}', flush=True)
        print("Fra:1 Mem:10.00M (Peak 12.00M) | Sample 1/4", flush=True)
        for v in range(2):
            emit(Frame(shard=shard, key=f"{shard}_v{v}", render_seconds=0.5))
        print(f"worker: {shard}: 2 frames", file=sys.stderr, flush=True)
        emit(Commit(shard=shard))
    return 0


if __name__ == "__main__":
    sys.exit(main())
