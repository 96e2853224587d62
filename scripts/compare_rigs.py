"""Dump every asset rig's geometry for a few planned identities, or compare two such dumps.

    PYTHONPATH=OLD .venv/bin/python scripts/compare_rigs.py dump /tmp/rigs-old [--identities 24 --seed 3]
    PYTHONPATH=NEW .venv/bin/python scripts/compare_rigs.py dump /tmp/rigs-new [--identities 24 --seed 3]
    .venv/bin/python scripts/compare_rigs.py compare /tmp/rigs-old /tmp/rigs-new

``dump`` (needs bpy) plans ``--identities`` identities (the catalogue's own presence
probabilities; the defaults meet every class), builds each identity's scene as the worker
does (head, materials, assets) for its two planned expressions, and writes per identity and
expression: the evaluated vertices of every rig object, the head's point attributes written
by shader-layer rigs (makeup and skin masks, iris coordinates) and the rigs' frame-JSON
``build`` records.
``compare`` prints every array or record that is not bit-identical and exits 1 if any.
Used to show that a refactor of the fitting code leaves the rigs unchanged, without the
sampling noise of a render.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

HEAD_ATTRIBUTES = ("makeup_mask", "makeup_mask2", "skin_mask", "iris_coord")


def _attribute(ob, name: str) -> np.ndarray | None:
    a = ob.data.attributes.get(name)
    if a is None:
        return None
    width = 4 if a.data_type in ("FLOAT_COLOR", "BYTE_COLOR") else 3
    out = np.empty(len(a.data) * width, np.float32)
    a.data.foreach_get("color" if width == 4 else "vector", out)
    return out.reshape(-1, width)


def _evaluated_points(ob) -> np.ndarray:
    """World positions of an object's evaluated points (mesh vertices, curve points)."""
    import bpy

    dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    ev = ob.evaluated_get(dg)
    mw = np.array(ev.matrix_world, np.float64)
    if ob.type == "CURVES":
        items, field = ev.data.points, "position"
        me = None
    else:
        me = ev.to_mesh()
        items, field = me.vertices, "co"
    p = np.empty(len(items) * 3, np.float32)
    items.foreach_get(field, p)
    if me is not None:
        ev.to_mesh_clear()
    return p.reshape(-1, 3).astype(np.float64) @ mw[:3, :3].T + mw[:3, 3]


def dump(out: Path, identities: int, seed: int, preset: str = "ci") -> None:
    from blender_scripts import scene as bscene
    from blender_scripts.worker import IdentityScene
    from synth.config import load_config
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan
    from synth.plan.records import RenderSettings

    out.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {}
    records: dict[str, object] = {}
    with tempfile.TemporaryDirectory(prefix="synth-rigs-") as d:
        cfg = load_config(None, [f'render.preset="{preset}"', "dataset.expressions_per_identity=2",
                                 "dataset.views_per_expression=1"])
        run_plan(cfg, identities, Path(d) / "plan", seed=seed)
        plan = load_plan(Path(d) / "plan")
        hm = HeadModel(plan.model_data())
        versions = {"synth": "-", "blender": "-", "python": "-"}
        for shard_id in plan.shard_ids():
            spec = plan.shard_spec(shard_id)
            for ident in spec.identities:
                i = ident.identity_index
                sc = IdentityScene(ident, hm, RenderSettings.from_json(plan.render_settings()), spec.run_seed,
                                   {"name": hm.data.name, "sha256": "-"}, versions)
                for e_i, e in enumerate(ident.expressions):
                    sc.set_expression(e)
                    tag = f"id{i:03d}_ex{e_i}"
                    for cls, rig in sorted(sc.rigs.items()):
                        for k, ob in enumerate(rig.objects):
                            arrays[f"{tag}/{cls}/{k}/{ob.name}"] = _evaluated_points(ob)
                        records[f"{tag}/{cls}"] = rig.record()
                    for name in HEAD_ATTRIBUTES:
                        a = _attribute(sc.head_ob, name)
                        if a is not None:
                            arrays[f"{tag}/head/{name}"] = a
                    records[f"{tag}/assets"] = sc.assets_record
                sc.close()
                bscene.reset()
    np.savez(out / "arrays.npz", **arrays)
    (out / "records.json").write_text(json.dumps(records, indent=1, sort_keys=True, default=str))
    classes = sorted({k.split("/")[1] for k in records if not k.endswith("/assets")})
    print(f"{out}: {len(arrays)} arrays, {len(records)} records; classes built: {', '.join(classes)}")


def compare(a: Path, b: Path) -> int:
    za, zb = np.load(a / "arrays.npz"), np.load(b / "arrays.npz")
    ra = json.loads((a / "records.json").read_text())
    rb = json.loads((b / "records.json").read_text())
    bad = 0
    for k in sorted(set(za.files) | set(zb.files)):
        if k not in za.files or k not in zb.files:
            print(f"{k}: only in {'B' if k not in za.files else 'A'}")
            bad += 1
            continue
        x, y = za[k], zb[k]
        if x.shape != y.shape or not np.array_equal(x, y, equal_nan=True):
            diff = np.abs(x - y).max() if x.shape == y.shape else f"shapes {x.shape} {y.shape}"
            print(f"{k}: differs (max |diff| {diff})")
            bad += 1
    for k in sorted(set(ra) | set(rb)):
        if ra.get(k) != rb.get(k):
            print(f"{k}: record differs")
            bad += 1
    print(f"{len(za.files)} arrays, {len(ra)} records compared: {bad} differ")
    return 1 if bad else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out", type=Path)
    d.add_argument("--identities", type=int, default=24)
    d.add_argument("--seed", type=int, default=3)
    d.add_argument("--preset", default="ci", help="render preset: its resolution sets the strand counts")
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args()
    if args.cmd == "dump":
        dump(args.out, args.identities, args.seed, args.preset)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
