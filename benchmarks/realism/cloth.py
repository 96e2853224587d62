"""Close-ups of the garments' folds and collars (docs/realism.md "Cloth").

    .venv/bin/python -m benchmarks.realism.cloth renders OUT_DIR [--tag after] [--res 256] [--spp 16]
    .venv/bin/python -m benchmarks.realism.cloth sheet OUT.png DIR [--tags before after] [--scale 0.75]
    .venv/bin/python -m benchmarks.realism.cloth cost [--repeats 3]
    .venv/bin/python -m benchmarks.realism.cloth stats

renders: four identities of the default model (codes at +-1 SD in a fixed sign pattern, one
  at 0), each in one garment (shirt with a collar, turtleneck, crew T-shirt, hoodie, coat),
  seen from the front and from 35 degrees to the side, framed on the chest (Cycles, CPU),
  written as sRGB PNGs ``<garment>_<view>_<tag>.png`` on mid-grey. Run once on the tree and
  once with ``PYTHONPATH`` at the tree before the change for the "before" images.
sheet: the renders of each tag side by side (a row per garment, before | after).
cost: per garment of the renders, the build (``garment_shell`` + ``fit_shell``) on the neutral
  head and one ``follow`` to a jaw opened 20 degrees (``jawOpen`` 1), the least of ``--repeats``
  runs (the machine is shared); only interfaces the tree before the change has too.
stats: on the neutral head and at +-3 SD (``asset_scene`` cases): per kind of drape, the folds'
  height (95th percentile of the displacement off the smooth shell in the waist band, the bridge
  apart) and the bridge's largest gap; the shirt collar's leaf: its gap over the shell and over
  the band (median, 99th percentile).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

#: (garment id, params, identity scale, sign offset, colour of the frame's sheet row)
LOOKS = (
    ("shirt_collar", {"tie": False, "top_button_open": False, "colour_hsv": "white", "fabric": "oxford"}, 1.0, 0),
    ("turtleneck", {"collar_height_m": 0.07, "fabric": "wool_knit", "colour_hsv": "grey"}, -1.0, 0),
    ("tshirt_crew", {"neckline_depth_m": 0.01, "colour_hsv": "navy"}, 0.0, 0),
    ("hoodie", {"hood_up": False, "drawstrings": True, "colour_hsv": "green", "fabric": "cotton_fleece"}, 1.0, 1),
    ("coat", {"collar_up": False, "fabric": "wool_felt", "colour_hsv": "camel"}, -1.0, 1),
)
VIEWS = {"front": (0.0, 0.0), "side": (35.0, 5.0)}


def _codes(hm, scale: float, shift: int):
    d = hm.data
    beta = scale * np.where((np.arange(d.identity_dims) + shift) % 2 == 0, 1.0, -1.0)
    return beta, np.zeros(d.expression_dims), np.zeros((hm.J, 3))


def _head(scale: float, shift: int):
    from blender_scripts import head as bhead
    from blender_scripts import materials as bmat
    from blender_scripts import scene as bscene
    from blender_scripts.assets import HeadContext
    from synth.appearance.skin import skin_albedo
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from tests.support.asset_scene import _ctx_arrays

    hm = HeadModel(load_default_model())
    bscene.reset()
    rest, verts, joints, lms = _ctx_arrays(hm, *_codes(hm, scale, shift))
    ctx = HeadContext(data=hm.data, head=None, materials={}, rest_vertices=rest, vertices=verts,
                      joint_transforms=joints, joint_index=dict(hm.joint_index), landmarks=lms, resolution=256,
                      identity_index=0, run_seed=0)
    ctx.materials = bmat.head_materials(None, skin_albedo(0.3, 0.015))
    ctx.head = bhead.build_head_object(hm.data, ctx.vertices, ctx.materials)
    return ctx


def renders(args) -> None:
    from blender_scripts import assets as basset
    from blender_scripts import camera, passes, scene
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world
    from synth.plan.records import RenderSettings

    from .eyes_garments import _save

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res = args.res
    only = set(args.only or [])
    with tempfile.TemporaryDirectory() as tmp:
        for aid, params, scale, shift in LOOKS:
            if only and aid not in only:
                continue
            ctx = _head(scale, shift)
            t = time.perf_counter()
            basset.dress(ctx, {"garment": {"id": aid, "params": params}})
            build = time.perf_counter() - t
            scene.configure_render(RenderSettings(samples=args.spp, denoise=args.spp > 32, device="cpu",
                                                  max_bounces=8), res, res)
            scene.uniform_environment(1.0)
            cam = camera.make_camera()
            lm = ctx.landmarks["ibug68"]
            target = np.array([0.0, float(lm[8, 1]) + 0.04, float(lm[8, 2]) - 0.15])
            for view, (az, el) in VIEWS.items():
                c2w = orbit_camera_to_world(az, el, 0.95, target)
                camera.set_camera(cam, intrinsics(res, res, 30.0), invert_rigid(c2w), res, res, 0.05, 10.0)
                r = passes.render_view(Path(tmp), 1)
                p = out / f"{aid}_{view}_{args.tag}.png"
                _save(p, r["rgba"])
                print(f"{aid} {view}: build {build:.2f} s, render {r['render_seconds']:.1f} s -> {p}")


def sheet(args) -> None:
    import imageio.v3 as iio

    d = Path(args.dir)
    rows = []
    for aid, *_ in LOOKS:
        tiles = [iio.imread(d / f"{aid}_{v}_{tag}.png")[..., :3] for tag in args.tags for v in VIEWS
                 if (d / f"{aid}_{v}_{tag}.png").exists()]
        if tiles:
            rows.append(np.concatenate(tiles, 1))
    if not rows:
        raise SystemExit(f"cloth sheet: no renders <garment>_<view>_<tag>.png in {d} for tags {args.tags}; "
                         "run `renders` first")
    w = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, w - r.shape[1]), (0, 0)), constant_values=128) for r in rows]
    img = np.concatenate(rows, 0)
    if args.scale != 1.0:
        from PIL import Image

        h, w = img.shape[:2]
        img = np.asarray(Image.fromarray(img).resize((round(w * args.scale), round(h * args.scale)), Image.LANCZOS))
    iio.imwrite(args.png, img)
    print(args.png)


def cost(args) -> None:
    from synth.assets.fit.body import Body, fit_shell
    from synth.assets.fit.garment import CLEARANCE, garment_shell
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from tests.support import asset_scene

    hm = HeadModel(load_default_model())
    ctx = asset_scene.head_arrays(hm, "neutral", resolution=256)
    beta, psi, rot = asset_scene._codes(hm, "neutral")
    names = list(hm.data.expression_names)
    if "jawOpen" in names:
        psi[names.index("jawOpen")] = 1.0
    rot[hm.joint_index["jaw"]] = (np.radians(20.0), 0.0, 0.0)
    moved = hm.evaluate(beta, psi, rot).vertices[0].astype(np.float64)
    for aid, params, *_ in LOOKS:
        build, follow, n = [], [], 0
        for _ in range(args.repeats):
            t = time.perf_counter()
            body = Body.of(ctx)
            s = fit_shell(body, garment_shell(body, {"id": aid, "params": params}, ctx.rng("garment")), CLEARANCE)
            build.append(time.perf_counter() - t)
            t = time.perf_counter()
            s.follow(moved, ctx.data.triangles)
            follow.append(time.perf_counter() - t)
            n = len(s.P)
        print(f"{aid}: build {min(build):.2f} s, follow {min(follow):.3f} s, {n} vertices")


def stats(args) -> None:
    from synth.assets.fit.body import Body, Parts
    from synth.assets.fit.collars import shirt_collar
    from synth.assets.fit.folds import DRAPES, Drape, Folds
    from synth.assets.fit.garment_parts import crew_neckline, torso_shell, vee_neckline
    from synth.geometry.sdf import SignedDistance
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from tests.support import asset_scene

    hm = HeadModel(load_default_model())
    base = 0.004
    for case in ("neutral", "id+3_brows", "id-3_brows"):
        body = Body.of(asset_scene.head_arrays(hm, case, resolution=256))
        row = []
        for kind, d in DRAPES.items():
            out = []
            for dr in (Drape(d.amp, d.wavelength, 0.0), Drape(0.0, d.wavelength, 0.0)):
                f = Folds(body, np.random.default_rng(0), base, dr)
                out.append(torso_shell(body, Parts(), crew_neckline(body, 0.008, 0.0), f, sleeves="short")[0])
            from scipy.spatial import cKDTree

            k = cKDTree(body.V).query(out[1])[1]
            hem, member = f.fields[k, 2], f.fields[k, 0]
            waist = (member < 0.1) & (hem > 0.015) & (hem < 0.06)
            disp = np.linalg.norm(out[0] - out[1], axis=1)
            row.append(f"{kind} {1000 * np.percentile(disp[waist], 95):.1f}")
        print(f"{case}: bridge gap max {1000 * body.bridge_gap.max():.1f} mm (uncapped); fold height p95 mm: "
              + ", ".join(row))
        for open_front in (False, True):
            parts = Parts()
            f = Folds(body, np.random.default_rng(1), base, DRAPES["shirt"])
            P, F, _ = torso_shell(body, parts, vee_neckline(body, 0.006, 0.045 if open_front else 0.0, 0.35), f)
            rec = shirt_collar(body, parts, 0, base, open_front, (P, F))
            G, ob, arcs = rec["rows"], rec["over_band"], rec["arcs"]
            hs = SignedDistance(P, F, sign="vertex").query(G[(ob == 0) & (arcs > 0)])
            gs = hs.signed[hs.distance < 0.006]
            hb = SignedDistance(parts.P[-3], parts.F[-3], sign="vertex").query(G[(ob == 1) & (arcs > 0.004)])
            gb = hb.signed[hb.distance < 0.006]
            print(f"  shirt collar{' (open)' if open_front else ''}: leaf over the shell {1000 * np.median(gs):.2f} / "
                  f"{1000 * np.percentile(gs, 99):.2f} mm (median / p99, {len(gs)} points), over the band "
                  f"{1000 * np.median(gb):.2f} / {1000 * np.percentile(gb, 99):.2f} mm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    r = sub.add_parser("renders")
    r.add_argument("out")
    r.add_argument("--tag", default="after")
    r.add_argument("--res", type=int, default=256)
    r.add_argument("--spp", type=int, default=16)
    r.add_argument("--only", nargs="*")
    s = sub.add_parser("sheet")
    s.add_argument("png")
    s.add_argument("dir")
    s.add_argument("--tags", nargs="+", default=["before", "after"])
    s.add_argument("--scale", type=float, default=1.0)
    c = sub.add_parser("cost")
    c.add_argument("--repeats", type=int, default=3)
    sub.add_parser("stats")
    args = ap.parse_args()
    {"renders": renders, "sheet": sheet, "cost": cost, "stats": stats}[args.what](args)


if __name__ == "__main__":
    main()
