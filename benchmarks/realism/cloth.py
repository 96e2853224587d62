"""Close-ups of the garments' folds and collars (docs/realism.md "Cloth").

    .venv/bin/python -m benchmarks.realism.cloth renders OUT_DIR [--tag after] [--res 256] [--spp 16]
    .venv/bin/python -m benchmarks.realism.cloth sheet OUT.png DIR [--tags before after]
    .venv/bin/python -m benchmarks.realism.cloth measure [--repeats 3]

renders: four identities of the default model (codes at +-1 SD in a fixed sign pattern, one
  at 0), each in one garment (shirt with a collar, turtleneck, crew T-shirt, hoodie, coat),
  seen from the front and from 35 degrees to the side, framed on the chest (Cycles, CPU),
  written as sRGB PNGs ``<garment>_<view>_<tag>.png`` on mid-grey. Run once on the tree and
  once with ``PYTHONPATH`` at the tree before the change for the "before" images.
sheet: the renders of each tag side by side (a row per garment, before | after).
measure: the fold statistics, collar gaps, build and ``follow`` time of each garment on the
  neutral head and at +-3 SD (pure numpy).
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
    w = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, w - r.shape[1]), (0, 0)), constant_values=128) for r in rows]
    iio.imwrite(args.png, np.concatenate(rows, 0))
    print(args.png)


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
    args = ap.parse_args()
    {"renders": renders, "sheet": sheet}[args.what](args)


if __name__ == "__main__":
    main()
