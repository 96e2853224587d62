"""The prior's benchmark scripts still run (smoke tests; the figures live in docs/prior.md)."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_gpu_script_dry_run_on_cpu(tmp_path):
    r = subprocess.run(["bash", str(ROOT / "benchmarks" / "prior_gpu.sh"), "--dry"], capture_output=True, text=True,
                       env={**os.environ, "OUT": str(tmp_path)}, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads((tmp_path / "prior_gpu.json").read_text())
    assert res["preset"] == "small" and res["flops_per_step"] > 0 and res["eager_rays_per_s"] > 0
    assert res["max_abs_rgb"] == 0.0  # CPU against itself
    assert "| eager bf16 |" in r.stdout
