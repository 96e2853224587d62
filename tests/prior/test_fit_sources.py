"""prior.fit.landmark_sources: frame JSON landmarks (noise, sigma, visibility) and the mediapipe extra."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: fake_frames

import fake_frames as ff  # noqa: E402
from prior.fit.landmark_sources import (  # noqa: E402
    MEDIAPIPE_VERSION, frame_observations, load_correspondence, read_frames, require_mediapipe)
from synth.dataset.shards import open_dataset  # noqa: E402
from synth.errors import SynthError  # noqa: E402

pytest.importorskip("OpenEXR")


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds") / "d"
    ds = open_dataset(root, "f" * 64, ff.plan(n_shards=1, n_expr=1, n_views=3))
    ff.render_dataset(ds, size=32)
    paths = sorted((root / "shards" / "shard_000000").glob("*.exr"))  # .exr or .json both work
    return read_frames(paths)


def test_json_landmarks_exact_and_noisy(frames):
    obs = frame_observations(frames)
    for f, m in zip(frames, obs.mean):
        np.testing.assert_array_equal(m, np.asarray(f.meta["landmarks_2d"]))
    assert obs.K is None  # the frame's camera is for evaluation only
    assert np.all(obs.sigma == 1.0) and obs.width[0] == 32
    noisy = frame_observations(frames, noise_px=2.0, seed=5)
    again = frame_observations(frames, noise_px=2.0, seed=5)
    np.testing.assert_array_equal(noisy.mean, again.mean)  # seeded by (seed, frame indices)
    assert not np.array_equal(frame_observations(frames, noise_px=2.0, seed=6).mean, noisy.mean)
    d = (noisy.mean - obs.mean).reshape(-1)
    assert 1.6 < d.std() < 2.4 and abs(d.mean()) < 0.4
    assert np.all(noisy.sigma == 2.0)  # sigma is at least the noise
    assert frame_observations(frames, known_intrinsics=True).K.shape == (3, 3, 3)


def test_hidden_landmarks(frames):
    f = frames[0]
    vis = np.ones(68, bool)
    vis[:17] = False  # the jaw line hidden
    f.meta["landmarks_visible"] = vis.tolist()
    try:
        obs = frame_observations(frames)
        assert np.all(np.isinf(obs.sigma[0, :17])) and not obs.used[0, :17].any() and obs.used[0, 17:].all()
        assert np.all(frame_observations(frames, hidden_sigma_px=5.0).sigma[0, :17] == 5.0)
    finally:
        f.meta["landmarks_visible"] = [True] * 68


def test_bad_frames(frames):
    with pytest.raises(SynthError, match="no frames"):
        frame_observations([])
    f = frames[1]
    lm = f.meta.pop("landmarks_2d")
    try:
        with pytest.raises(SynthError, match="has no 'landmarks_2d'"):
            frame_observations(frames)
    finally:
        f.meta["landmarks_2d"] = lm
    with pytest.raises(SynthError, match="frame file not found"):
        read_frames(["/nonexistent/id000000_ex00_v00.exr"])


def test_mediapipe_missing_is_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "mediapipe", None)  # import fails as if not installed
    with pytest.raises(SynthError) as e:
        require_mediapipe()
    msg = str(e.value)
    assert "\n" not in msg and "not installed" in msg and f"pip install 'synth[fit]'" in msg
    assert MEDIAPIPE_VERSION in msg


def test_correspondence_only_for_its_model():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from toy_model import make_toy_model

    with pytest.raises(SynthError, match="no mediapipe landmark correspondence"):
        load_correspondence(make_toy_model())
