"""Loose hair over the bust (synth.assets.fit.strands.settle, the parting in hair._free):
a child blended from guides that drape over a shoulder on different sides, or that are combed to
opposite sides of a parting, runs through the body; pushed out point by point it folds into hooks,
laid over the body from the root it does not."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from synth.assets.fit.groom import head_frame
from synth.assets.fit.strands import Surface, settle
from tests.support import asset_scene

hair = importlib.import_module("synth.assets.fit.hair")


def _turns(P):
    d = np.diff(P, axis=1)
    d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-15)
    return np.degrees(np.arccos(np.clip((d[:, 1:] * d[:, :-1]).sum(-1), -1.0, 1.0)))


def test_settle_drapes_a_strand_through_the_body_and_keeps_its_length(default_head):
    ctx = asset_scene.head_arrays(default_head, "neutral", 64, 1, 0)
    s = Surface(ctx)
    c = head_frame(ctx)["centre"]
    # straight strands from beside the head down through the shoulder, and one well clear of the body
    z = np.linspace(0.0, -0.35, 29)[None, :, None]
    x = np.array([0.11, 0.13, 0.15, 0.6])[:, None, None]
    P = np.concatenate([c[0] + x + 0 * z, c[1] + 0.0 * x + 0 * z, c[2] + z + 0 * x], -1)
    d0, _ = s.signed_offset(P[:3, 1:])
    assert (d0 < -0.01).any(1).all()  # the first three run through the body
    out = settle(s, P, 0.004)
    d, _ = s.signed_offset(out[:, 1:])
    assert d.min() > 0.004 - 1e-3
    ratio = np.linalg.norm(np.diff(out, axis=1), axis=2) / np.linalg.norm(np.diff(P, axis=1), axis=2)
    assert 0.9 < ratio.min() and ratio.max() < 1.1
    assert np.array_equal(out[:, 0], P[:, 0])
    assert np.array_equal(out[3], P[3])  # clear of the body: untouched
    assert _turns(out[:3]).max() < 100.0  # laid over the shoulder, no fold back


@pytest.mark.parametrize("style,params", [("long_straight", {"length_m": 0.3, "parting": "centre", "curl": 0.0}),
                                          ("long_layered", {}), ("bob", {"parting": "left"})])
def test_loose_hair_lies_over_the_bust_without_hooks(default_head, style, params):
    """Three draws each: no strand point more than 0.5 mm inside the body, and at most 2.5 % of
    the strands turn by more than 120 degrees anywhere past their first joint (where a strand
    leaves the scalp along its normal). Without the settle and the parting split the same
    long_straight draws have 50 points inside and 168 of 5,760 strands (2.9 %) turning so; the
    ears' thin shells are where most of the turns left lie."""
    hooks = n = 0
    for ident in (1, 2, 3):
        ctx = asset_scene.head_arrays(default_head, "neutral", 64, ident, 0)
        s = Surface(ctx)
        g = hair.groom(ctx, {"id": style, "params": params})
        d, _ = s.signed_offset(g.pts[:, 1:])
        assert d.min() > -0.0005
        hooks += int((_turns(g.pts)[:, 1:].max(1) > 120.0).sum())
        n += len(g.pts)
    assert hooks <= 0.025 * n


@pytest.mark.parametrize("parting,offset", [("centre", 0.0), ("left", 0.028)])
def test_children_blend_guides_from_their_side_of_the_parting(default_head, parting, offset):
    """With a parting, every child is blended from guides rooted on one side of it only (a child
    between guides combed to opposite sides took their mean, down through the skull); without
    one, from all guides."""
    seen = []
    real = hair.interpolate

    def spy(surface, g_tri, g_bary, g_pts, c_tri, c_bary, **kw):
        seen.append(surface.points(g_tri, g_bary)[:, 0])
        return real(surface, g_tri, g_bary, g_pts, c_tri, c_bary, **kw)

    ctx = asset_scene.head_arrays(default_head, "neutral", 64, 1, 0)
    xp = head_frame(ctx)["centre"][0] + offset
    hair.interpolate = spy
    try:
        hair.groom(ctx, {"id": "long_straight", "params": {"length_m": 0.3, "parting": parting, "curl": 0.0}})
        assert len(seen) == 2
        assert all(np.all(x >= xp) or np.all(x < xp) for x in seen)
        seen.clear()
        hair.groom(ctx, {"id": "long_straight", "params": {"length_m": 0.3, "parting": "none", "curl": 0.0}})
        assert len(seen) == 1
    finally:
        hair.interpolate = real
