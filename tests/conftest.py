"""Shared fixtures."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def farm_reference(tmp_path_factory):
    """The farm tests' plan (farm_helpers.SMALL) rendered in one go by the local backend: what
    every other backend and every resumed run must reproduce bit for bit."""
    pytest.importorskip("bpy")
    from farm_helpers import SMALL, synth

    out = tmp_path_factory.mktemp("farm_reference") / "ds"
    synth("render", *SMALL, "--out", out, "-q")
    return out
