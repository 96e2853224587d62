"""A bpy-free render worker that really fills the dataset: fake frames (tests.support.fake_frames)
written and committed through synth.dataset, with the worker protocol and exit statuses of
blender_scripts.worker. The concurrency tests run it in place of the real worker:

    python tests/support/dataset_worker.py --dataset DIR --plan PLAN --shards a,b

Each frame it renders is appended to the file named by ``$FAKE_LOG`` (one key a line), and
takes ``$FAKE_RENDER_S`` seconds (default 0.05), so that runs overlap.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from renderer_jobs import guard  # noqa: E402
from renderer_jobs.events import EXIT_INPUT, Commit, Error, Frame, Skip, Start, emit  # noqa: E402

WORKER = Path(__file__).resolve()


def command(dataset: Path, plan_dir: Path, shards) -> list[str]:
    """A :data:`renderer_jobs.spawn.WorkerCommand` that runs this worker."""
    return [sys.executable, str(WORKER), "--dataset", str(dataset), "--plan", str(plan_dir), "--shards",
            ",".join(shards)]


def parse_args(argv=None) -> argparse.Namespace:
    """The render worker's arguments that the fake workers take: --dataset, --plan, --shards."""
    ap = argparse.ArgumentParser()
    for name in ("--dataset", "--plan", "--shards"):
        ap.add_argument(name, required=True)
    return ap.parse_args(argv)


def main() -> int:
    from synth.dataset.shards import open_dataset
    from synth.errors import SynthError
    from synth.plan.io import load_plan
    from tests.support import fake_frames as ff

    args = parse_args()
    guard.install()
    shards = args.shards.split(",")
    emit(Start(shards=tuple(shards), pid=os.getpid(), host=platform.node()))
    sleep = float(os.environ.get("FAKE_RENDER_S", "0.05"))
    log = os.environ.get("FAKE_LOG")
    try:
        plan = load_plan(Path(args.plan))
        ds = open_dataset(Path(args.dataset), plan.plan_hash, plan.expected())
        for sid in shards:
            st = ds.try_staging(sid)
            if st is None:
                emit(Skip(shard=sid))
                continue
            with st:
                def staged(key: str, sid: str = sid) -> None:
                    if log:
                        with open(log, "a") as f:
                            f.write(key + "\n")
                    emit(Frame(shard=sid, key=key, render_seconds=sleep))

                ff.stage_missing(st, sleep, staged)
                st.commit()
            emit(Commit(shard=sid))
    except SynthError as e:
        emit(Error(shard=args.shards, message=str(e)))
        return EXIT_INPUT
    return 0


if __name__ == "__main__":
    sys.exit(main())
