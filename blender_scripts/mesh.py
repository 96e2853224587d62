"""Mesh objects from numpy arrays: the one place that fills Blender meshes (head, garments,
headwear, glasses)."""

from __future__ import annotations

import bpy
import numpy as np


def new_mesh(name: str, vertices: np.ndarray, offsets: np.ndarray, indices: np.ndarray,
             material_index: np.ndarray | None = None, corner_uv: np.ndarray | None = None) -> "bpy.types.Mesh":
    """A smooth-shaded mesh of polygons given as CSR (offsets (P+1,), corner vertex indices),
    optional per-polygon material slot and per-corner UVs (layer "UVMap")."""
    off = np.asarray(offsets, np.int64)
    idx = np.asarray(indices, np.int64).ravel()
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(vertices))
    me.vertices.foreach_set("co", np.ascontiguousarray(vertices, np.float32).ravel())
    me.loops.add(len(idx))
    me.loops.foreach_set("vertex_index", idx.astype(np.int32))
    P = len(off) - 1
    me.polygons.add(P)
    me.polygons.foreach_set("loop_start", off[:-1].astype(np.int32))
    me.polygons.foreach_set("loop_total", np.diff(off).astype(np.int32))
    if corner_uv is not None:
        uv_layer = me.uv_layers.new(name="UVMap")
        uv_layer.data.foreach_set("uv", np.ascontiguousarray(corner_uv, np.float32).ravel())
    if material_index is not None:
        me.polygons.foreach_set("material_index", np.ascontiguousarray(material_index, np.int32))
    me.polygons.foreach_set("use_smooth", np.ones(P, bool))
    me.update()
    me.validate(clean_customdata=False)
    return me


def new_triangle_mesh(name: str, vertices: np.ndarray, faces: np.ndarray,
                      material_index: np.ndarray | None = None) -> "bpy.types.Mesh":
    faces = np.asarray(faces, np.int64)
    return new_mesh(name, vertices, np.arange(0, faces.size + 1, 3), faces, material_index)


def link_object(name: str, mesh, materials=()) -> "bpy.types.Object":
    """Append ``materials`` as the mesh's slots and link a new object into the scene."""
    for m in materials:
        mesh.materials.append(m)
    ob = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def set_positions(ob, vertices: np.ndarray) -> None:
    """Overwrite vertex coordinates in place (same topology; no rebuild)."""
    me = ob.data
    me.vertices.foreach_set("co", np.ascontiguousarray(vertices, np.float32).ravel())
    me.update()
