"""The USD export rebuilds a garment's body below the bust only for renders that built one (their
record has ``torso_vertices``), with the rendered vertex count; older renders get the shell alone.
Renders with the bust's forearms (``torso_forearms``) get the prism and the forearms, renders
without them the prism alone; renders of the tube arms before the bust (``torso_arms``) are not
rebuilt."""

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


def _body(d, rest):
    return rest.vertices, d.triangles, d.regions


def test_torso_exported_only_when_rendered(default_head):
    from synth.assets.fit.arms import FOREARM_INSET

    d, rest, entry, fitted = _fitted(default_head, "sweater")  # long sleeves: the forearms in its cloth
    off = fitted.info["cloth_reach_m"] - FOREARM_INSET
    Vt, _ = torso.garment_torso(fitted, _body(d, rest), off)
    Vp, _ = torso.garment_torso(fitted)
    assert len(Vt) > len(Vp)
    build = {"vertices": fitted.info["vertices"], "faces": fitted.info["faces"]}
    for recorded, want in ((None, None), ({"torso_vertices": len(Vp)}, Vp),
                           ({"torso_vertices": len(Vt), "torso_forearms": True}, Vt)):
        rec = dict(entry, generator="procedural:garment_shell", build=dict(build, **(recorded or {})))
        meshes, skipped = asset_meshes(d, rest, [rest, rest], {"garment": rec}, 7, 3)
        names = ["garment_sweater"] + ([] if want is None else ["garment_sweater_torso"])
        assert [m.name for m in meshes] == names and not skipped
        if want is not None:
            np.testing.assert_allclose(meshes[1].points[0], want)
    rec = dict(entry, generator="procedural:garment_shell", build=dict(build, torso_vertices=len(Vt)))  # no forearms
    meshes, skipped = asset_meshes(d, rest, [rest], {"garment": rec}, 7, 3)
    assert not meshes and "torso vertices" in skipped["garment"]
    rec = dict(entry, generator="procedural:garment_shell", build=dict(build, torso_vertices=len(Vt), torso_arms=True))
    meshes, skipped = asset_meshes(d, rest, [rest], {"garment": rec}, 7, 3)
    assert not meshes and "tube arms" in skipped["garment"]


def test_bare_forearms_exported_as_skin(default_head):
    """A T-shirt's forearms (``torso_forearms_skin``: short sleeves) are bare skin: the export gives
    them their own mesh in the skin's segmentation class, beside the prism in the garment's class,
    and together they are the rendered torso's vertices."""
    from synth.dataset.segmentation import CLASSES as SEG

    d, rest, entry, fitted = _fitted(default_head, "tshirt_crew")
    assert fitted.info["sleeves"] == "short"
    Vt, Ft = torso.garment_torso(fitted, _body(d, rest))
    (Vp, Fp), (Va, Fa) = torso.garment_torso_parts(fitted, _body(d, rest))
    np.testing.assert_array_equal(Vt, np.vstack([Vp, Va]))
    np.testing.assert_array_equal(Ft, np.vstack([Fp, Fa + len(Vp)]))
    build = {"vertices": fitted.info["vertices"], "faces": fitted.info["faces"], "torso_vertices": len(Vt),
             "torso_forearms": True, "torso_forearms_skin": True}
    rec = dict(entry, generator="procedural:garment_shell", build=build)
    meshes, skipped = asset_meshes(d, rest, [rest], {"garment": rec}, 7, 3)
    assert not skipped
    assert [m.name for m in meshes] == ["garment_tshirt_crew", "garment_tshirt_crew_torso",
                                        "garment_tshirt_crew_forearms"]
    assert [m.segmentation_id for m in meshes[1:]] == [9, SEG["skin"]] and SEG["skin"] != 9
    np.testing.assert_allclose(meshes[1].points[0], Vp)
    np.testing.assert_allclose(meshes[2].points[0], Va)
    np.testing.assert_array_equal(meshes[2].faces[0], Fa)
