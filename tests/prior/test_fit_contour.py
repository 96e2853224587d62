"""Jaw landmarks on the face's visible outline (prior.fit.contour)."""

from __future__ import annotations

import numpy as np
import pytest

from prior.fit.contour import IBUG68_CONTOUR, contour_lines, visible_contour
from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
from synth.geometry.raycast import first_hits
from synth.model.head import HeadModel
from synth.model.meshutil import barycentric_points


@pytest.fixture(scope="module")
def lines(default_model):
    return contour_lines(default_model)


@pytest.fixture(scope="module")
def posed(default_model):
    hm = HeadModel(default_model, np.float64)
    ev = hm.evaluate(np.zeros(default_model.identity_dims), np.zeros(default_model.expression_dims))
    return ev.vertices[0], ev.landmarks["ibug68"][0]


def _camera(azimuth_deg, centre):
    K = intrinsics(512, 512, 20.0)
    w2c = invert_rigid(orbit_camera_to_world(azimuth_deg, 0.0, 1.2, centre))
    return K, w2c


def _moved(default_model, lines, posed, azimuth_deg):
    V, lm = posed
    K, w2c = _camera(azimuth_deg, lm[:17].mean(0))
    q = project(K, w2c, lm[:17])[0]
    return q, visible_contour(lines, default_model.triangles, V, q, lambda X: project(K, w2c, X)[0]), (K, w2c)


def test_lines_start_at_their_landmarks_and_mirror(default_model, lines):
    V = np.asarray(default_model.template, np.float64)
    T = np.asarray(default_model.triangles, np.int64)
    tri, bary = default_model.landmarks["ibug68"]
    fixed = barycentric_points(V, T, np.asarray(tri), np.asarray(bary, np.float64))[list(IBUG68_CONTOUR)]
    assert lines.tri.shape[0] == 17 and np.all(lines.count > 20)
    at = barycentric_points(V, T, lines.tri[np.arange(17), lines.fixed], lines.bary[np.arange(17), lines.fixed])
    assert np.linalg.norm(at - fixed, axis=1).max() < 1e-3
    inner = barycentric_points(V, T, lines.tri[:, 0], lines.bary[:, 0])  # towards the face's front
    assert np.all(inner[:, 1] < fixed[:, 1])  # the model looks along -y
    np.testing.assert_allclose(inner * [-1, 1, 1], inner[::-1], atol=1e-3)  # the template is symmetric


def test_a_frontal_view_keeps_the_fixed_contour(default_model, lines, posed):
    q, moved, _ = _moved(default_model, lines, posed, 0.0)
    assert np.abs(moved - q).max() < 0.5


def test_a_turned_head_moves_the_hidden_side_out_to_the_outline(default_model, lines, posed):
    """Turned 50 degrees: the far side's jaw points (0-6 seen from the subject's left) are hidden
    behind the face and move out across the contour by tens of pixels; the near side stays; the
    other turn mirrors it; a tiny turn moves nothing by a jump."""
    V, lm = posed
    q, moved, (K, w2c) = _moved(default_model, lines, posed, 50.0)
    shift = np.linalg.norm(moved - q, axis=1)
    centre = invert_rigid(w2c)[:3, 3]
    _, _, t = first_hits(np.repeat(centre[None], 17, 0), lm[:17] - centre, V, default_model.triangles)
    hidden = t < 1.0 - 1e-3  # something nearer than the landmark on its camera ray
    assert hidden[:7].all() and not hidden[9:].any(), hidden
    assert shift[:7].min() > 20.0 and shift[8:].max() < 0.5, shift
    _, mirrored, _ = _moved(default_model, lines, posed, -50.0)
    np.testing.assert_allclose(np.linalg.norm(mirrored - project(*_camera(-50.0, lm[:17].mean(0)), lm[:17])[0],
                                              axis=1)[::-1], shift, atol=0.5)
    _, nudged, _ = _moved(default_model, lines, posed, 50.01)
    assert np.abs(nudged - moved).max() < 0.2


def test_an_edge_on_contour_is_left_as_it_is(default_model, lines, posed):
    V, _ = posed
    q = np.stack([np.linspace(10, 50, 17), np.full(17, 30.0)], 1)
    np.testing.assert_array_equal(visible_contour(lines, default_model.triangles, V, q, lambda X: X[:, :2] * 0), q)
