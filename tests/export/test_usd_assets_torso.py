"""The USD export rebuilds a garment's body below the bust only for renders that built one (their
record has ``torso_vertices``), with the rendered vertex count; older renders get the shell alone.
Renders with arms (``torso_arms``, 2026-12-01) get the prism and the arms, renders before them the
prism alone."""

from __future__ import annotations

import numpy as np

from synth.assets.classes import rig_rng
from synth.assets.fit import torso
from synth.assets.fit.body import Body, fit_shell
from synth.assets.fit.garment import CLEARANCE, garment_shell
from synth.export.usd_assets import HeadPose, asset_meshes


def test_torso_exported_only_when_rendered(default_head):
    hm = default_head
    d = hm.data
    ev = hm.evaluate(np.zeros(d.identity_dims), np.zeros(d.expression_dims), np.zeros((hm.J, 3)))
    rest = HeadPose(ev.vertices[0].astype(np.float64), {k: v[0].astype(np.float64) for k, v in ev.landmarks.items()})
    entry = {"id": "tshirt_crew", "params": {}}
    body = Body(rest.vertices, d.triangles, d.regions, rest.landmarks["ibug68"])
    fitted = fit_shell(body, garment_shell(body, entry, rig_rng(7, 3, "garment")), CLEARANCE)
    Vt, _ = torso.garment_torso(fitted)
    Vp, _ = torso.garment_torso(fitted, with_arms=False)
    assert len(Vt) > len(Vp)
    build = {"vertices": fitted.info["vertices"], "faces": fitted.info["faces"]}
    for recorded, want in ((None, None), ({"torso_vertices": len(Vp)}, Vp),
                           ({"torso_vertices": len(Vt), "torso_arms": True}, Vt)):
        rec = dict(entry, generator="procedural:garment_shell", build=dict(build, **(recorded or {})))
        meshes, skipped = asset_meshes(d, rest, [rest, rest], {"garment": rec}, 7, 3)
        names = ["garment_tshirt_crew"] + ([] if want is None else ["garment_tshirt_crew_torso"])
        assert [m.name for m in meshes] == names and not skipped
        if want is not None:
            np.testing.assert_allclose(meshes[1].points[0], want)
    rec = dict(entry, generator="procedural:garment_shell", build=dict(build, torso_vertices=len(Vt)))  # no torso_arms
    meshes, skipped = asset_meshes(d, rest, [rest], {"garment": rec}, 7, 3)
    assert not meshes and "torso vertices" in skipped["garment"]
