"""GPUs on this machine and how local workers share them: one worker per GPU by default,
each pinned to its device with ``CUDA_VISIBLE_DEVICES`` (Cycles then picks OptiX, else CUDA,
on the one device it sees; without GPUs the workers render on the CPU)."""

from __future__ import annotations

import shutil
import subprocess


def visible_gpus(env: dict) -> list[str]:
    """The GPU ids workers may use: those ``CUDA_VISIBLE_DEVICES`` lists when it is set ("" or
    "-1" mean none), else every GPU ``nvidia-smi`` reports (none without the tool)."""
    if "CUDA_VISIBLE_DEVICES" in env:
        ids = [d.strip() for d in env["CUDA_VISIBLE_DEVICES"].split(",") if d.strip()]
        out = []
        for d in ids:
            if d.startswith("-"):  # CUDA stops at the first invalid id
                break
            out.append(d)
        return out
    smi = shutil.which("nvidia-smi", path=env.get("PATH", ""))
    if smi is None:
        return []
    try:
        p = subprocess.run([smi, "--query-gpu=index", "--format=csv,noheader"], capture_output=True, text=True,
                           timeout=20)
    except (OSError, subprocess.TimeoutExpired):
        return []
    if p.returncode != 0:
        return []
    return [line.strip() for line in p.stdout.splitlines() if line.strip().isdigit()]


def worker_slots(workers: int | None, gpus: list[str]) -> list[str | None]:
    """The device of each worker slot: ``workers`` (default: one per GPU, else 1) slots, the
    GPUs dealt round-robin (more workers than GPUs share them); ``None`` = no pinning (CPU)."""
    n = workers if workers is not None else max(1, len(gpus))
    if n < 1:
        raise ValueError("workers must be at least 1")
    if not gpus:
        return [None] * n
    return [gpus[i % len(gpus)] for i in range(n)]
