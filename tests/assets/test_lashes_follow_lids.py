"""Eyelashes follow the eyelid rig (synth.model.eyelids): built on the open, level-gaze head of an
identity (as the worker builds assets on its first expression), the lashes' roots stay on the
posed lid margins when the gaze pitches by +-15 degrees and the lids blink (eyeBlink 0 / 1), each
on the lid it was grown on. The roots are barycentric on margin edges
(synth.assets.fit.eyelashes), so they follow any motion of the margin vertices; the test fails if
the attachment read the build-time head instead of the posed one (the margins move by
millimetres: checked below). No Blender needed: the Curves object takes exactly these points
(blender_scripts.assets.strands.StrandRig.update)."""

from __future__ import annotations

import numpy as np
import pytest

from synth.assets.fit.eyelashes import groom
from synth.assets.fit.groom import attach
from synth.conventions import gaze_axis_angle
from synth.model.lid_metrics import _point_polyline_distance
from tests.support import asset_scene
from tests.support.surface_distance import closest_points, head_distance

LIDS = tuple((side, lid) for side in "lr" for lid in ("upper", "lower"))
#: the roots are interpolated on margin edges: they lie on the margin polyline to rounding
MAX_ROOT_OFF_M = 1e-9
#: no lash point (roots excepted) deeper than this inside an eyeball
MAX_EYE_DEPTH_M = 1e-4


def _posed(hm, beta, pitch_deg: float, blink: float) -> np.ndarray:
    d = hm.data
    psi = np.zeros(d.expression_dims)
    for n in ("eyeBlinkLeft", "eyeBlinkRight"):
        psi[list(d.expression_names).index(n)] = blink
    rot = np.zeros((hm.J, 3))
    rot[hm.joint_index["eye_l"]] = rot[hm.joint_index["eye_r"]] = gaze_axis_angle(0.0, pitch_deg)
    return hm.vertices(beta, psi, rot)[0].astype(np.float64)


def _margin_distances(data, V: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(n, 4) distance of points P to each lid margin polyline (LIDS order): the margin vertices
    chained in the template's x order (a posed closed lid can reorder them in x near a corner)."""
    out = []
    for side, lid in LIDS:
        vid = np.asarray(data.regions[f"eyelid_{side}_{lid}"], np.int64)
        out.append(_point_polyline_distance(P, V[vid[np.argsort(data.template[vid, 0])]]))
    return np.stack(out, 1)


def _winding(P: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Generalised winding number of points P (n, 3) in a closed triangle mesh tri (m, 3, 3), the
    sum of the triangles' solid angles (Van Oosterom and Strackee 1983) over 4 pi: +-1 inside
    (the sign is the winding's), 0 outside. Independent of the rigs' signed distances."""
    a, b, c = (tri[None, :, k] - P[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    det = np.einsum("nmd,nmd->nm", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("nmd,nmd->nm", a, b) * lc + np.einsum("nmd,nmd->nm", a, c) * lb
           + np.einsum("nmd,nmd->nm", b, c) * la)
    return 2.0 * np.arctan2(det, den).sum(1) / (4.0 * np.pi)


def _eye_depth(data, V: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(n,) how deep each point lies inside either eyeball (0 outside): winding number for inside,
    trimesh's closest point on every eye triangle (brute force, in mm) for the depth."""
    T = np.asarray(data.triangles, np.int64)
    depth = np.zeros(len(P))
    for side in "lr":
        eye = np.zeros(len(V), bool)
        eye[data.regions[f"eye_{side}"]] = True
        tri = V[T[eye[T].all(1)]]
        inside = np.flatnonzero(np.abs(_winding(P, tri)) > 0.5)
        for i in inside:
            q = closest_points(tri, np.repeat(P[i][None], len(tri), 0))
            depth[i] = np.linalg.norm(q - P[i], axis=1).min()
    return depth


@pytest.fixture(scope="module")
def hm(default_model):
    from synth.model.head import HeadModel

    return HeadModel(default_model, np.float64)


@pytest.mark.parametrize("case", ["neutral", "id+3_jaw", "id-3_jaw"])
@pytest.mark.parametrize("sid", ["natural", "mascara"])
def test_lash_roots_stay_on_the_posed_lid_margin(hm, case, sid):
    ctx = asset_scene.head_arrays(hm, case, resolution=64)
    beta = asset_scene._codes(hm, case)[0]
    ctx.vertices = _posed(hm, beta, 0.0, 0.0)
    pts, att = attach(groom(ctx, {"id": sid, "params": {}}))
    lid0 = _margin_distances(hm.data, ctx.vertices, pts[:, 0]).argmin(1)
    assert set(lid0.tolist()) == set(range(len(LIDS)))  # lashes on all four lids
    upper_l = hm.data.regions["eyelid_l_upper"]
    for pitch in (-15.0, 15.0):
        for blink in (0.0, 1.0):
            V = _posed(hm, beta, pitch, blink)
            moved = np.linalg.norm(V[upper_l] - ctx.vertices[upper_l], axis=1).max()
            assert moved > 1e-3  # the margin really moved (so a root left behind would show)
            posed = type(ctx)(**{**ctx.__dict__, "vertices": V})
            root = att.positions(posed)[:, 0]
            D = _margin_distances(hm.data, V, root)
            off = D[np.arange(len(root)), lid0]
            assert off.max() < MAX_ROOT_OFF_M, (pitch, blink, off.max())
            assert np.array_equal(D.argmin(1), lid0)
            # the build-time roots are off the posed margin: what a frozen attachment would give
            stale = _margin_distances(hm.data, V, pts[:, 0])[np.arange(len(root)), lid0]
            assert stale.max() > 0.5e-3


@pytest.mark.parametrize("case", ["neutral", "id+3_jaw", "id-3_jaw"])
@pytest.mark.parametrize("sid", ["natural", "mascara"])
def test_lashes_stay_out_of_the_eyeballs(hm, case, sid):
    """Built on the open, level-gaze head and posed with the lids (gaze pitch 0 / +-15 degrees,
    eyeBlink 0 / 1): no lash point but the root more than 0.1 mm inside an eyeball. Before the
    keep-out (synth.assets.fit.strands.KeepOut) 3-10 lashes of 112-128 were up to 0.8 mm inside
    at -3 SD in every pose (the fast nearest-vertex push-out read a vertex across the thin lid
    fold and pushed them through it), and blinking put up to 5 mm of a lash turned with its
    margin triangle into the eye (+3 SD natural, -3 SD)."""
    ctx = asset_scene.head_arrays(hm, case, resolution=64)
    beta = asset_scene._codes(hm, case)[0]
    ctx.vertices = _posed(hm, beta, 0.0, 0.0)
    g = groom(ctx, {"id": sid, "params": {}})
    pts, att = attach(g)
    depth = _eye_depth(hm.data, ctx.vertices, pts[:, 1:].reshape(-1, 3))
    assert depth.max() <= MAX_EYE_DEPTH_M, ("built", depth.max())
    worst = {}
    for pitch in (0.0, -15.0, 15.0):
        for blink in (0.0, 1.0):
            V = _posed(hm, beta, pitch, blink)
            P = att.positions(type(ctx)(**{**ctx.__dict__, "vertices": V}))
            assert np.all(np.isfinite(P))
            worst[pitch, blink] = _eye_depth(hm.data, V, P[:, 1:].reshape(-1, 3)).max()
    print(case, sid, {k: round(v * 1e3, 3) for k, v in worst.items()})
    assert max(worst.values()) <= MAX_EYE_DEPTH_M, worst


#: no lash point (roots excepted) deeper than this inside the head's skin (the lids)
MAX_SKIN_DEPTH_M = 2e-4


@pytest.mark.parametrize("case", ["neutral", "id+3_jaw", "id-3_jaw"])
@pytest.mark.parametrize("sid", ["natural", "mascara"])
def test_lashes_stay_out_of_the_lids_when_blinking(hm, case, sid):
    """Built on the open, level-gaze head and posed with eyeBlink 1: no lash point but the root
    more than 0.2 mm inside the head (exact distance to every exterior triangle, sign by the
    thin-fold tie rule: tests.support.surface_distance). Before the skin joined the keep-out
    (KeepOut.bend) the closing lid carried its lashes rigidly into the opposite lid and behind
    it: 3-32 points of 560-640, 1.5-3.3 mm deep."""
    ctx = asset_scene.head_arrays(hm, case, resolution=64)
    beta = asset_scene._codes(hm, case)[0]
    ctx.vertices = _posed(hm, beta, 0.0, 0.0)
    _, att = attach(groom(ctx, {"id": sid, "params": {}}))
    posed = type(ctx)(**{**ctx.__dict__, "vertices": _posed(hm, beta, 0.0, 1.0)})
    P = att.positions(posed)
    _, sd = head_distance(posed, P[:, 1:].reshape(-1, 3), exact=True)
    assert -sd.min() <= MAX_SKIN_DEPTH_M, (int((sd < -MAX_SKIN_DEPTH_M).sum()), -sd.min())
    assert np.array_equal(P, att.positions(posed))  # deterministic
