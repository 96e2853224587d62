"""Build the head mesh object from model arrays; update it per expression without rebuilding."""

from __future__ import annotations

import bpy
import numpy as np

from blender_scripts.mesh import link_object, new_mesh, set_positions
from synth.appearance.lips import vermilion_attribute
from synth.appearance.teeth import arch_attribute
from synth.dataset.segmentation import polygon_classes


def build_head_object(data, vertices: np.ndarray, materials: dict[int, "bpy.types.Material"],
                      name: str = "head") -> "bpy.types.Object":
    """Create the mesh (polygons with quads kept, UVs, one material slot per class)."""
    off, idx, cls, keep = polygon_classes(data)
    corner_uv = None
    if data.uvs is not None:
        if data.poly_uv is not None and data.poly_offsets is not None:
            corner_uv = data.uvs[data.poly_uv]
            orig_counts = np.diff(data.poly_offsets.astype(np.int64))
        else:
            corner_uv = data.uvs[data.tri_uv.reshape(-1)]
            orig_counts = np.full(len(data.triangles), 3, np.int64)
        corner_uv = corner_uv[np.repeat(keep, orig_counts)]
    slots = sorted(set(cls.tolist()))
    slot_of = {c: i for i, c in enumerate(slots)}
    me = new_mesh(name, vertices, off, idx, np.array([slot_of[c] for c in cls.tolist()], np.int32), corner_uv)
    arch = arch_attribute(len(vertices), data.regions, vertices)
    if arch is not None:  # where the teeth's gaps lie (synth.appearance.teeth; the teeth material)
        attr = me.attributes.new("tooth_arch", "FLOAT", "POINT")
        attr.data.foreach_set("value", np.ascontiguousarray(arch, np.float32))
    lips = vermilion_attribute(len(vertices), data.regions, data.triangles)
    if lips is not None:  # where the lips' own colour lies (synth.appearance.lips; the skin material)
        attr = me.attributes.new("vermilion", "FLOAT", "POINT")
        attr.data.foreach_set("value", np.ascontiguousarray(lips, np.float32))
    return link_object(name, me, [materials[c] for c in slots])


def set_vertices(ob, vertices: np.ndarray) -> None:
    """Expression change: overwrite coordinates in place (no rebuild)."""
    set_positions(ob, vertices)


def set_rest_positions(ob, rest: np.ndarray) -> None:
    """Store the identity's neutral shape as the ``rest_position`` point attribute: Geometry
    Nodes (Deform Curves on Surface) compare it with the current shape to carry attached
    strands along when an expression changes the vertices."""
    me = ob.data
    attr = me.attributes.get("rest_position")
    if attr is None:
        attr = me.attributes.new("rest_position", "FLOAT_VECTOR", "POINT")
    attr.data.foreach_set("vector", np.ascontiguousarray(rest, np.float32).ravel())
    me.update()


#: Render size (pixels, larger side) from which the head is subdivided once at render time: below
#: it a 6k-vertex head with smooth normals has no visibly faceted silhouette, above it it does.
SUBDIVIDE_FROM_PX = 512


def add_render_subdivision(ob, resolution: int) -> int:
    """Catmull-Clark at render time only (levels: 1 from SUBDIVIDE_FROM_PX). Labels (landmarks,
    asset attachment) stay on the control mesh; the limit surface moves < 1 mm from it."""
    levels = 1 if resolution >= SUBDIVIDE_FROM_PX else 0
    if levels:
        mod = ob.modifiers.new("render_subdivision", "SUBSURF")
        mod.levels = 0
        mod.render_levels = levels
        mod.show_viewport = False
        mod.uv_smooth = "PRESERVE_BOUNDARIES"
    return levels
