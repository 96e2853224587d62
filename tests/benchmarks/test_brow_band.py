"""benchmarks/brow_band.py: a drawn band's contrast and width are read back; shading is not a brow."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import brow_band as bb  # noqa: E402

IOD = 60.0


def _face(depth: float, width_px: float, shading: float = 0.0):
    """A 200 x 200 'face': skin 0.6 with a vertical shading gradient, eye corners 60 px apart at
    y = 120, straight brows at y = 90 darkened by ``depth`` over ``width_px`` (soft 1 px edges)."""
    y, x = np.mgrid[0:200, 0:200] + 0.5
    skin = 0.6 * (1.0 + shading * (y - 100.0) / 100.0)
    d = np.abs(y - 90.0)
    band = np.clip(0.5 * width_px + 0.5 - d, 0.0, 1.0) * ((x > 60) & (x < 140))
    lm = np.full((68, 2), np.nan)
    lm[36], lm[45] = (70.0, 120.0), (130.0, 120.0)
    lm[17:22] = np.stack([np.linspace(62, 96, 5), np.full(5, 90.0)], 1)
    lm[22:27] = np.stack([np.linspace(104, 138, 5), np.full(5, 90.0)], 1)
    return skin * (1.0 - depth * band), lm


@pytest.mark.parametrize("depth,width", [(0.3, 4.0), (0.7, 8.0), (0.5, 2.0)])
def test_a_drawn_band_is_read_back(depth, width):
    luma, lm = _face(depth, width, shading=-0.3)
    m = bb.brow_metrics(luma, lm, IOD)
    assert m["contrast"] == pytest.approx(1.0 - depth, abs=0.03)
    assert m["width"] == pytest.approx(width, abs=1.0)
    assert m["width_iod"] == pytest.approx(m["width"] / IOD)


@pytest.mark.parametrize("shading", [-0.4, 0.4])
def test_shading_alone_is_no_brow(shading):
    luma, lm = _face(0.0, 0.0, shading=shading)
    m = bb.brow_metrics(luma, lm, IOD)
    assert m["contrast"] > 0.98


def test_a_wider_band_reads_wider_at_any_scale():
    for scale in (0.5, 2.0):  # the face shrunk / enlarged to the common inter-ocular distance
        got = []
        for w in (3.0, 6.0, 9.0):
            luma, lm = _face(0.5, w)
            from PIL import Image

            img = Image.fromarray(luma.astype(np.float32), mode="F")
            n = int(200 * scale)
            luma_s = np.asarray(img.resize((n, n), Image.Resampling.BICUBIC), np.float64)
            got.append(bb.brow_metrics(luma_s, lm * scale, IOD)["width"])
        assert got[0] < got[1] < got[2], got
