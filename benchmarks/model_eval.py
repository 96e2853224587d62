"""Model evaluation speed against accuracy: meshes per second at batch 1, 64 and 1024, and
the float32 error against a float64 evaluation of the same codes (metres).

    .venv/bin/python benchmarks/model_eval.py [--model PATH]

Prints a table (and a Markdown copy for docs/performance.md with --markdown).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np


def bench(hm, hm64, data, batch: int, posed: bool, min_seconds: float = 1.0) -> tuple[float, float]:
    rng = np.random.Generator(np.random.Philox(key=[batch, int(posed)]))
    beta = rng.standard_normal((batch, data.identity_dims)) * 1.5
    psi = rng.uniform(0, 0.7, size=(batch, data.expression_dims))
    rot = None
    if posed:
        rot = np.zeros((batch, len(data.joint_names), 3))
        rot[:, :, 0] = rng.uniform(-0.3, 0.3, size=(batch, len(data.joint_names)))
    hm.vertices(beta, psi, rot)  # warm-up
    n, t0 = 0, time.perf_counter()
    while True:
        hm.vertices(beta, psi, rot)
        n += 1
        dt = time.perf_counter() - t0
        if dt >= min_seconds and n >= 2:
            break
    rate = n * batch / dt
    k = min(batch, 64)
    err = float(np.abs(hm.vertices(beta[:k], psi[:k], None if rot is None else rot[:k]).astype(np.float64)
                       - hm64.vertices(beta[:k], psi[:k], None if rot is None else rot[:k])).max())
    return rate, err


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None)
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    from rich.console import Console
    from rich.table import Table

    from synth.model.default import resolve_model
    from synth.model.head import HeadModel

    data = resolve_model(args.model)
    hm, hm64 = HeadModel(data, np.float32), HeadModel(data, np.float64)
    rows = []
    for posed in (False, True):
        for batch in (1, 64, 1024):
            rate, err = bench(hm, hm64, data, batch, posed)
            rows.append((batch, "yes" if posed else "no", rate, err))
    t = Table(title=f"{data.name}: {data.num_vertices} vertices, {data.identity_dims} identity + "
                    f"{data.expression_dims} expression dims ({os.cpu_count()} cores, {platform.processor() or platform.machine()})")
    for c in ("batch", "joint rotations", "meshes/s", "max |f32 - f64| (m)"):
        t.add_column(c, justify="right")
    for b, p, r, e in rows:
        t.add_row(str(b), p, f"{r:,.0f}", f"{e:.2e}")
    Console().print(t)
    if args.markdown:
        print("| batch | joint rotations | meshes/s | max abs float32 error (m) |")
        print("|---:|:---:|---:|---:|")
        for b, p, r, e in rows:
            print(f"| {b} | {p} | {r:,.0f} | {e:.2e} |")


if __name__ == "__main__":
    main()
