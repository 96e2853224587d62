"""The eyebrow band rendered (Cycles, 64 x 64, 4 samples, at about the pixel size of ``preview``):
the brow reads as a band as dark as real brows at that size, and wider for a thicker brow. Read
with benchmarks/brow_band.py's own measure. The band's placement, expressions and determinism:
tests/assets/test_eyebrow_band.py."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from tests.blender.test_shaders import _render
from tests.support import asset_scene

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

#: benchmarks/brow_band.py on the five real photos (astronaut, breakingbad, einstein, takeo,
#: lenna), faces at the preview renders' inter-ocular distance: the darkest brow / skin ratio,
#: lowest and highest (docs/realism.md "Eyebrows at the render's resolution")
PHOTO_CONTRAST = (0.11, 0.77)
#: a view of the brows with about preview's pixel (1.7 mm on the face): 0.5 m away, 12.5 degrees
VIEW = dict(radius=0.5, fov_deg=12.5)


def _brows(params: dict, tmp, monkeypatch=None, depth=None):
    from blender_scripts import assets as basset
    from synth.appearance.srgb import linear_to_srgb
    from synth.assets.fit import eyebrows as fe
    from synth.conventions import project

    import brow_band as bb

    if depth is not None:
        monkeypatch.setattr(fe, "BAND_DEPTH", depth)
    ctx, hm = asset_scene.head_context("neutral", resolution=256)
    rigs = basset.dress(ctx, {"eyebrows": {"id": "natural", "params": dict(params)}})
    lm = ctx.landmarks["ibug68"]
    r, K, w2c = _render(ctx, tmp, target=0.5 * (lm[19] + lm[24]) + np.array([0.0, 0.0, -0.012]), **VIEW)
    rgb = r["rgba"][..., :3]
    a = r["rgba"][..., 3:4]
    luma = linear_to_srgb(np.clip(rgb + (1 - a) * 0.18, 0, 1)) @ bb.LUMA
    uv, _ = project(K, w2c, lm)
    iod = float(np.linalg.norm(uv[36] - uv[45]))
    return bb.brow_metrics(luma, uv, iod), rigs["eyebrows"].record(), iod


@pytest.mark.blender
@pytest.mark.slow
def test_the_band_darkens_the_brow_into_the_real_photos_range(tmp_path, monkeypatch):
    pytest.importorskip("bpy")
    params = {"thickness": 0.9, "density": 0.9, "arch": 0.3, "colour": "dark_brown"}
    without, rec0, iod = _brows(params, tmp_path, monkeypatch, depth=0.0)
    assert 30 < iod < 60, iod  # the brows fill the frame at about preview's pixel size
    assert rec0["band"]["drawn"] is False
    monkeypatch.undo()
    with_band, rec, _ = _brows(params, tmp_path)
    assert rec["band"]["drawn"] and rec["band"]["optical_depth"] > 0.5, rec["band"]
    assert with_band["contrast"] < without["contrast"] - 0.1, (with_band, without)
    assert PHOTO_CONTRAST[0] <= with_band["contrast"] <= PHOTO_CONTRAST[1], with_band


@pytest.mark.blender
@pytest.mark.slow
def test_a_thicker_brow_renders_wider(tmp_path):
    pytest.importorskip("bpy")
    widths = [_brows({"thickness": t, "density": 1.0, "arch": 0.3, "colour": "black"}, tmp_path)[0]["width"]
              for t in (0.4, 0.9, 1.6)]
    assert widths[0] < widths[1] < widths[2], widths
