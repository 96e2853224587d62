"""Installed without an extra: a command that needs it stops before planning or starting a
worker, with one line naming the extra and the Python it needs, exit 2, nothing written.

Each case runs ``synth`` in a subprocess whose meta path refuses the extra's modules, as a
fresh ``pip install synth-faces`` without extras would."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from synth.extras import importable, require
from synth.errors import SynthError

ROOT = Path(__file__).resolve().parents[2]

_BLOCK = """
import sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {blocked!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None
sys.meta_path.insert(0, _Block())
from synth.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def _synth_without(blocked: set[str], *argv, cwd: Path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", _BLOCK.format(blocked=sorted(blocked)), *map(str, argv)],
                          capture_output=True, text=True, env=env, cwd=cwd, timeout=120)


@pytest.mark.parametrize("blocked,argv,needle", [
    ({"bpy"}, ["render", "-n", "1", "-e", "1", "-v", "2", "--preset", "ci", "--out", "ds"], "'render' extra"),
    ({"bpy"}, ["render", "--plan", "noplan", "--out", "ds"], "'render' extra"),
    ({"ray"}, ["render", "-n", "1", "--backend", "ray", "--ray-address", "h:1", "--out", "ds"], "'farm' extra"),
    ({"submitit"}, ["render", "-n", "1", "--backend", "slurm", "--out", "ds"], "'farm' extra"),
    ({"torch"}, ["prior", "train", "ds", "--out", "run"], "'prior' extra"),
])
def test_missing_extra_is_one_line_exit_2_nothing_written(tmp_path, blocked, argv, needle):
    r = _synth_without(blocked, *argv, cwd=tmp_path)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and needle in lines[0], lines
    assert f"Python {sys.version_info.major}.{sys.version_info.minor}" in lines[0]
    assert "pip install 'synth-faces[" in lines[0] and sorted(blocked)[0] in lines[0]
    assert r.stdout == ""
    assert list(tmp_path.iterdir()) == []  # no plan, index, logs or shard folders


def test_commands_that_need_no_extra_run_without_them(tmp_path):
    """``synth plan`` and ``synth assets validate`` are pure Python: no bpy, torch or ray needed."""
    r = _synth_without({"bpy", "torch", "ray", "submitit"}, "plan", "-n", "1", "--out", "p", "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = _synth_without({"bpy", "torch"}, "assets", "validate", cwd=tmp_path)
    assert r.returncode == 0, r.stderr


def test_require_names_the_python_the_extra_needs(monkeypatch):
    monkeypatch.setitem(sys.modules, "bpy", None)  # import fails as if not installed
    assert not importable("bpy")
    assert importable("json")
    monkeypatch.setattr(sys, "version_info", (3, 12, 0))
    with pytest.raises(SynthError) as e:
        require("render", ("bpy",), "synth render")
    msg = str(e.value)
    assert "\n" not in msg and "Python 3.12" in msg and "use Python 3.11" in msg and "synth-faces[render]" in msg
