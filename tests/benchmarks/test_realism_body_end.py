"""`benchmarks/realism.py body-end`: which frames show the body ending inside the image."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _realism():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        spec = importlib.util.spec_from_file_location("realism_bench", ROOT / "benchmarks" / "realism.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))


def test_body_ends_in_frame():
    r = _realism()
    seg = np.zeros((8, 8), np.uint32)
    assert not r.body_ends_in_frame(seg)  # no body at all: not counted
    seg[2:5, 3:5] = 9  # a garment floating in the frame
    assert r.body_ends_in_frame(seg)
    seg[5:, 3:5] = 1  # the neck's skin reaching the bottom row
    assert not r.body_ends_in_frame(seg)
    seg[5:, 3:5] = 5  # hair reaching it does not count as the body
    assert r.body_ends_in_frame(seg)
