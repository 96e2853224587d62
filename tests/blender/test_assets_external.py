"""External .blend packs end to end: a pack built here, registered with its sha256, validated,
planned, linked onto the default head by blender_scripts.assets.external, rendered (64x64,
4 spp) with the class's segmentation id; a tampered pack is refused."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from synth.assets.params import AssetPick
from synth.plan.records import RenderSettings

bpy = pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

SKULL_REF = 0.15
RADIUS, LIFT = 0.105, 0.06  # the cap: a hemisphere this big, this far above the head joint


def _write_cap_pack(path: Path) -> None:
    """A hemispherical cap (open at the bottom) with one material, its origin at the head joint
    as the pack convention asks, lifted LIFT above it inside the pack file."""
    import bmesh

    bpy.ops.wm.read_factory_settings(use_empty=True)
    me = bpy.data.meshes.new("CapMesh")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=24, v_segments=12, radius=RADIUS)
    bmesh.ops.delete(bm, geom=[v for v in bm.verts if v.co.z < -0.005], context="VERTS")
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new("HairCap", me)
    ob.location = (0.0, 0.0, LIFT)
    mat = bpy.data.materials.new("CapMat")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.1, 0.05, 0.02, 1.0)
    mat.pass_index = 0  # deliberately wrong: the rig must give the segmentation id
    me.materials.append(mat)
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.view_layer.update()
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.data.libraries.write(str(path), {ob}, fake_user=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)


@pytest.fixture(scope="module")
def pack_manifest(tmp_path_factory):
    from synth.assets import catalogue

    d = tmp_path_factory.mktemp("ext") / "manifest"
    shutil.copytree(catalogue.default_manifest_dir(), d)
    pack = d / "packs" / "caps" / "cap.blend"
    _write_cap_pack(pack)
    sha = hashlib.sha256(pack.read_bytes()).hexdigest()
    h = d / "hair.toml"
    h.write_text('asset_root = "packs"\n' + h.read_text() +
                 '\n[[assets]]\nid = "test_cap"\nclass = "hair"\ngenerator = "blend:caps/cap.blend"\n'
                 f'object = "HairCap"\nsha256 = "{sha}"\nlicence = "CC0-1.0"\nweight = 1e9\n'
                 f'reference_width_m = {SKULL_REF}\ntags = ["short_hair"]\n')
    h.write_text(h.read_text().replace("presence = 0.93", "presence = 1.0"))
    return d, pack, sha


def test_pack_validates(pack_manifest, tmp_path):
    from synth.assets.classes import CLASSES
    from synth.assets.validate import validate_manifest

    d, _, _ = pack_manifest
    rigs = tmp_path / "rigs"
    rigs.mkdir()
    for c in CLASSES.values():
        (rigs / f"{c.rig}.py").write_text("")
    rep = validate_manifest(d, rigs)
    assert rep.ok and rep.packs == 1, [x.line() for x in rep.defects]


@pytest.fixture(scope="module")
def built(pack_manifest, tmp_path_factory):
    from blender_scripts import assets as basset
    from synth.assets import catalogue
    from synth.plan import assets
    from tests.support import asset_scene

    d, pack, sha = pack_manifest
    cat = catalogue.load_catalogue(d)
    pick = assets.sample_assets(5, 0, cat)["hair"]
    assert pick["id"] == "test_cap" and pick["pack"]["sha256"] == sha
    ctx, hm = asset_scene.head_context()
    assert basset.rig_module("hair", AssetPick.coerce("hair", pick)).__name__ == "blender_scripts.assets.external"
    rigs = basset.dress(ctx, {"hair": pick})
    return ctx, hm, rigs["hair"], pack, pick


def test_pack_is_linked_and_segmented(built):
    from synth.dataset.segmentation import CLASSES

    ctx, _, rig, pack, _ = built
    assert len(rig.objects) == 1
    ob = rig.objects[0]
    assert ob.name in bpy.context.scene.objects
    # the geometry is the library's: linked, read-only, from the checked file
    assert ob.data.library is not None
    assert Path(bpy.path.abspath(ob.data.library.filepath)).resolve() == pack.resolve()
    assert ob.library is None  # the placed object is local (it only shares the linked mesh)
    mats = [s.material for s in ob.material_slots]
    assert mats and all(s.link == "OBJECT" for s in ob.material_slots)
    assert all(m.pass_index == CLASSES["hair"] for m in mats)
    rec = rig.record()
    assert rec["fit"] == "rigid" and rec["segmentation_id"] == CLASSES["hair"] and rec["sha256"]


def test_pack_is_placed_on_the_head(built):
    from tests.support import asset_scene

    ctx, _, rig, _, _ = built
    v, _ = asset_scene.evaluated_mesh(rig.objects[0])
    head = ctx.joint_transforms[ctx.joint_index["head"]]
    scalp = ctx.vertices[ctx.data.regions["scalp"]]
    s = rig.record()["scale"]
    width = np.ptp(((scalp - head[:3, 3]) @ head[:3, :3])[:, 0])
    assert s == pytest.approx(width / SKULL_REF, rel=1e-4)
    # the cap's rim circle sits LIFT (scaled) above the head joint, centred on it
    centre = head[:3, 3] + head[:3, 2] * LIFT * s
    rim = v[np.abs(v[:, 2] - v[:, 2].min()) < 1e-4]
    np.testing.assert_allclose(rim.mean(0), centre, atol=2e-3)
    assert np.ptp(v[:, 0]) == pytest.approx(2 * RADIUS * s, rel=0.02)
    # it covers the top of the scalp: the scalp's top lies inside the cap's sphere
    top = scalp[np.argmax(scalp[:, 2])]
    assert np.linalg.norm(top - centre) < RADIUS * s


def test_render_shows_the_segmentation_id(built, tmp_path):
    from blender_scripts import camera, passes, scene
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world
    from synth.dataset.segmentation import CLASSES

    ctx, _, _, _, _ = built
    W = H = 64
    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu"), W, H)
    scene.uniform_environment(1.0)
    cam = camera.make_camera()
    target = ctx.joint_transforms[ctx.joint_index["head"]][:3, 3]
    w2c = invert_rigid(orbit_camera_to_world(0.0, 15.0, 0.7, target))
    camera.set_camera(cam, intrinsics(W, H, 35.0, (0.0, 0.0)), w2c, W, H, 0.05, 10.0)
    r = passes.render_view(tmp_path, 3)
    seg = r["segmentation"]
    assert (seg == CLASSES["hair"]).sum() > 50
    assert (seg == CLASSES["skin"]).sum() > 50
    # the cap is above the face in the image (rows grow downward)
    rows_hair = np.nonzero(seg == CLASSES["hair"])[0].mean()
    rows_skin = np.nonzero(seg == CLASSES["skin"])[0].mean()
    assert rows_hair < rows_skin


def test_update_follows_the_joints(built):
    from tests.support import asset_scene

    ctx, hm, rig, _, _ = built
    before = np.array(rig.objects[0].matrix_world)
    ctx.joint_transforms = ctx.joint_transforms.copy()
    ctx.joint_transforms[ctx.joint_index["head"]][:3, 3] += (0.0, 0.0, 0.01)
    rig.update(ctx)
    after = np.array(rig.objects[0].matrix_world)
    np.testing.assert_allclose(after[:3, 3] - before[:3, 3], (0.0, 0.0, 0.01), atol=1e-6)
    asset_scene.set_case(ctx, hm, "neutral")
    rig.update(ctx)
    np.testing.assert_allclose(np.array(rig.objects[0].matrix_world), before, atol=1e-6)


def test_tampered_pack_is_refused(pack_manifest, tmp_path):
    from tests.support import asset_scene

    from blender_scripts.assets import external
    from synth.errors import SynthError
    from synth.assets import catalogue
    from synth.plan import assets

    d, pack, sha = pack_manifest
    cat = catalogue.load_catalogue(d)
    pick = assets.sample_assets(5, 0, cat)["hair"]
    # a copy of the manifest whose pack file is then changed after planning
    d2 = tmp_path / "m2"
    shutil.copytree(d, d2)
    pick = {**pick, "pack": {**pick["pack"], "asset_root": str((d2 / "packs").resolve())}}
    f2 = d2 / "packs" / "caps" / "cap.blend"
    with f2.open("ab") as f:
        f.write(b"\0tampered")
    ctx, _ = asset_scene.head_context()
    n_libs = len(bpy.data.libraries)
    with pytest.raises(SynthError) as e:
        external.build(ctx, AssetPick.coerce("hair", pick))
    msg = str(e.value)
    assert str(f2.resolve()) in msg and "checksum" in msg and "\n" not in msg
    assert len(bpy.data.libraries) == n_libs  # nothing was linked
    with pytest.raises(SynthError, match="cap.blend"):  # and the planner refuses it too
        catalogue.load_catalogue(d2)
    # a pick without its pack record (hand-made) is refused with a clear message
    with pytest.raises(SynthError, match="no pack record"):
        external.build(ctx, AssetPick.coerce("hair", {"id": "x", "generator": "blend:caps/cap.blend", "params": {}}))
