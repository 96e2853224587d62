"""Shared fixture code for asset-rig tests: a head scene at hard codes, and evaluated geometry.

Usage (inside a test that did ``pytest.importorskip("bpy")``; ``head_arrays`` needs no bpy)::

    ctx, hm, cases = asset_scene.head_context(case="id+3_jaw")
    rig = importlib.import_module("blender_scripts.assets.hair").build(ctx, entry)
    verts, faces = asset_scene.evaluated_mesh(rig.objects[0])
    asset_scene.set_case(ctx, hm, "id-3_brows")    # new expression: head updated, then rig.update(ctx)
"""

from __future__ import annotations

import numpy as np

#: Hard cases: identity at +-3 SD along every component (sign pattern fixed), jaw open and
#: brows raised expressions.
CASES = ("neutral", "id+3_jaw", "id-3_brows", "id+3_brows", "id-3_jaw")


def _codes(hm, case: str):
    d = hm.data
    beta = np.zeros(d.identity_dims)
    if case.startswith("id+3"):
        beta[:] = 3.0 * np.where(np.arange(d.identity_dims) % 2 == 0, 1.0, -1.0)
    elif case.startswith("id-3"):
        beta[:] = -3.0 * np.where(np.arange(d.identity_dims) % 2 == 0, 1.0, -1.0)
    psi = np.zeros(d.expression_dims)
    rot = np.zeros((hm.J, 3))
    names = list(d.expression_names)
    if case.endswith("jaw"):
        if "jawOpen" in names:
            psi[names.index("jawOpen")] = 1.0
        rot[hm.joint_index["jaw"]] = (np.radians(25.0), 0.0, 0.0)
    if case.endswith("brows"):
        for n in ("browInnerUp", "browOuterUpLeft", "browOuterUpRight"):
            if n in names:
                psi[names.index(n)] = 1.0
    return beta, psi, rot


def _ctx_arrays(hm, beta, psi, rot):
    ev = hm.evaluate(beta, psi, rot)
    rest = hm.evaluate(beta, np.zeros_like(psi), np.zeros_like(rot), landmarks=False).vertices[0]
    return (rest.astype(np.float64), ev.vertices[0].astype(np.float64), ev.joint_transforms[0].astype(np.float64),
            {k: v[0].astype(np.float64) for k, v in ev.landmarks.items()})


def head_arrays(hm, case: str = "neutral", resolution: int = 64, identity_index: int = 0, run_seed: int = 0):
    """A HeadContext without Blender objects (``head`` None, no materials), for the numpy
    fitting code of ``synth.assets.fit`` (no bpy needed)."""
    from blender_scripts.assets import HeadContext

    beta, psi, rot = _codes(hm, case)
    rest, verts, joints, lms = _ctx_arrays(hm, beta, psi, rot)
    return HeadContext(data=hm.data, head=None, materials={}, rest_vertices=rest, vertices=verts,
                       joint_transforms=joints, joint_index=dict(hm.joint_index), landmarks=lms,
                       resolution=resolution, identity_index=identity_index, run_seed=run_seed)


def set_case_arrays(ctx, hm, case: str) -> None:
    """Change identity/expression of the arrays in place (no Blender objects touched)."""
    beta, psi, rot = _codes(hm, case)
    ctx.rest_vertices, ctx.vertices, ctx.joint_transforms, ctx.landmarks = _ctx_arrays(hm, beta, psi, rot)


def head_context(case: str = "neutral", resolution: int = 64, identity_index: int = 0, run_seed: int = 0,
                 model=None):
    """Fresh scene with a head at ``case`` (``model``: a HeadModelData, default the embedded
    model); returns (HeadContext, HeadModel)."""
    from blender_scripts import head as bhead
    from blender_scripts import materials as bmat
    from blender_scripts import scene as bscene
    from synth.appearance.skin import skin_albedo
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel

    hm = HeadModel(load_default_model() if model is None else model)
    bscene.reset()
    ctx = head_arrays(hm, case, resolution, identity_index, run_seed)
    ctx.materials = bmat.head_materials(None, skin_albedo(0.1, 0.015))
    ctx.head = bhead.build_head_object(hm.data, ctx.vertices, ctx.materials)
    return ctx, hm


def set_case(ctx, hm, case: str) -> None:
    """Change identity/expression in place (as the worker does between expressions)."""
    from blender_scripts import head as bhead

    set_case_arrays(ctx, hm, case)
    bhead.set_vertices(ctx.head, ctx.vertices)


def evaluated_mesh(ob):
    """(V, 3) float64 world vertices and (F, 3) triangles of an object's evaluated geometry
    (modifiers and Geometry Nodes applied). Curves objects give their points and no faces."""
    import bpy

    dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    ev = ob.evaluated_get(dg)
    mw = np.array(ev.matrix_world, np.float64)
    if ob.type == "CURVES":
        c = ev.data
        pts = np.empty(len(c.points) * 3, np.float32)
        c.points.foreach_get("position", pts)
        p = pts.reshape(-1, 3).astype(np.float64)
        return p @ mw[:3, :3].T + mw[:3, 3], np.zeros((0, 3), np.int64)
    me = ev.to_mesh()
    try:
        me.calc_loop_triangles()
        v = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", v)
        t = np.empty(len(me.loop_triangles) * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", t)
    finally:
        ev.to_mesh_clear()
    v = v.reshape(-1, 3).astype(np.float64)
    return v @ mw[:3, :3].T + mw[:3, 3], t.reshape(-1, 3).astype(np.int64)


def curve_roots(ob) -> np.ndarray:
    """First point of every curve of an evaluated Curves object (world)."""
    import bpy

    dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    ev = ob.evaluated_get(dg)
    c = ev.data
    off = np.empty(len(c.curves), np.int32)
    c.curves.foreach_get("first_point_index", off)
    pts, _ = evaluated_mesh(ob)
    return pts[off]


def head_trimesh(ctx):
    """trimesh of the current head surface (for distance and penetration checks)."""
    import trimesh

    return trimesh.Trimesh(ctx.vertices, ctx.data.triangles.astype(np.int64), process=False)


def single_shader_material(name: str, shader: str, inputs: dict):
    """A node material whose surface is one shader node (``shader``, e.g. ShaderNodeEmission)
    with these input values; returns (material, that node)."""
    import bpy

    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    node = nt.nodes.new(shader)
    for k, v in inputs.items():
        node.inputs[k].default_value = v
    nt.links.new(node.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    return mat, node
