"""prior.fit.landmark_sources: frame JSON landmarks (noise, sigma, visibility) and the mediapipe extra."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from prior.fit.landmark_sources import (MEDIAPIPE_VERSION, frame_observations, load_correspondence, read_frames,
                                        require_mediapipe)
from synth.dataset.shards import open_dataset
from synth.errors import SynthError
from tests.support import fake_frames as ff

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
    assert "\n" not in msg and "not installed" in msg and "pip install 'synth-faces[fit]'" in msg
    assert MEDIAPIPE_VERSION in msg


def test_correspondence_only_for_its_model():
    from tests.support.toy_model import make_toy_model

    with pytest.raises(SynthError, match="no mediapipe landmark correspondence"):
        load_correspondence(make_toy_model())


# --------------------------------------------------------------------------- the correspondence


def test_correspondence_checks_the_rest_shape_within_a_tolerance(default_model):
    """The file is named by the model's topology; its rest shape is compared point by point, so that
    the same model built on another CPU (float32 bytes that differ in the last bits) finds it, and a
    model of the same topology whose face has moved by 0.1 mm does not."""
    import dataclasses

    from prior.fit.landmark_sources import CORRESPONDENCE_TOLERANCE_M

    T = np.asarray(default_model.template, np.float64)
    rng = np.random.default_rng(0)
    ulp = dataclasses.replace(default_model, template=(T * (1.0 + rng.uniform(-2e-7, 2e-7, T.shape))).astype(np.float32))
    assert not np.array_equal(ulp.template, default_model.template)
    np.testing.assert_array_equal(load_correspondence(ulp)["triangles"], load_correspondence(default_model)["triangles"])
    moved = T.copy()
    moved[default_model.regions["face"], 1] -= 10 * CORRESPONDENCE_TOLERANCE_M  # the face 0.1 mm forward
    with pytest.raises(SynthError, match="derived on another rest shape") as e:
        load_correspondence(dataclasses.replace(default_model, template=moved.astype(np.float32)))
    assert "\n" not in str(e.value) and "0.100 mm" in str(e.value)


def test_default_correspondence_is_sane(default_model):
    m = default_model
    c = load_correspondence(m)
    idx = c["index"]
    assert len(idx) >= 400 and len(np.unique(idx)) == len(idx) and idx.min() >= 0 and idx.max() < 478
    assert c["triangles"].min() >= 0 and c["triangles"].max() < len(m.triangles)
    np.testing.assert_allclose(c["bary"].sum(1), 1.0, atol=1e-5)
    assert np.all(c["bary"] >= -1e-6) and np.all(c["sigma_face"] > 0)
    # semantics: mediapipe's eye and mouth corners and nose tip land next to the same ibug68 points
    T, tri = np.asarray(m.template, np.float64), np.asarray(m.triangles)
    pos = dict(zip(idx.tolist(), np.einsum("pk,pkc->pc", c["bary"], T[tri[c["triangles"]]])))
    t, b = m.landmarks["ibug68"]
    ib = np.einsum("lk,lkc->lc", b, T[tri[t]])
    for mp_i, ibug in ((33, 36), (263, 45), (133, 39), (362, 42), (61, 48), (291, 54), (1, 30), (152, 8)):
        assert np.linalg.norm(pos[mp_i] - ib[ibug]) < 0.01, (mp_i, ibug)


def test_mediapipe_points_fit_round_trip(default_model):
    """Detections made by projecting the correspondence points of a known scene: the fit
    through the custom landmark set recovers the cameras (no mediapipe needed)."""
    torch = pytest.importorskip("torch")
    from prior.fit.landmark_sources import mediapipe_points_observations
    from prior.fit.landmarks_fit import fit_landmarks
    from prior.fit.camera import relative_pose_errors
    from prior.fit.synthetic import make_scene
    from synth.conventions import project
    from synth.model.head import HeadModel

    torch.set_num_threads(1)
    m = default_model
    hm = HeadModel(m, np.float64)
    c = load_correspondence(m)
    sc = make_scene(m, 7, 1, resolution=512, head=hm)
    V = hm.vertices(sc.identity, sc.expression, sc.joint_rotations)[0].astype(np.float64)
    X = np.einsum("pk,pkc->pc", c["bary"], V[np.asarray(m.triangles)[c["triangles"]]])
    pts = np.zeros((3, 478, 2))
    for v in range(3):
        pts[v, c["index"]] = project(sc.K[v], sc.world_to_camera[v], X)[0]
    # exact "detections": tiny sigmas, so that the landmarks dominate the priors
    obs = mediapipe_points_observations(pts, 512, 512, dict(c, sigma_face=np.full(len(c["index"]), 1e-6)),
                                        min_sigma_px=1e-3)
    assert np.all(obs.sigma == 1e-3)
    obs.K = sc.K
    fit = fit_landmarks(m, obs)
    rot, _ = relative_pose_errors(fit.world_to_camera, sc.world_to_camera)
    assert fit.converged and rot.max() < 0.01 and fit.rmse_px.max() < 0.01
    assert fit.landmarks_2d.shape == (3, len(c["index"]), 2)


def test_mediapipe_on_a_photo(default_model):
    """Needs the fit extra (mediapipe), which scripts/setup.sh installs."""
    pytest.importorskip("mediapipe", reason="the synth-faces[fit] extra (mediapipe) is not installed: make setup")
    skd = pytest.importorskip("skimage.data", reason="scikit-image (test extra) provides the photo")
    from prior.fit.landmark_sources import mediapipe_observations
    from prior.fit.landmarks_fit import fit_landmarks

    photo = skd.astronaut()  # 512 x 512 RGB, one face
    obs, masks, found = mediapipe_observations([photo], default_model)
    assert found == [{"faces": 1, "face_px": found[0]["face_px"]}] and 90 < found[0]["face_px"] < 120
    assert obs.mean.shape[1] == len(load_correspondence(default_model)["index"]) and np.all(np.isfinite(obs.sigma))
    assert masks[0].shape == photo.shape[:2] and 0.05 < float(masks[0].mean()) < 0.95
    fit = fit_landmarks(default_model, obs)
    assert fit.converged and fit.rmse_px.max() < 10.0
    with pytest.raises(SynthError, match="no face found"):
        mediapipe_observations([np.zeros((64, 64, 3), np.uint8)], default_model)


def test_default_correspondence_is_left_right_consistent(default_model):
    """Each point mirrored (x -> -x) on the template is its mediapipe partner's point: a point and
    its partner are derived together (scripts/mediapipe_correspondence.py), so they are mirror
    images up to the fold of a quad split the other way (the correspondence before, each point
    chosen on its own: 0.8 mm median, 8.8 mm at most), and the 28 points that are their own
    partner lie on the midline."""
    import json

    from prior.fit.landmark_sources import CORRESPONDENCE_DIR, model_key

    m = default_model
    doc = json.loads((CORRESPONDENCE_DIR / f"mediapipe-{model_key(m)}.json").read_text())
    assert doc["derivation"]["mirror_symmetric"] is True
    pair = np.asarray(doc["mirror"])
    assert sorted(pair) == list(range(478)) and np.all(pair[pair] == np.arange(478))
    T, tri = np.asarray(m.template, np.float64), np.asarray(m.triangles)
    pos = {q["mediapipe"]: np.einsum("k,kc->c", q["bary"], T[tri[q["triangle"]]]) for q in doc["points"]}
    assert sorted(pos) == list(range(478))
    miss = np.array([np.linalg.norm(pos[i] * (-1.0, 1.0, 1.0) - pos[pair[i]]) for i in range(478)])
    assert miss.max() < 1e-5  # bary rounded to 1e-6 in the file
    midline = np.nonzero(pair == np.arange(478))[0]
    assert len(midline) == 28 and max(abs(pos[i][0]) for i in midline) < 1e-6
    for a, b in ((33, 263), (133, 362), (61, 291), (234, 454)):  # eye and mouth corners, face sides
        assert pair[a] == b
    assert pair[1] == 1 and pair[152] == 152  # nose tip and chin on the midline
