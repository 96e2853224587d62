"""Load ``benchmarks/realism.py`` (a script, not a package) as a module for the benchmark tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def realism_module():
    """benchmarks/realism.py as a fresh module (its own imports from benchmarks/ resolved)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        spec = importlib.util.spec_from_file_location("realism_bench", ROOT / "benchmarks" / "realism.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
