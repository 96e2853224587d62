"""Time to stage and commit one shard (default: 13 expressions x 30 views = 390 frames of 64x64).

Run: .venv/bin/python benchmarks/shard_commit.py [SIZE] [DIR] [dir|tar]
(the last argument: the shard format, dataset.shard_format; default dir).
Frames are synthetic (benchmarks/exr_io.py's sphere); frame JSONs are realistic in size.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from synth.dataset.reader import iter_frames  # noqa: E402
from synth.dataset.shards import open_dataset  # noqa: E402
from synth.dataset.validate import validate_dataset  # noqa: E402
from tests.support import fake_frames as ff  # noqa: E402


def main() -> None:
    size = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    base = Path(sys.argv[2]) if len(sys.argv) > 2 and sys.argv[2] else None
    fmt = sys.argv[3] if len(sys.argv) > 3 else "dir"
    plan = ff.plan(1, 13, 30)
    keys = plan["shard_000000"]
    with tempfile.TemporaryDirectory(dir=base) as d:
        root = Path(d) / "ds"
        ds = open_dataset(root, "0" * 64, plan, shard_format=fmt)
        frames = {k: (ff.pixels(k, size), ff.frame_json(k, size)) for k in keys}
        t0 = time.perf_counter()
        with ds.staging("shard_000000") as st:
            for k in keys:
                st.write_frame(k, *frames[k][0], frames[k][1])
            t1 = time.perf_counter()
            st.frames_done()
            t2 = time.perf_counter()
            m = st.commit(manifest_extra={"seeds": {"run": 0}})
            t3 = time.perf_counter()
        rep = validate_dataset(root)
        t4 = time.perf_counter()
        assert rep.ok, [x.line() for x in rep.defects]
        validate_dataset(root, quick=True)
        t5 = time.perf_counter()
        n = sum(1 for _ in iter_frames(root))
        t6 = time.perf_counter()
        assert n == len(keys)
        nbytes = sum(e["bytes"] for e in m["files"].values())
        print(f"| {fmt} | {len(keys)} frames of {size}² | write_frame {1e3 * (t1 - t0) / len(keys):.1f} ms/frame "
              f"| frames_done {1e3 * (t2 - t1):.0f} ms | commit {1e3 * (t3 - t2):.0f} ms "
              f"| validate {t4 - t3:.2f} s (quick {t5 - t4:.2f} s) | read all {t6 - t5:.2f} s | {nbytes / 1e6:.1f} MB |")


if __name__ == "__main__":
    main()
