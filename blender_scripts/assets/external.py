"""External asset packs: link an object or collection from a checked ``.blend`` and fit it rigidly.

Used for every plan entry whose generator is ``blend:PATH.blend`` (see
``blender_scripts.assets.rig_module`` and docs/assets.md). The entry carries the ``pack``
record the planner wrote (synth.assets.packs.pack_record): file (relative to the asset
root), asset_root, object, sha256, anchor, reference_width_m, class.

What ``build`` does:

1. **Checks again** (defence in depth; the planner checked too): the file must resolve,
   symlinks followed, inside the asset root and have the declared sha256; otherwise a
   SynthError naming the file. Script auto-execution is never enabled, so a pack is data only.
2. **Links** (``bpy.data.libraries.load(path, link=True)``) the named object, or every object
   of the named collection. The linked datablocks stay read-only in the library: the mesh
   (or curves) data of what is rendered is the library's own (``ob.data.library`` is set).
3. **Instances** each linked object as a *local* object that shares the linked data
   (``linked_object.copy()``: a new Object, same data), because a linked object's transform
   and material slots cannot be edited. Its material slots are switched to object-level
   (``slot.link = 'OBJECT'``) and filled with local copies of the library's materials whose
   ``pass_index`` is the class's segmentation id: the renderer's segmentation is the
   material-index pass (``IndexMA``), so material pass indices are what count.
   ``object.pass_index`` is set too (harmless; for an Object Index pass).
4. **Fits rigidly**: the pack is modelled in its file's world frame with its anchor at the
   origin (metres, Z up, face toward -Y, docs/assets.md), for a skull ``reference_width_m``
   wide. Each object is placed at ``anchor @ scale(s) @ its matrix in the pack file`` where
   the anchor is the head joint (hair, beard, eyebrows, eyelashes, headwear), the nose
   bridge (glasses: ibug68 point 27 with the head joint's rotation) or the neck joint
   (garment), and ``s`` = the head's skull width (X extent of the scalp region in the
   head-joint frame) / ``reference_width_m``. This is a simple rigid fit: no deformation to
   the head's shape, no collision handling; ``update`` re-places the pack when the joints move
   (the jaw does not carry it: a pack beard does not open with the mouth).
"""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from blender_scripts.assets import HeadContext, Rig
from synth.assets.classes import CLASSES
from synth.assets.packs import REFERENCE_SKULL_WIDTH_M, verify_pack
from synth.assets.params import AssetPick
from synth.errors import SynthError

#: object types that render and carry material slots (lights, cameras, empties... are skipped)
RENDERABLE = {"MESH", "CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD", "VOLUME"}
NOSE_BRIDGE_IBUG = 27




def anchor_matrix(ctx: HeadContext, anchor: str) -> np.ndarray:
    """World 4x4 frame the pack's origin is placed at."""
    ji = ctx.joint_index
    head = np.asarray(ctx.joint_transforms[ji["head"]], np.float64) if "head" in ji else np.eye(4)
    if anchor == "neck":
        return np.asarray(ctx.joint_transforms[ji["neck"]], np.float64) if "neck" in ji else head
    if anchor == "nose_bridge":
        m = head.copy()
        lm = (ctx.landmarks or {}).get("ibug68")
        if lm is not None and len(lm) > NOSE_BRIDGE_IBUG:
            m[:3, 3] = np.asarray(lm[NOSE_BRIDGE_IBUG], np.float64)
        return m
    return head


def skull_width(ctx: HeadContext) -> float:
    """X extent of the scalp region in the head-joint frame (metres)."""
    ji = ctx.joint_index
    head = np.asarray(ctx.joint_transforms[ji["head"]], np.float64) if "head" in ji else np.eye(4)
    regions = getattr(ctx.data, "regions", {}) or {}
    v = np.asarray(ctx.vertices, np.float64)
    local = (v - head[:3, 3]) @ head[:3, :3]
    if "scalp" in regions and len(regions["scalp"]):
        pts = local[np.asarray(regions["scalp"])]
    else:  # no scalp region: everything above the head joint
        pts = local[local[:, 2] > 0.0]
    if len(pts) < 2:
        return REFERENCE_SKULL_WIDTH_M
    return float(np.ptp(pts[:, 0]))


def pack_matrix(ob) -> np.ndarray:
    """An object's transform in its pack file's world frame, from its stored local transform
    and its parents' (a linked object that is in no scene has no evaluated matrix_world).
    Object parenting only: constraints, drivers and bone/vertex parents are ignored."""
    m = np.array(ob.matrix_basis, np.float64)
    p = ob.parent
    if p is not None:
        m = pack_matrix(p) @ np.array(ob.matrix_parent_inverse, np.float64) @ m
    return m


def _link(path: Path, name: str, where: str) -> list:
    """Link the object (or the collection's objects) ``name`` from ``path``; the linked objects."""
    kind = None
    with bpy.data.libraries.load(str(path), link=True, relative=False) as (src, dst):
        objects, collections = list(src.objects), list(src.collections)
        if name in objects:
            dst.objects = [name]
            kind = "object"
        elif name in collections:
            dst.collections = [name]
            kind = "collection"
    if kind is None:
        raise SynthError(f"'{name}' is neither an object nor a collection in {path}", where,
                         f"fix object = ... (objects: {', '.join(objects[:10]) or 'none'}; "
                         f"collections: {', '.join(collections[:10]) or 'none'})")
    if kind == "object":
        linked = [o for o in dst.objects if o is not None]
    else:
        linked = [o for c in dst.collections if c is not None for o in c.all_objects]
    linked = [o for o in linked if o.type in RENDERABLE]
    if not linked:
        raise SynthError(f"'{name}' in {path} has nothing to render (no mesh, curves or surface objects)", where,
                         "link an object or collection with geometry")
    return linked


class PackRig(Rig):
    """Objects instanced from a linked pack and their rest matrices in the pack file."""

    def __init__(self, cls: str, objects: list, rest: list[np.ndarray], anchor: str, scale: float, info: dict):
        super().__init__(cls, objects, info)
        self.rest = rest
        self.anchor = anchor
        self.scale = scale

    def place(self, ctx: HeadContext) -> None:
        a = anchor_matrix(ctx, self.anchor)
        s = np.diag([self.scale, self.scale, self.scale, 1.0])
        for ob, m0 in zip(self.objects, self.rest):
            ob.matrix_world = Matrix((a @ s @ m0).tolist())
        self.info["anchor_world"] = [round(float(x), 6) for x in a[:3, 3]]

    def update(self, ctx: HeadContext) -> None:
        self.place(ctx)


def build(ctx: HeadContext, entry: AssetPick) -> Rig:
    pack = entry.pack
    where = f"asset {entry.id} ({entry.generator})"
    if pack is None:
        raise SynthError("external asset entry carries no pack record", where,
                         "re-plan with the current synth (synth plan writes the pack record)")
    if pack.cls != entry.cls:
        raise SynthError(f"external asset '{entry.id}' is planned as {entry.cls} but its pack is {pack.cls}", where,
                         "re-plan with the current synth")
    cls = entry.cls
    path = verify_pack(pack.file, pack.asset_root, pack.sha256, where)
    linked = _link(path, pack.object, where)

    seg = CLASSES[cls].segmentation_id
    coll = bpy.data.collections.new(f"asset_{cls}")
    bpy.context.scene.collection.children.link(coll)
    local_mats: dict = {}
    objects, rest = [], []
    for src in linked:
        m0 = pack_matrix(src)
        ob = src.copy()  # local Object sharing the linked data
        ob.name = f"{cls}_{entry.id}_{src.name}"
        ob.parent = None
        coll.objects.link(ob)
        if not len(ob.material_slots):
            raise SynthError(f"object '{src.name}' in {path} has no material slot", where,
                             "give every pack object at least one material in the .blend")
        for slot in ob.material_slots:
            m = slot.material
            key = m.name_full if m is not None else None
            if key not in local_mats:
                lm = m.copy() if m is not None else bpy.data.materials.new(f"{cls}_pack_default")
                lm.name = f"{cls}_{entry.id}_{m.name if m is not None else 'default'}"
                lm.pass_index = seg
                local_mats[key] = lm
            slot.link = "OBJECT"
            slot.material = local_mats[key]
        ob.pass_index = seg
        objects.append(ob)
        rest.append(m0)

    anchor, ref = pack.anchor, float(pack.reference_width_m)  # the catalogue's (synth.assets.packs.pack_record)
    width = skull_width(ctx)
    scale = width / ref
    info = {"fit": "rigid", "pack": pack.file, "library": str(path), "sha256": pack.sha256,
            "object": pack.object, "anchor": anchor, "skull_width_m": round(width, 6),
            "reference_width_m": ref, "scale": round(scale, 6), "segmentation_id": seg,
            "objects": [o.name for o in objects]}
    rig = PackRig(cls, objects, rest, anchor, scale, info)
    rig.place(ctx)
    return rig
