"""Fitting to the JSON landmarks of real renders (`synth render` at the ci preset, Blender)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("bpy")
torch = pytest.importorskip("torch")

pytestmark = [pytest.mark.blender, pytest.mark.slow]


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    from prior.fit.landmark_sources import read_frames

    out = tmp_path_factory.mktemp("fit") / "ds"
    # one frontal-hemisphere identity: 1 expression, 3 views within +-60 degrees of the front
    cmd = [sys.executable, "-m", "synth.cli.main", "render", "--identities", "1", "--expressions", "1",
           "--views", "3", "--preset", "ci", "--out", str(out), "-q", "--seed", "5",
           "--set", "camera.azimuth_deg=[-60,60]", "--set", "camera.elevation_deg=[-20,20]"]
    p = subprocess.run(cmd, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return read_frames(sorted(out.glob("shards/*/id*.json")))


def test_fit_to_rendered_frames(frames, default_model):
    from prior.fit.camera import relative_pose_errors
    from prior.fit.landmark_sources import frame_observations
    from prior.fit.landmarks_fit import fit_landmarks
    model = default_model
    # the JSON holds exact projections of the model's landmarks: with a tiny sigma they dominate
    # the priors and the truth is recovered (even from 64 px images, where the face is ~20 px)
    obs = frame_observations(frames, sigma_px=1e-3, known_intrinsics=True)
    fit = fit_landmarks(model, obs)
    # the JSON cameras serve for evaluation only; renders keep the head at rest in the model
    # frame, the gauge of a fit with free cameras, so the cameras compare directly
    rot, pos = relative_pose_errors(fit.world_to_camera, np.stack([f.world_to_camera for f in frames]))
    assert fit.converged
    assert rot.max() <= 0.05, rot
    assert pos.max() <= 0.002, pos
    assert fit.rmse_px.max() <= 1e-3, fit.rmse_px
