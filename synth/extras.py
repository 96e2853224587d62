"""The optional extras (pyproject.toml ``[project.optional-dependencies]``) and the check that
a command's extra is installed, made before the command plans, starts a worker or writes
anything (README, "Install").

A plain ``pip install synth-faces`` plans, reads, validates and exports; rendering needs the
``render`` extra (``bpy``, whose 4.5 wheels exist for Python 3.11 only), the prior the
``prior`` extra (``torch``), the ray and slurm backends the ``farm`` extra. :func:`require`
looks the modules up with :func:`importlib.util.find_spec`, which finds a module without
importing it (``import bpy`` alone takes seconds), and raises one :class:`SynthError` line
that names the extra and the Python it needs (exit 2).
"""

from __future__ import annotations

import importlib.util
import sys
from dataclasses import dataclass

from synth.errors import SynthError


@dataclass(frozen=True)
class Extra:
    name: str
    python: tuple[str, ...]  # the minor versions ("3.11") the extra's wheels exist for


#: The extras a command can need, with the Python versions their wheels exist for.
EXTRAS = {
    "render": Extra("render", ("3.11",)),  # bpy 4.5
    "prior": Extra("prior", ("3.11", "3.12")),  # torch, safetensors
    "farm": Extra("farm", ("3.11", "3.12")),  # ray, submitit
    "export": Extra("export", ("3.11", "3.12")),  # usd-core, webdataset
}


#: The distribution that installs a module, where their names differ.
PACKAGES = {"pxr": "usd-core"}


def importable(module: str) -> bool:
    """Whether ``module`` can be imported here, found without importing it. A module that is
    blocked (``sys.modules[name] = None``) or whose finder raises counts as missing."""
    if module in sys.modules:
        return sys.modules[module] is not None
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def require(extra: str, modules: tuple[str, ...], where: str) -> None:
    """Raise the one-line :class:`SynthError` (exit 2) unless every module in ``modules`` is
    importable: it names the missing module, the extra that installs it and the Python that
    extra needs (and says so when this Python is not one of them)."""
    missing = [m for m in modules if not importable(m)]
    if not missing:
        return
    ex = EXTRAS[extra]
    here = "%d.%d" % tuple(sys.version_info[:2])
    needs = " or ".join(f"Python {v}" for v in ex.python)
    fix = f"install the {extra} extra: pip install 'synth-faces[{extra}]' (needs {needs})"
    if here not in ex.python:
        fix = f"use {needs} (this is Python {here}), then " + fix.replace(f" (needs {needs})", "")
    names = ", ".join(PACKAGES.get(m, m) for m in missing)
    raise SynthError(f"{where} needs {names} (the '{extra}' extra), which is not installed for this Python {here}",
                     sys.executable, fix)
