"""Reader throughput: frames/s and rays/s of synth.dataset.reader, as a training job sees them.

Each sample is one decoded frame (EXR + JSON -> float32 arrays) plus its per-pixel rays
(origins, directions), delivered to the consuming process by a torch DataLoader with W worker
processes (W = 0: in the consuming process itself). The dataset is written once per size with
fake head-like frames (a sphere with 3 % Monte Carlo noise, like benchmarks/exr_io.py), so no
Blender is needed; real renders compress similarly (docs/frame-format.md).

Run: .venv/bin/python benchmarks/reader.py [--sizes 64 256 512] [--workers 0 1 2] [--frames 60]
Prints a markdown table (docs/performance.md holds one).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from exr_io import fake_frame  # noqa: E402

from synth.dataset.reader import list_frames, rays  # noqa: E402
from synth.dataset.shards import open_dataset  # noqa: E402
from tests.support import fake_frames as ff  # noqa: E402


def make_dataset(root: Path, size: int, n_frames: int) -> Path:
    views = 30
    n_shards = max(1, -(-n_frames // views))
    expected = ff.plan(n_shards=n_shards, n_expr=1, n_views=views)
    ds = open_dataset(root, "b" * 64, expected)
    for sid in ds.pending_shards():
        with ds.staging(sid) as st:
            for i, key in enumerate(st.expected_keys):
                st.write_frame(key, *fake_frame(size, seed=i), ff.frame_json(key, size), durable=False)
            st.commit(manifest_extra={"seeds": {}, "versions": {}})
    return root


class _Frames:
    """A torch IterableDataset over frame refs, split across DataLoader workers."""

    def __init__(self, refs):
        self.refs = refs

    def __iter__(self):
        import torch.utils.data as tud

        info = tud.get_worker_info()
        refs = self.refs if info is None else self.refs[info.id::info.num_workers]
        for ref in refs:
            f = ref.read()
            o, d, _ = rays(f)
            yield f.rgba, o, d


def measure(root: Path, workers: int) -> tuple[float, float]:
    import torch.utils.data as tud

    refs = list_frames(root)
    ds = type("FramesDS", (_Frames, tud.IterableDataset), {})(refs)
    loader = tud.DataLoader(ds, batch_size=None, num_workers=workers, persistent_workers=False)
    n = n_rays = 0
    t0 = time.perf_counter()
    for rgba, o, d in loader:
        n += 1
        n_rays += int(np.prod(rgba.shape[:2]))
    dt = time.perf_counter() - t0
    return n / dt, n_rays / dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[64, 256, 512])
    ap.add_argument("--workers", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--frames", type=int, default=60, help="frames per size (rounded up to 30-view shards)")
    args = ap.parse_args(argv)
    print("| size | DataLoader workers | frames/s | Mrays/s |")
    print("|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            root = make_dataset(Path(tmp) / f"d{size}", size, args.frames)
            measure(root, 0)  # warm the page cache
            for w in args.workers:
                fps, rps = measure(root, w)
                print(f"| {size}² | {w} | {fps:,.0f} | {rps / 1e6:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
