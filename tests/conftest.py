"""Shared fixtures and collection rules for the whole suite (the only conftest.py).

Layout: the folders mirror the packages (``tests/dataset`` for ``synth/dataset`` ...);
``tests/blender`` holds every test that imports ``bpy``; helpers shared by several folders
live in ``tests/support`` and are imported as ``from tests.support import fake_frames``
(see tests/README.md).
"""

from __future__ import annotations

from pathlib import Path

import pytest

BLENDER_DIR = Path(__file__).parent / "blender"


def pytest_collection_modifyitems(config, items):
    """Every test under tests/blender/ needs bpy: it gets the ``blender`` marker (so ``-m "not
    blender"`` leaves it out) even if its module forgot to say so."""
    for item in items:
        if BLENDER_DIR in Path(str(item.fspath)).parents:
            item.add_marker(pytest.mark.blender)


@pytest.fixture(scope="session")
def default_model():
    """The embedded default head model (the file shipped in the package; docs/default-model.md)."""
    from synth.model.default import load_default_model

    return load_default_model()


@pytest.fixture(scope="session")
def default_head(default_model):
    """A :class:`synth.model.head.HeadModel` of the default model."""
    from synth.model.head import HeadModel

    return HeadModel(default_model)


@pytest.fixture(scope="session")
def farm_reference(tmp_path_factory):
    """The farm tests' plan (farm_helpers.SMALL) rendered in one go by the local backend: what
    every other backend and every resumed run must reproduce bit for bit."""
    pytest.importorskip("bpy")
    from tests.support.farm_helpers import SMALL, synth

    out = tmp_path_factory.mktemp("farm_reference") / "ds"
    synth("render", *SMALL, "--out", out, "-q")
    return out
