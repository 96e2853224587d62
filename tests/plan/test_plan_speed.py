"""What made planning fast, checked without timing anything: the slow optional imports stay
out of a plan, the extreme-vertex search is cached per model (in memory and on disk) with the
same result, frame keys are made in bulk as one by one, and the benchmark script runs."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from synth.dataset.layout import frame_key, frame_keys
from synth.plan import identities

ROOT = Path(__file__).resolve().parents[2]


def test_a_plan_imports_no_colour_science_scipy_stats_or_matplotlib(tmp_path):
    code = ("import sys; from synth.cli.main import main; rc = main(['plan', '-n', '1', '--out', sys.argv[1], '-q']);"
            "print(sorted(m for m in ('colour', 'scipy.stats', 'matplotlib') if m in sys.modules), rc)")
    p = subprocess.run([sys.executable, "-c", code, str(tmp_path / "p")], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == "[] 0"


def test_extreme_vertices_cached_per_model(default_model, tmp_path, monkeypatch):
    monkeypatch.setenv("SYNTH_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(identities, "_extremes_memo", {})
    want = identities._extreme_vertices(default_model)
    got = identities.extreme_vertices(default_model, "abc")
    files = list((tmp_path / "plan-extremes").iterdir())
    assert np.array_equal(got, want) and [f.name for f in files] == ["abc-v1.npy"]
    identities._extremes_memo.clear()
    assert np.array_equal(identities.extreme_vertices(default_model, "abc"), want)  # read back from disk
    files[0].write_bytes(b"not an npy file")  # a damaged cache is searched again and rewritten
    identities._extremes_memo.clear()
    assert np.array_equal(identities.extreme_vertices(default_model, "abc"), want)
    assert np.array_equal(np.load(files[0]), want)
    codes = np.random.default_rng(1).normal(size=(3, default_model.identity_dims))
    a = identities.head_spheres(default_model, codes, 0.01)
    b = identities.head_spheres(default_model, codes, 0.01, want)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


def test_frame_keys_in_bulk():
    assert frame_keys(42, 7, 13) == [frame_key(42, 7, v) for v in range(13)]
    assert frame_keys(0, 0, 0) == []


def test_the_benchmark_prints_its_table():
    p = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "plan_speed.py"), "--runs", "1", "--large", "2"],
                       capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT,
                       timeout=600)
    assert p.returncode == 0, p.stderr
    assert "slow optional imports loaded: none" in p.stdout
    assert p.stdout.count("\n| ") == 4  # the header and three cases
