"""EXR frame write/read speed and size against compression (synthetic head-like frames).

Run: .venv/bin/python benchmarks/exr_io.py  (prints a markdown table; docs/frame-format.md holds one)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from synth.dataset.exr import read_frame_exr, write_frame_exr


def fake_frame(size: int, seed: int = 0, noise: float = 0.03):
    """A sphere 'head' on an empty background with render-like Monte Carlo noise."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:size, 0:size]
    x = (u + 0.5) / size * 2 - 1
    y = (v + 0.5) / size * 2 - 1
    r2 = x * x + y * y
    inside = r2 < 0.6**2
    z = np.sqrt(np.clip(0.6**2 - r2, 0, None)) / 0.6
    n = np.stack([x / 0.6, -y / 0.6, z], -1) * inside[..., None]
    shade = np.clip(0.2 + 0.8 * (n @ np.array([0.3, 0.5, 0.8])), 0, None)
    albedo = np.array([0.8, 0.55, 0.45])
    rgb = shade[..., None] * albedo * (1 + noise * rng.standard_normal((size, size, 3)))
    rgba = np.concatenate([rgb * inside[..., None], inside[..., None].astype(float)], -1)
    depth = np.where(inside, 1.0 - 0.1 * z, np.inf)
    seg = np.where(inside, np.where(y < -0.3, 5, 1), 0)
    return rgba.astype(np.float32), depth.astype(np.float32), n.astype(np.float32), seg.astype(np.uint32)


def bench(size: int, compression: str, reps: int = 10) -> tuple[float, float, int]:
    frame = fake_frame(size)
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.exr"
        t0 = time.perf_counter()
        for _ in range(reps):
            nbytes = write_frame_exr(p, *frame, {"synthFrameKey": "id000000_ex00_v00"}, compression=compression,
                                     durable=False)
        tw = (time.perf_counter() - t0) / reps
        t0 = time.perf_counter()
        for _ in range(reps):
            read_frame_exr(p)
        tr = (time.perf_counter() - t0) / reps
    return tw, tr, nbytes


def main() -> None:
    sizes = [int(a) for a in sys.argv[1:]] or [256, 512]
    print("| size | compression | write ms | read ms | bytes | bytes/pixel |")
    print("|---|---|---|---|---|---|")
    for size in sizes:
        for comp in ("ZIP", "PIZ", "ZIPS", "NO"):
            tw, tr, nb = bench(size, comp)
            print(f"| {size}² | {comp} | {tw * 1e3:.1f} | {tr * 1e3:.1f} | {nb} | {nb / size / size:.2f} |")


if __name__ == "__main__":
    main()
