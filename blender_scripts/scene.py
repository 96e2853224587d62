"""Scene lifecycle and Cycles settings. The only place (with its siblings) that imports bpy.

One scene is built per identity; expressions are applied as vertex updates and views as
camera moves, so a scene is never rebuilt per view.
"""

from __future__ import annotations

import math
from typing import Any

import bpy
import numpy as np

from synth.plan.records import RenderSettings, StudioLight

VIEW_LAYER = "ViewLayer"


def reset() -> None:
    """Empty factory scene and purge orphan data (keeps memory flat across scenes)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    purge()


def purge() -> None:
    for _ in range(3):
        removed = bpy.data.orphans_purge(do_local_ids=True, do_linked_ids=True, do_recursive=True)
        if not removed:
            break


def _pick_device(scene, wanted: str) -> str:
    """'auto' -> OptiX, then CUDA, else CPU. Returns what was chosen."""
    if wanted == "cpu":
        scene.cycles.device = "CPU"
        return "cpu"
    try:
        prefs = bpy.context.preferences.addons["cycles"].preferences
    except KeyError:
        scene.cycles.device = "CPU"
        return "cpu"
    order = ["OPTIX", "CUDA"] if wanted in ("auto", "gpu") else [wanted.upper()]
    for backend in order:
        try:
            prefs.compute_device_type = backend
            prefs.refresh_devices()
        except (TypeError, ValueError):
            continue
        gpus = [d for d in prefs.devices if d.type == backend]
        if gpus:
            for d in prefs.devices:
                d.use = d.type == backend
            scene.cycles.device = "GPU"
            return backend.lower()
    if wanted not in ("auto", "cpu"):
        from synth.errors import SynthError

        raise SynthError(f"render device '{wanted}' requested but no OptiX/CUDA GPU is available", "render.device",
                         "set render.device = \"auto\" or \"cpu\"")
    scene.cycles.device = "CPU"
    return "cpu"


def configure_render(settings: RenderSettings, width: int, height: int) -> dict[str, Any]:
    """Apply render settings; returns the effective settings (recorded in frame JSON)."""
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    device = _pick_device(scene, str(settings.device).lower())
    c = scene.cycles
    c.samples = int(settings.samples)
    c.time_limit = 0.0
    c.use_adaptive_sampling = bool(settings.adaptive_sampling)
    if c.use_adaptive_sampling:
        c.adaptive_threshold = float(settings.adaptive_threshold)
    c.use_denoising = bool(settings.denoise)
    if c.use_denoising:
        c.denoiser = "OPENIMAGEDENOISE" if device == "cpu" else str(settings.gpu_denoiser).upper()
        c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        c.denoising_prefilter = str(settings.denoise_prefilter).upper()
        c.denoising_quality = str(settings.denoise_quality).upper()
    c.max_bounces = int(settings.max_bounces)
    c.diffuse_bounces = int(settings.diffuse_bounces)
    c.glossy_bounces = int(settings.glossy_bounces)
    c.transmission_bounces = int(settings.transmission_bounces)
    c.transparent_max_bounces = int(settings.transparent_bounces)
    c.use_light_tree = bool(settings.light_tree)
    c.caustics_reflective = c.caustics_refractive = bool(settings.caustics)
    scene.cycles_curves.shape = str(settings.hair_shape).upper()
    # path guiding (Open PGL) exists on the CPU only; its deterministic training gives the same pixels whatever the
    # thread count and whatever was rendered before (checked by tests/blender/test_plan_render_settings.py)
    c.use_guiding = bool(settings.path_guiding) and device == "cpu"
    c.use_surface_guiding, c.use_volume_guiding, c.use_deterministic_guiding = True, False, True
    c.use_animated_seed = False
    c.seed = 0
    c.sample_clamp_indirect = float(settings.clamp_indirect)
    c.pixel_filter_width = float(settings.filter_width)
    scene.render.resolution_x = int(width)
    scene.render.resolution_y = int(height)
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.use_persistent_data = True  # keep BVH/shaders between the views of a scene
    scene.render.threads_mode = "AUTO"
    scene.view_settings.view_transform = "Standard"  # EXR stores linear scene-referred values
    scene.display_settings.display_device = "sRGB"
    vl = scene.view_layers[0]
    vl.name = VIEW_LAYER
    vl.use_pass_z = True
    vl.use_pass_normal = True
    vl.use_pass_material_index = True
    _alpha_denoiser(scene, vl, c.use_denoising)
    settings_out = {
        "engine": "CYCLES",
        "device": device,
        "samples": c.samples,
        "adaptive": c.use_adaptive_sampling,
        "denoise": c.use_denoising,
        "denoiser": c.denoiser if c.use_denoising else None,
        "max_bounces": c.max_bounces,
        "diffuse_bounces": c.diffuse_bounces,
        "glossy_bounces": c.glossy_bounces,
        "transmission_bounces": c.transmission_bounces,
        "transparent_bounces": c.transparent_max_bounces,
        "hair_shape": scene.cycles_curves.shape.lower(),
        "light_tree": c.use_light_tree,
        "caustics": c.caustics_reflective,
        "path_guiding": c.use_guiding,
        "filter_width": c.pixel_filter_width,
        "alpha_denoised": c.use_denoising,
    }
    if c.use_denoising and c.denoiser == "OPENIMAGEDENOISE":
        settings_out["denoise_prefilter"] = c.denoising_prefilter.lower()
        settings_out["denoise_quality"] = c.denoising_quality.lower()
    if c.use_adaptive_sampling:
        settings_out["adaptive_threshold"] = c.adaptive_threshold
    img = scene.render.image_settings
    img.file_format = "OPEN_EXR_MULTILAYER"
    img.color_depth = "32"
    img.exr_codec = "NONE"  # intermediate file, repacked by synth.dataset.exr
    return settings_out


def _alpha_denoiser(scene, vl, on: bool) -> None:
    """With denoising on, the compositor denoises the film's alpha too, with OpenImageDenoise
    (the compositor's denoiser, whatever denoised the colour) and the colour's albedo and
    normal guides: its result is the render's ``Composite`` layer,
    which blender_scripts/passes.py merges at the coverage edges (synth.dataset.alpha: Cycles
    denoises the colour, not the alpha, so a fringe's composite was salt-and-pepper noise).
    The guides are prefiltered with OIDN's fast mode: as good on hair fringes as the accurate
    one (composite error against 512 samples 0.0270 vs 0.0260, unfiltered guides 0.0391) at
    an eighth of its cost (docs/performance.md)."""
    vl.cycles.denoising_store_passes = on
    scene.use_nodes = on
    if not on:
        return
    nt = scene.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    rl = nt.nodes.new("CompositorNodeRLayers")
    rl.layer = vl.name
    dn = nt.nodes.new("CompositorNodeDenoise")
    dn.prefilter = "FAST"
    dn.inputs["HDR"].default_value = False
    out = nt.nodes.new("CompositorNodeComposite")
    nt.links.new(rl.outputs["Alpha"], dn.inputs["Image"])
    nt.links.new(rl.outputs["Denoising Normal"], dn.inputs["Normal"])
    nt.links.new(rl.outputs["Denoising Albedo"], dn.inputs["Albedo"])
    nt.links.new(dn.outputs["Image"], out.inputs["Image"])


def drop_render_cache() -> None:
    """Free Cycles' persistent data (BVH, synced scene, compiled shaders) so the next render
    starts from the scene's data alone. Setting ``use_persistent_data`` to False frees it (the
    property's update callback); the views after it cache again. Called at each expression
    change: an incremental Cycles update after a geometry change does not always give the same
    pixels as a fresh sync (see docs/farm.md, "Resume gives the same bytes")."""
    r = bpy.context.scene.render
    keep = r.use_persistent_data
    r.use_persistent_data = False
    r.use_persistent_data = keep


def current_world():
    return bpy.context.scene.world


def remove_world(world) -> None:
    """Remove a world that is no longer the scene's, with the images made for it in memory
    (a studio's map); maps loaded from files stay for the next environment that uses them."""
    if world is None or world == bpy.context.scene.world:
        return
    images = [n.image for n in (world.node_tree.nodes if world.node_tree else ())
              if n.bl_idname == "ShaderNodeTexEnvironment" and n.image is not None and n.image.source == "GENERATED"]
    bpy.data.worlds.remove(world)
    for img in images:
        bpy.data.images.remove(img)


def uniform_environment(strength: float = 1.0, color=(1.0, 1.0, 1.0)) -> None:
    """A constant environment ('uniform'): every surface gets the same irradiance, no shading."""
    scene = bpy.context.scene
    world = bpy.data.worlds.new("synth_uniform")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = float(strength)
    scene.world = world


def studio_environment(env: StudioLight, strength: float = 1.0, color=(1.0, 1.0, 1.0)) -> None:
    """The procedural studio environment of the plan's lighting record ``env``
    (synth.appearance.lighting): an equirectangular float image made in memory (no file)."""
    from synth.appearance.lighting import studio_map

    L = studio_map(env.studio())
    H, W = L.shape[:2]
    rgba = np.ones((H, W, 4), np.float32)
    rgba[..., :3] = L * np.asarray(color, np.float32)
    img = bpy.data.images.new("synth_studio", W, H, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Linear Rec.709"
    img.pixels.foreach_set(rgba[::-1].ravel())  # Blender's rows start at the bottom
    scene = bpy.context.scene
    world = bpy.data.worlds.new("synth_studio")
    world.use_nodes = True
    nt = world.node_tree
    tex = nt.nodes.new("ShaderNodeTexEnvironment")
    tex.image = img
    tex.interpolation = "Linear"
    bg = nt.nodes["Background"]
    bg.inputs["Strength"].default_value = float(strength)
    nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
    # No importance map: the lobes are broad (>= 5 degrees, 25 by default), so BSDF sampling
    # finds them. 12 preview frames, Cycles s: uniform 38.7, studio with the automatic map 51.8
    # (+34 %), a 64 px manual map 45.4 (+17 %), none 37.5; skin pixels none vs automatic: 1.5-2.6 %
    # apart (noise), mean ratio 0.996-1.003.
    world.cycles.sampling_method = "NONE"
    scene.world = world


def hdr_environment(path: str, strength: float = 1.0, rotation_z_deg: float = 0.0) -> None:
    """An HDR environment map (optional diversity, as in the paper's ablation)."""
    scene = bpy.context.scene
    world = bpy.data.worlds.new("synth_hdr")
    world.use_nodes = True
    nt = world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(path, check_existing=True)
    mapping = nt.nodes.new("ShaderNodeMapping")
    coord = nt.nodes.new("ShaderNodeTexCoord")
    mapping.inputs["Rotation"].default_value[2] = math.radians(rotation_z_deg)
    nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    bg = nt.nodes["Background"]
    bg.inputs["Strength"].default_value = float(strength)
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    scene.world = world
