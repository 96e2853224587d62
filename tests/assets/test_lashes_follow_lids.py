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

LIDS = tuple((side, lid) for side in "lr" for lid in ("upper", "lower"))
#: the roots are interpolated on margin edges: they lie on the margin polyline to rounding
MAX_ROOT_OFF_M = 1e-9


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
