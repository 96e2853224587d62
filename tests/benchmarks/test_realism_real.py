"""benchmarks/realism_real.py: the face square, the cut at one face scale, and the sheet."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import realism_real as rr  # noqa: E402


def test_the_square_is_centred_between_eyes_and_chin_and_scales_with_the_eyes():
    cx, cy, side = rr.face_square(((40.0, 50.0), (100.0, 50.0)), (70.0, 130.0), 3.0)
    assert (cx, cy, side) == (70.0, 90.0, 180.0)
    _, _, half = rr.face_square(((40.0, 50.0), (70.0, 50.0)), (55.0, 90.0), 3.0)
    assert half == 90.0


def test_the_cut_keeps_what_is_inside_and_fills_grey_past_the_edges():
    img = np.zeros((100, 200, 3), np.float32)
    img[:, 100:] = 1.0  # right half white
    t = rr.cut(img, (100.0, 50.0, 100.0), 50)  # centred on the edge between the halves
    assert t.shape == (50, 50, 3)
    assert t[:, :20].max() < 0.02 and t[:, 30:].min() > 0.98
    t = rr.cut(img, (190.0, 50.0, 40.0), 40)  # half of it past the right edge: grey there
    assert np.allclose(t[:, 32:], rr.GREY, atol=0.01) and t[:, :8].min() > 0.98


def test_rendered_frames_become_tiles_of_one_size(tmp_path):
    from tests.support.datasets import model_dataset

    ds, _ = model_dataset(tmp_path / "ds", identities=1, expressions=1, views=2, size=32)
    tiles = rr.render_tiles(ds, 3.0, 48)
    assert len(tiles) == 2 and all(t.shape == (48, 48, 3) and 0 <= t.min() and t.max() <= 1 for _, t in tiles)
    img = rr.sheet([tiles, tiles[:1]], 48)
    assert img.size == (2 * 48, 2 * (48 + 16))


def test_the_astronaut_is_cut_around_her_face():
    pytest.importorskip("mediapipe")
    name, t = rr.astronaut_tile(3.0, 64)
    assert name == "astronaut" and t.shape == (64, 64, 3)
    centre = t[24:40, 24:40].mean(axis=(0, 1))  # skin: redder than blue, not the grey of a miss
    assert centre[0] > centre[2] + 0.1
