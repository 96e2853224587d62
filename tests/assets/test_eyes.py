"""Eye geometry the iris shader relies on (``synth.assets.fit.eyes``) on the default head at
+-3 SD: anatomical iris size, and an eye frame that turns with the planned gaze. The rendered
gaze is tested in tests/blender/test_gaze.py."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.fit.eyes import eye_coordinates, eye_frames
from synth.conventions import gaze_axis_angle
from tests.support import asset_scene

#: visible iris (limbus) diameter, metres: adults 11-12 mm (horizontal visible iris diameter,
#: mean ~11.7 mm)
IRIS_DIAMETER = (0.011, 0.012)


@pytest.mark.parametrize("case", ["neutral", "id+3_jaw", "id-3_jaw"])
def test_iris_diameter_is_anatomical(default_head, case):
    ctx = asset_scene.head_arrays(default_head, case)
    fr = eye_frames(ctx.data, ctx.rest_vertices)
    _, info = eye_coordinates(ctx.data, ctx.rest_vertices)
    for side in "lr":
        eye = np.asarray(ctx.data.regions[f"eye_{side}"])
        r_lim, h, _ = fr["eye_plane"][eye[0]]
        assert IRIS_DIAMETER[0] <= 2 * r_lim <= IRIS_DIAMETER[1], (case, side, 2 * r_lim)
        # the same limbus as the iris coordinates' (rho = 1), measured independently: the widest
        # iris-region vertex from the optical axis
        c, f = np.asarray(info[side]["centre"]), np.asarray(info[side]["forward"])
        q = ctx.rest_vertices[np.asarray(ctx.data.regions[f"iris_{side}"])] - c
        lateral = np.linalg.norm(q - np.outer(q @ f, f), axis=1).max()
        assert abs(lateral - r_lim) < 2e-4
        assert 0 < h < np.linalg.norm(q, axis=1).max()  # the iris plane lies behind the corneal apex


@pytest.mark.parametrize("yaw,pitch", [(0.0, 0.0), (20.0, 0.0), (-15.0, 10.0), (10.0, -12.0)])
def test_eye_frame_turns_with_the_gaze(default_head, yaw, pitch):
    hm = default_head
    rot = np.zeros((hm.J, 3))
    rot[hm.joint_index["eye_l"]] = gaze_axis_angle(yaw, pitch)
    rot[hm.joint_index["eye_r"]] = gaze_axis_angle(yaw, pitch)
    beta = np.zeros(hm.data.identity_dims)
    V = hm.evaluate(beta, np.zeros(hm.data.expression_dims), rot, landmarks=False).vertices[0].astype(np.float64)
    fr = eye_frames(hm.data, V)
    y, p = np.radians(yaw), np.radians(pitch)
    want = np.array([np.sin(y) * np.cos(p), -np.cos(y) * np.cos(p), np.sin(p)])  # docs/conventions: +yaw to +X, +pitch up
    for side in "lr":
        i = int(np.asarray(hm.data.regions[f"eye_{side}"])[0])
        f, u, w = fr["eye_fwd"][i], fr["eye_u"][i], fr["eye_w"][i]
        assert np.degrees(np.arccos(np.clip(f @ want, -1, 1))) < 0.5, side
        assert abs(f @ u) < 1e-9 and abs(f @ w) < 1e-9 and abs(u @ w) < 1e-9
        assert np.allclose([np.linalg.norm(u), np.linalg.norm(w)], 1.0)
    off = np.ones(len(V), bool)
    off[np.concatenate([hm.data.regions["eye_l"], hm.data.regions["eye_r"]])] = False
    assert not fr["eye_plane"][off].any()


def test_lid_margin_is_the_lid_edge_per_sector(default_head):
    from synth.assets.fit.eyes import MARGIN_SECTORS, lid_margin

    hm = default_head
    ctx = asset_scene.head_arrays(hm, "id+3_jaw")
    V = ctx.vertices
    m = lid_margin(hm.data, V)
    fr = eye_frames(hm.data, V)
    for side in "lr":
        lid = np.asarray(hm.data.regions[f"eyelid_{side}_lower"])
        assert m[lid].sum() >= 6 and set(np.nonzero(m)[0]) <= set(np.concatenate(
            [hm.data.regions["eyelid_l_lower"], hm.data.regions["eyelid_r_lower"]]).tolist())
        i0 = int(np.asarray(hm.data.regions[f"eye_{side}"])[0])
        c, f, u, w = (fr[k][i0] for k in ("eye_centre", "eye_fwd", "eye_u", "eye_w"))
        # brute force: per sector the lid vertex at the smallest angle from the axis
        for k in range(MARGIN_SECTORS):
            best, best_t = None, np.inf
            for i in lid:
                q = (V[i] - c) / np.linalg.norm(V[i] - c)
                phi = np.arctan2(q @ w, q @ (u if side == "l" else -u))
                if int(np.floor((phi + np.pi) / (2 * np.pi) * MARGIN_SECTORS)) == k and np.arccos(q @ f) < best_t:
                    best, best_t = i, np.arccos(q @ f)
            if best is not None:
                assert m[best] == 1.0


@pytest.mark.parametrize("case", ["neutral", "id+3_jaw", "id-3_jaw"])
def test_caruncle_centre_is_each_eyes_medial_canthus_and_stays_when_the_eye_turns(default_head, case):
    """``eye_canthus`` (the caruncle's centre in the iris shader) is, on each eye's vertices,
    that eye's ibug68 inner corner (39 / 42) projected from the eye's centre onto the eyeball
    (the canthus itself stands up to 3 mm in front of it), medial of the eye's centre; it does
    not turn with the gaze, and off the eyes it is zero."""
    from synth.assets.fit.eyes import medial_canthi
    from synth.model.meshutil import barycentric_points

    hm = default_head
    ctx = asset_scene.head_arrays(hm, case)
    V = ctx.vertices
    can = medial_canthi(hm.data, V)
    fr = eye_frames(hm.data, V)
    tri, bary = hm.data.landmarks["ibug68"]
    lm = barycentric_points(V, hm.data.triangles, tri, bary)
    for side, k in (("r", 39), ("l", 42)):
        eye = np.asarray(hm.data.regions[f"eye_{side}"])
        c = fr["eye_centre"][eye[0]]
        assert np.allclose(can[eye], can[eye[0]]), (case, side)
        q, p = can[eye[0]] - c, lm[k] - c
        assert np.dot(q, p) / np.linalg.norm(q) / np.linalg.norm(p) > 1 - 1e-12, (case, side)  # on its ray
        assert abs(lm[k][0]) < abs(c[0]) - 0.005, (case, side)  # medial, by over 5 mm
        R = np.linalg.norm(V[np.asarray(hm.data.regions[f"sclera_{side}"])] - c, axis=1).mean()
        assert abs(np.linalg.norm(q) - R) < 1e-9, (case, side)
        assert -0.05e-3 < np.linalg.norm(p) - R < 3.2e-3, (case, side)  # the canthus: on it or in front
    off = np.ones(len(V), bool)
    off[np.concatenate([hm.data.regions["eye_l"], hm.data.regions["eye_r"]])] = False
    assert not can[off].any()
    # turned 20 degrees sideways, the eyeball moves under a canthus that stays put
    beta, psi, rot = asset_scene._codes(hm, case)
    rot[hm.joint_index["eye_l"]] = rot[hm.joint_index["eye_r"]] = gaze_axis_angle(20.0, 0.0)
    Vt = hm.evaluate(beta, psi, rot, landmarks=False).vertices[0].astype(np.float64)
    eye = np.asarray(hm.data.regions["eye_l"])
    assert np.linalg.norm(medial_canthi(hm.data, Vt)[eye[0]] - can[eye[0]]) < 2e-4
    assert np.abs(Vt[eye] - V[eye]).max() > 0.003


def test_no_caruncle_without_ibug68_landmarks(default_head):
    from dataclasses import replace

    from synth.assets.fit.eyes import medial_canthi

    data = replace(default_head.data, landmarks={})
    assert not medial_canthi(data, default_head.data.template).any()
