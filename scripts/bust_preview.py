"""Clay preview of the bust prototype (docs/body-plan.md, docs/body_bust.png): planned identities'
neutral heads (the default model, its shoulder polygons that the bust replaces left out) and
busts (synth.model.builders.makehuman.bust), front and 35 degrees, Cycles 16 spp, 256 px.

    .venv/bin/python scripts/bust_preview.py --bust /tmp/bust.npz --out docs/body_bust.png [--ids 72 9 129 134]

``--bust``: written by ``python -m benchmarks.bust_shapes --save FILE``. Skin-coloured: the head
model; blue-grey: the bust. Needs bpy.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bust", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--ids", type=int, nargs="+", default=[72, 9, 129, 134])
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)

    import bpy
    from PIL import Image

    from synth.config import load_config
    from synth.model.builders.makehuman import bust as B
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from synth.plan import identities

    b = B.load_bust(a.bust)
    m = load_default_model()
    hm = HeadModel(m, np.float64)
    codes = identities.planned_codes(a.seed, np.asarray(a.ids), m, load_config().identity)
    off = np.asarray(m.poly_offsets)
    npol = len(off) - 1
    replaced = {tuple(sorted(b.head_rows[p].tolist())) for p, h in zip(b.polys, b.head_polys) if h}
    drop = np.array([tuple(sorted(m.poly_indices[off[i]:off[i + 1]].tolist())) in replaced for i in range(npol)])
    head_tris = np.asarray(m.triangles)[~drop[np.repeat(np.arange(npol), np.diff(off) - 2)]]

    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 16
    scene.cycles.device = "CPU"
    scene.cycles.seed = 0
    scene.render.resolution_x = scene.render.resolution_y = 256
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 1
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o)

    def clay(name, rgb):
        mat = bpy.data.materials.new(name)
        mat.use_nodes = True
        p = mat.node_tree.nodes["Principled BSDF"]
        p.inputs["Base Color"].default_value = (*rgb, 1.0)
        p.inputs["Roughness"].default_value = 0.6
        return mat

    skin, cloth = clay("head", (0.62, 0.5, 0.45)), clay("bust", (0.45, 0.5, 0.62))

    def mesh(name, V, F, mat):
        me = bpy.data.meshes.new(name)
        me.from_pydata(V.tolist(), [], F.tolist())
        me.update()
        for p in me.polygons:
            p.use_smooth = True
        o = bpy.data.objects.new(name, me)
        o.data.materials.append(mat)
        scene.collection.objects.link(o)
        return o

    cam = bpy.data.cameras.new("cam")
    cam.type = "ORTHO"
    cam.ortho_scale = 0.75
    co = bpy.data.objects.new("cam", cam)
    scene.collection.objects.link(co)
    scene.camera = co
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = 3.0
    so = bpy.data.objects.new("sun", sun)
    so.rotation_euler = (np.radians(50), 0.0, np.radians(-30))
    scene.collection.objects.link(so)
    world = bpy.data.worlds.new("world")
    scene.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[0].default_value = (0.35, 0.35, 0.35, 1.0)
    world.node_tree.nodes["Background"].inputs[1].default_value = 0.6

    sheet = Image.new("RGB", (256 * len(codes), 512))
    with tempfile.TemporaryDirectory() as tmp:
        for j, c in enumerate(codes):
            hv = hm.evaluate(c, np.zeros(m.expression_dims), np.zeros((hm.J, 3)), landmarks=False).vertices[0]
            objs = [mesh(f"h{j}", hv, head_tris, skin), mesh(f"b{j}", b.evaluate(c), b.triangles, cloth)]
            for k, yaw in enumerate((0.0, 35.0)):
                t = np.radians(yaw)
                co.location = (2.0 * np.sin(t), -2.0 * np.cos(t), 0.52)
                co.rotation_euler = (np.radians(90.0), 0.0, t)
                scene.render.filepath = str(Path(tmp) / f"{j}_{k}.png")
                bpy.ops.render.render(write_still=True)
                sheet.paste(Image.open(scene.render.filepath).convert("RGB"), (256 * j, 256 * k))
            for o in objs:
                bpy.data.objects.remove(o)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
