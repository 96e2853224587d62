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


def _fitted(hm, garment_id: str):
    """(model data, the neutral head, the plan entry, the garment fitted as the renderer fits it)."""
    d = hm.data
    ev = hm.evaluate(np.zeros(d.identity_dims), np.zeros(d.expression_dims), np.zeros((hm.J, 3)))
    rest = HeadPose(ev.vertices[0].astype(np.float64), {k: v[0].astype(np.float64) for k, v in ev.landmarks.items()})
    entry = {"id": garment_id, "params": {}}
    body = Body(rest.vertices, d.triangles, d.regions, rest.landmarks["ibug68"])
    return d, rest, entry, fit_shell(body, garment_shell(body, entry, rig_rng(7, 3, "garment")), CLEARANCE)


def test_torso_exported_only_when_rendered(default_head):
    d, rest, entry, fitted = _fitted(default_head, "tshirt_crew")
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


def test_bare_arms_exported_as_skin(default_head):
    """A tank top's arms (``torso_arms_skin``) are bare skin: the export gives them their own mesh in
    the skin's segmentation class, beside the prism in the garment's class, and together they are
    the rendered torso's vertices."""
    from synth.dataset.segmentation import CLASSES as SEG

    d, rest, entry, fitted = _fitted(default_head, "tank_top")
    Vt, Ft = torso.garment_torso(fitted)
    (Vp, Fp), (Va, Fa) = torso.garment_torso_parts(fitted)
    np.testing.assert_array_equal(Vt, np.vstack([Vp, Va]))
    np.testing.assert_array_equal(Ft, np.vstack([Fp, Fa + len(Vp)]))
    build = {"vertices": fitted.info["vertices"], "faces": fitted.info["faces"], "torso_vertices": len(Vt),
             "torso_arms": True, "torso_arms_skin": True}
    rec = dict(entry, generator="procedural:garment_shell", build=build)
    meshes, skipped = asset_meshes(d, rest, [rest], {"garment": rec}, 7, 3)
    assert not skipped
    assert [m.name for m in meshes] == ["garment_tank_top", "garment_tank_top_torso", "garment_tank_top_arms"]
    assert [m.segmentation_id for m in meshes[1:]] == [9, SEG["skin"]] and SEG["skin"] != 9
    np.testing.assert_allclose(meshes[1].points[0], Vp)
    np.testing.assert_allclose(meshes[2].points[0], Va)
    np.testing.assert_array_equal(meshes[2].faces[0], Fa)
