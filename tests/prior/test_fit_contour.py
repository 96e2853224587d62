"""Jaw landmarks on the face's visible outline (prior.fit.contour)."""

from __future__ import annotations

import numpy as np
import pytest

from prior.fit.contour import IBUG68_CONTOUR, annotated_jaw, contour_lines, spaced_evenly, visible_contour
from synth.errors import SynthError
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


def _arc_positions(points, polyline):
    """Arc length along ``polyline`` (P, 2) of each of ``points`` (on it), and their distance off it."""
    seg = np.diff(polyline, axis=0)
    s0 = np.concatenate([[0.0], np.cumsum(np.linalg.norm(seg, axis=1))])
    rel = points[:, None] - polyline[None, :-1]  # (N, P-1, 2)
    t = np.clip(np.einsum("npc,pc->np", rel, seg) / np.maximum((seg * seg).sum(1), 1e-12), 0, 1)
    off = np.linalg.norm(rel - t[..., None] * seg[None], axis=-1)
    k = np.argmin(off, axis=1)
    return s0[k] + t[np.arange(len(points)), k] * np.linalg.norm(seg[k], axis=1), off.min(1)


def test_spaced_evenly_keeps_the_anchors_and_evens_the_arc_length_between_them():
    """17 points on a curve, bunched unevenly: the anchors stay, every point stays on the polyline,
    the points between two anchors sit at equal arc lengths; points spaced evenly on a line stay."""
    u = np.concatenate([0.5 * np.linspace(0, 1, 9) ** 1.7, 0.5 + 0.5 * np.linspace(0, 1, 9)[1:] ** 0.6])
    p = 100.0 * np.stack([np.cos(np.pi * u), np.sin(np.pi * u)], 1)
    out = spaced_evenly(p)
    np.testing.assert_array_equal(out[[0, 8, 16]], p[[0, 8, 16]])
    s, off = _arc_positions(out, p)
    assert off.max() < 1e-9
    np.testing.assert_allclose(np.diff(s[:9]), np.diff(s[:9]).mean(), rtol=1e-9)
    np.testing.assert_allclose(np.diff(s[8:]), np.diff(s[8:]).mean(), rtol=1e-9)
    assert np.abs(out - p).max() > 5.0  # the bunched points did move
    line = np.stack([np.linspace(0, 160, 17), np.linspace(0, 40, 17)], 1)  # evenly spaced already
    np.testing.assert_allclose(spaced_evenly(line), line, atol=1e-9)
    np.testing.assert_array_equal(spaced_evenly(np.zeros((17, 2))), np.zeros((17, 2)))  # degenerate: no NaN
    with pytest.raises(SynthError, match="anchors"):
        spaced_evenly(p, anchors=(0, 8, 15))


def test_the_annotated_jaw_of_a_turned_tilted_head_is_even_along_its_outline(default_model, lines, posed):
    """A projected model head 35 degrees to the side, seen from 15 degrees above: the fixed jaw points,
    moved out to the outline, lie unevenly along it (segments differing by more than 1.4 times); the
    annotated jaw keeps 0, 8 and 16 where visible_contour puts them and spaces the rest evenly
    along the outline; the other turn mirrors it; a 0.01 degree change moves nothing by a jump;
    seen from the front (builder 11's points spaced evenly from the front) it moves under 2 px."""
    V, lm = posed
    T = default_model.triangles

    def jaw(az, el):
        K = intrinsics(512, 512, 20.0)
        w2c = invert_rigid(orbit_camera_to_world(az, el, 1.2, lm[:17].mean(0)))
        f = lambda X: project(K, w2c, X)[0]  # noqa: E731
        q = f(lm[:17])
        return visible_contour(lines, T, V, q, f), annotated_jaw(lines, T, V, q, f)

    across, out = jaw(35.0, 15.0)
    for half in (slice(0, 9), slice(8, 17)):
        d = np.linalg.norm(np.diff(across[half], axis=0), axis=1)
        assert d.max() / d.min() > 1.4, d
    np.testing.assert_array_equal(out[[0, 8, 16]], across[[0, 8, 16]])
    s, off = _arc_positions(out, across)
    assert off.max() < 1e-6
    for half in (slice(0, 9), slice(8, 17)):
        np.testing.assert_allclose(np.diff(s[half]), np.diff(s[half]).mean(), rtol=1e-6)
    _, mirrored = jaw(-35.0, 15.0)
    np.testing.assert_allclose(mirrored[::-1] * [-1, 1] + [512, 0], out, atol=0.5)
    assert np.abs(jaw(35.01, 15.0)[1] - out).max() < 0.2
    front_across, front = jaw(0.0, 0.0)
    assert np.abs(front - front_across).max() < 2.0
