"""benchmarks/photo_orbit.py's tiny profile end to end: a real photo (scikit-image's astronaut)
through the render, a prior, two fits, the orbit and the figure; a second run redoes nothing."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bpy")
pytest.importorskip("mediapipe")
pytest.importorskip("skimage")

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import photo_orbit  # noqa: E402


@pytest.mark.slow
def test_the_tiny_profile_runs_end_to_end_and_resumes(tmp_path):
    from PIL import Image

    work, fig = tmp_path / "w", tmp_path / "fig.png"
    assert photo_orbit.main(["all", "--work", str(work), "--profile", "tiny", "--figure", str(fig)]) in (0, None)
    res = json.loads((work / "results.json").read_text())
    prof = photo_orbit.PROFILES["tiny"]
    assert sorted(res["rows"]) == sorted(name for name, *_ in prof["fits"])
    for name, row in res["rows"].items():
        assert np.isfinite(row["psnr"]) and 0.0 <= row["ssim"] <= 1.0 and 0.0 <= row["lpips"] <= 1.5
        assert row["face_pixels"] > 0 and row["landmarks"]["source"] == "mediapipe"
        views = sorted((work / "fits" / name / "views").glob("orbit*_colour.png"))
        assert len(views) == photo_orbit.ORBIT
        with Image.open(views[0]) as im:
            assert im.size == (prof["size"], prof["size"])
    with Image.open(fig) as im:
        assert im.size[0] > 0 and im.size[1] > 0
    times = json.loads((work / "times.json").read_text())
    stamps = {p: p.stat().st_mtime_ns for p in (work / "fits").rglob("*") if p.is_file()}
    assert photo_orbit.main(["all", "--work", str(work), "--profile", "tiny"]) in (0, None)
    assert {p: p.stat().st_mtime_ns for p in (work / "fits").rglob("*") if p.is_file()} == stamps  # nothing redone
    assert json.loads((work / "results.json").read_text())["rows"] == res["rows"]
    assert set(times) <= set(json.loads((work / "times.json").read_text()))
