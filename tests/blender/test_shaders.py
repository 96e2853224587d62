"""Shader-layer assets (makeup, iris, skin detail) and a glasses render: every id builds, and
tiny Cycles renders change where they should (the iris colour model: tests/appearance/test_iris.py)."""

from __future__ import annotations

import importlib
import tomllib
from pathlib import Path

import numpy as np
import pytest

from synth.assets.params import AssetPick
from synth.plan.records import RenderSettings
from tests.support import asset_scene

MANIFEST = Path(__file__).resolve().parents[2] / "assets_manifest"


def _ids(cls):
    return [a["id"] for a in tomllib.loads((MANIFEST / f"{cls}.toml").read_text())["assets"]]


# ----------------------------------------------------------------------------- Blender

W = H = 64


def _render(ctx, tmp, target=None, radius: float = 0.3, fov_deg: float = 30.0):
    from blender_scripts import camera, passes, scene
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world

    scene.configure_render(RenderSettings(samples=4, denoise=False, device="cpu", max_bounces=4), W, H)
    scene.uniform_environment(1.0)
    lm = ctx.landmarks["ibug68"]
    if target is None:
        target = 0.5 * (lm[39] + lm[42]) + np.array([0.0, 0.0, -0.025])
    cam = camera.make_camera()
    w2c = invert_rigid(orbit_camera_to_world(0.0, 0.0, radius, target))
    K = intrinsics(W, H, fov_deg, (0.0, 0.0))
    camera.set_camera(cam, K, w2c, W, H, 0.05, 10.0)
    r = passes.render_view(tmp, 3)
    return r, K, w2c


def _pixels(ctx, K, w2c, region):
    from synth.conventions import project

    uv, _ = project(K, w2c, ctx.vertices[np.asarray(ctx.data.regions[region])])
    ij = np.floor(uv).astype(int)
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
    m = np.zeros((H, W), bool)
    m[ij[ok, 1], ij[ok, 0]] = True
    return m


def _scene(assets: dict, tmp, case="neutral"):
    from blender_scripts import assets as basset

    ctx, hm = asset_scene.head_context(case)
    rigs = basset.dress(ctx, assets)
    r, K, w2c = _render(ctx, tmp)
    return ctx, rigs, r, K, w2c


@pytest.fixture(scope="module")
def renders(tmp_path_factory):
    pytest.importorskip("bpy")
    tmp = tmp_path_factory.mktemp("shaders")
    out = {}
    out["base"] = _scene({}, tmp)
    out["lipstick"] = _scene({"makeup": {"id": "lipstick", "params": {"lip_colour": "red", "gloss": 0.5,
                                                                       "opacity": 1.0}}}, tmp)
    out["blue"] = _scene({"iris": {"id": "blue", "params": {"melanin": 0.05, "stroma_scatter": 0.9,
                                                             "limbal_ring": 0.5, "pupil_dilation": 0.3}}}, tmp)
    out["dark"] = _scene({"iris": {"id": "dark_brown", "params": {"melanin": 0.95, "limbal_ring": 0.5,
                                                                   "pupil_dilation": 0.3, "fibre_contrast": 0.2}}}, tmp)
    out["glasses"] = _scene({"glasses": {"id": "rectangular", "params": {"frame_colour": "black",
                                                                         "frame_material": "acetate"}}}, tmp)
    return out


@pytest.mark.blender
@pytest.mark.slow
def test_lipstick_changes_lip_pixels(renders):
    ctx, _, base, K, w2c = renders["base"]
    _, _, lip, _, _ = renders["lipstick"]
    m = _pixels(ctx, K, w2c, "lips") & (base["segmentation"] == 1)
    assert m.sum() >= 10
    b, l = base["rgba"][m, :3].mean(0), lip["rgba"][m, :3].mean(0)
    assert l[0] / l[1] > 1.3 * b[0] / b[1]  # redder lips
    far = _pixels(ctx, K, w2c, "nose") & ~_pixels(ctx, K, w2c, "lips")
    assert np.abs(base["rgba"][far, :3].mean(0) - lip["rgba"][far, :3].mean(0)).max() < 0.03


@pytest.mark.blender
@pytest.mark.slow
def test_iris_melanin_changes_eye_pixels(renders):
    ctx, _, blue, K, w2c = renders["blue"]
    _, _, dark, _, _ = renders["dark"]
    m = (_pixels(ctx, K, w2c, "iris_l") | _pixels(ctx, K, w2c, "iris_r")) & (blue["segmentation"] == 2)
    assert m.sum() >= 2
    b, d = blue["rgba"][m, :3].mean(0), dark["rgba"][m, :3].mean(0)
    assert b[2] / max(b[0], 1e-6) > 1.2 * d[2] / max(d[0], 1e-6)  # bluer with little melanin
    assert d.sum() < b.sum()


@pytest.mark.blender
@pytest.mark.slow
def test_glasses_render_with_segmentation_id(renders):
    _, _, base, _, _ = renders["base"]
    _, rigs, gl, _, _ = renders["glasses"]
    seg = gl["segmentation"]
    assert (seg == 10).sum() >= 20
    assert (base["segmentation"] == 10).sum() == 0
    assert np.isfinite(gl["rgba"]).all()
    assert rigs["glasses"].record()["nose_gap_m"] < 0.002


@pytest.mark.blender
@pytest.mark.slow
def test_eyeliner_wing_renders_as_a_thin_band(tmp_path):
    """A close-up of the right eye's outer corner (0.33 mm a pixel) with a winged eyeliner: the
    wing darkens a band along its segment, a few pixels wide and continuous, and nothing 3 mm or
    more beside it (drawn per vertex, it was a row of blobs ending in a dot)."""
    pytest.importorskip("bpy")
    from blender_scripts import assets as basset
    from synth.assets.fit.masks import WING_TIP_M, wing_width
    from synth.conventions import project

    ctx, hm = asset_scene.head_context("neutral")
    corner = ctx.landmarks["ibug68"][36]
    tip = corner + np.array([-1.0, 1.0, 1.0]) * WING_TIP_M
    view = dict(target=0.5 * (corner + tip), radius=0.2, fov_deg=6.0)
    base, K, w2c = _render(ctx, tmp_path, **view)
    basset.dress(ctx, {"makeup": {"id": "eyeliner", "params": {"thickness": 1.0, "wing": True}}})
    wing, _, _ = _render(ctx, tmp_path, **view)
    dark = (base["rgba"][..., :3].mean(-1) - wing["rgba"][..., :3].mean(-1)) > 0.08
    along = np.linspace(0.2, 0.9, 15)
    uv, _ = project(K, w2c, corner + along[:, None] * (tip - corner))
    px = (1.0 / (2 * 0.2 * np.tan(np.radians(3.0)) / W))  # pixels per metre at the target
    on = dark[np.floor(uv[:, 1]).astype(int), np.floor(uv[:, 0]).astype(int)]
    assert on.all(), on  # continuous along the wing
    # nothing beyond the wing's half width + 3 mm, in the frame's half beyond the eye corner
    yy, xx = np.mgrid[0:H, 0:W] + 0.5
    a, b = uv[0], uv[-1]
    d_axis = np.abs((xx - a[0]) * (b[1] - a[1]) - (yy - a[1]) * (b[0] - a[0])) / np.linalg.norm(b - a)
    beyond = (xx - a[0]) * (b[0] - a[0]) + (yy - a[1]) * (b[1] - a[1]) > 0  # past the corner's perpendicular
    far = beyond & (d_axis > (wing_width(1.0) + 0.003) * px)
    assert far.sum() > 200 and not dark[far].any(), int(dark[far].sum())
    near = dark & beyond & (d_axis <= (wing_width(1.0) + 0.003) * px)
    assert 10 <= near.sum() <= 2.0 * np.linalg.norm(b - a) * 2 * wing_width(1.0) * px + 20, int(near.sum())


@pytest.mark.blender
@pytest.mark.slow
def test_every_shader_layer_id_builds(tmp_path):
    pytest.importorskip("bpy")
    from synth.assets.classes import CLASSES

    ctx, hm = asset_scene.head_context("id+3_jaw")
    ctx.assets = {}
    recs = []
    for cls in [c.name for c in CLASSES.values() if c.shader_layer]:
        mod = importlib.import_module(f"blender_scripts.assets.{CLASSES[cls].rig}")
        for i in _ids(cls):
            params = {"freckles": 0.5, "age_spots": 0.2, "oiliness": 0.4, "wrinkle_depth": 0.8} if cls == "skin" else {}
            rig = mod.build(ctx, AssetPick.coerce(cls, {"id": i, "params": params}))
            recs.append(rig.record())
    assert len(recs) == len(_ids("skin")) + len(_ids("iris")) + len(_ids("makeup"))
    for name in ("makeup_mask", "makeup_mask2", "iris_coord", "skin_mask"):
        assert name in ctx.head.data.attributes
    r, _, _ = _render(ctx, tmp_path)  # the stacked node trees compile and render finite
    assert np.isfinite(r["rgba"]).all() and (r["segmentation"] == 1).sum() > 100
    # stubble shadow chosen by the beard asset
    ctx2, _ = asset_scene.head_context("neutral")
    sd = importlib.import_module("blender_scripts.assets.skin_detail")
    from synth.appearance.pigment import pigment, shaft_darkness

    shadow = {}
    for colour in ("black", "blonde"):
        ctx2.assets = {"beard": {"id": "stubble", "params": {"colour": colour}}}
        shadow[colour] = sd.build(ctx2, AssetPick.of("skin", "procedural_skin")).record()["stubble_shadow"]
        assert shadow[colour] == pytest.approx(sd.STUBBLE_SHADOW * shaft_darkness(pigment(colour)), abs=1e-4)
    assert shadow["black"] > 3 * shadow["blonde"] > 0  # fair stubble barely shows
    # the scalp shadow under scalp hair, as dark as the hair; none without hair
    scalp = {}
    for colour in ("black", "blonde", None):
        ctx2.assets = {"hair": {"id": "short_straight", "params": {"colour": colour}}} if colour else {}
        if "scalp_mask" in ctx2.head.data.attributes:
            ctx2.head.data.attributes.remove(ctx2.head.data.attributes["scalp_mask"])
        scalp[colour] = sd.build(ctx2, AssetPick.of("skin", "procedural_skin")).record()["scalp_shadow"]
        assert ("scalp_mask" in ctx2.head.data.attributes) == bool(colour)
        if colour:
            assert scalp[colour] == pytest.approx(sd.SCALP_SHADOW * shaft_darkness(pigment(colour)), abs=1e-4)
    assert scalp["black"] > 3 * scalp["blonde"] > 0 and scalp[None] == 0.0


@pytest.mark.blender
@pytest.mark.slow
def test_teeth_show_gaps_between_teeth(tmp_path):
    """A close-up of the open mouth (+3 SD head, jaw open; 0.33 mm a pixel): against the same
    render without the ``tooth_arch`` attribute (one flat band, as before), the teeth show dark
    gaps where the arch coordinate crosses an integer (the midline and the gaps to either side),
    thin columns, not a darkened band."""
    pytest.importorskip("bpy")
    from synth.appearance.teeth import ARCH_OFFSET
    from synth.conventions import project
    from synth.dataset.segmentation import CLASSES

    ctx, hm = asset_scene.head_context("id+3_jaw")
    me = ctx.head.data
    arch = np.empty(len(me.vertices), np.float32)
    me.attributes["tooth_arch"].data.foreach_get("value", arch)
    lower = np.asarray(ctx.data.regions["teeth_lower"])
    front = lower[np.abs(arch[lower] - ARCH_OFFSET) < 2.5]  # the incisors
    view = dict(target=ctx.vertices[front].mean(0), radius=0.2, fov_deg=6.0)
    gaps, K, w2c = _render(ctx, tmp_path, **view)
    me.attributes.remove(me.attributes["tooth_arch"])
    flat, _, _ = _render(ctx, tmp_path, **view)
    teeth = (gaps["segmentation"] == CLASSES["teeth"]) & (flat["segmentation"] == CLASSES["teeth"])
    assert teeth.sum() > 150
    drop = flat["rgba"][..., :3].mean(-1) - gaps["rgba"][..., :3].mean(-1)
    dark = teeth & (drop > 0.15 * flat["rgba"][..., :3].mean(-1))
    assert 0.02 < dark.sum() / teeth.sum() < 0.3, dark.sum() / teeth.sum()
    # the gaps are columns: separate runs of columns with dark pixels across the teeth's rows
    rows = np.nonzero(teeth.sum(1) > 10)[0]
    cols_dark = dark[rows].any(0).astype(int)
    runs = np.count_nonzero(np.diff(np.concatenate([[0], cols_dark, [0]])) == 1)
    assert runs >= 3, cols_dark
    # the midline gap lies where the model's midline projects
    uv, _ = project(K, w2c, ctx.vertices[front][np.argmin(np.abs(ctx.vertices[front][:, 0]))][None])
    cols = np.nonzero(cols_dark)[0]
    assert np.min(np.abs(cols + 0.5 - uv[0, 0])) < 2.0


@pytest.mark.blender
@pytest.mark.slow
def test_under_eye_darkening_shows_where_its_mask_is(tmp_path, monkeypatch):
    """The skin rig's under-eye layer at its strongest against none: the skin under the lower
    lids darker (and only there: the nose bridge unchanged); the vellus sheen drawn in its range."""
    pytest.importorskip("bpy")
    from synth.conventions import project

    sd = importlib.import_module("blender_scripts.assets.skin_detail")
    from synth.assets.fit.masks import skin_tint_mask

    lum = {}
    for strength in (0.0, 0.6):
        monkeypatch.setattr(sd, "UNDER_EYE", (strength, strength))
        ctx, hm = asset_scene.head_context("neutral")
        ctx.assets = {}
        rec = sd.build(ctx, AssetPick.coerce("skin", {"id": "procedural_skin", "params": {"haemoglobin": 0.05}})).record()
        assert rec["under_eye"] == strength and sd.VELLUS_SHEEN[0] <= rec["vellus_sheen"] <= sd.VELLUS_SHEEN[1]
        lm = ctx.landmarks["ibug68"]
        r, K, w2c = _render(ctx, tmp_path, target=0.5 * (lm[39] + lm[42]), radius=0.3, fov_deg=10.0)
        lum[strength] = r["rgba"][..., :3].mean(-1)
    mask = skin_tint_mask(ctx.data, ctx.vertices, lm)
    uv, _ = project(K, w2c, ctx.vertices)
    ij = np.floor(uv).astype(int)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)

    def pix(sel):
        m = np.zeros((H, W), bool)
        m[ij[sel & inside, 1], ij[sel & inside, 0]] = True
        return m

    under = pix(mask[:, 0] > 0.8)
    bridge = pix((mask[:, 0] == 0) & (np.linalg.norm(ctx.vertices - lm[27], axis=1) < 0.012))  # between the eyes
    assert under.sum() >= 10 and bridge.sum() >= 10, (under.sum(), bridge.sum())
    drop = 1.0 - lum[0.6][under].mean() / lum[0.0][under].mean()
    assert 0.08 < drop < 0.4, drop  # about -12 L* at strength 1, scaled by 0.6
    assert abs(1.0 - lum[0.6][bridge].mean() / lum[0.0][bridge].mean()) < 0.02
