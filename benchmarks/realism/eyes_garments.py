"""Before/after figures for the eyes, skin detail and garments (docs/realism-eyes-garments.md).

    .venv/bin/python -m benchmarks.realism.eyes_garments crops OUT_DIR [--tag after] [--spp 16]
    .venv/bin/python -m benchmarks.realism.eyes_garments cost [--identities 3 --views 2 --repeats 2]

Run it once on the tree to measure and once with ``PYTHONPATH`` pointing at the tree before the
change (the script uses only interfaces both have) for the "before" column.

crops: 256x256 close-ups (Cycles, CPU): the left eye from the front at 0.25 m (12 degree field:
  ~0.2 mm per pixel, so pores are resolved) with a hazel iris, and the garment's hem at the
  arm cut seen from the side and a little below (tshirt_crew on the neutral head), written as
  sRGB PNGs ``eye_<tag>.png`` and ``garment_<tag>.png`` (background mid-grey).
cost: the `preview` preset's Cycles time per frame (scene sync, sampling, denoising:
  ``render_seconds``) over planned identities with all their assets, each frame rendered
  ``--repeats`` times (the minimum is kept: the machine is shared).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from synth.plan.records import RenderSettings

from .common import planned_options


def _save(path: Path, rgba: np.ndarray) -> None:
    import imageio.v3 as iio

    from synth.appearance.srgb import srgb8

    a = rgba[..., 3:4]
    iio.imwrite(path, srgb8(np.clip(rgba[..., :3], 0, None) * a + 0.214 * (1 - a)))  # linear 0.214: sRGB mid-grey


def crops(args) -> None:
    from blender_scripts import assets as basset
    from blender_scripts import camera, passes, scene
    from synth.assets.fit.eyes import eye_coordinates
    from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world
    from tests.support import asset_scene

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res = 256
    with tempfile.TemporaryDirectory() as tmp:
        ctx, _ = asset_scene.head_context("neutral")
        basset.dress(ctx, {"iris": {"id": "hazel", "params": {"melanin": 0.5, "central_heterochromia": 0.5,
                                                               "limbal_ring": 0.6, "pupil_dilation": 0.4}},
                           "skin": {"id": "procedural_skin", "params": {"pore_scale": 1.0, "wrinkle_depth": 0.5,
                                                                        "freckles": 0.2, "oiliness": 0.3}},
                           "garment": {"id": "tshirt_crew", "params": {"colour_hsv": "navy"}}})
        _, info = eye_coordinates(ctx.data, ctx.rest_vertices)
        scene.configure_render(RenderSettings(samples=args.spp, denoise=False, device="cpu", max_bounces=8), res, res)
        scene.uniform_environment(1.0)
        cam = camera.make_camera()
        shots = {"eye": (intrinsics(res, res, 12.0), orbit_camera_to_world(0.0, 0.0, 0.25, np.array(info["l"]["centre"]))),
                 "garment": (intrinsics(res, res, 20.0), orbit_camera_to_world(75.0, -15.0, 0.45,
                                                                               np.array([0.17, -0.02, 0.5])))}
        for name, (K, c2w) in shots.items():
            camera.set_camera(cam, K, invert_rigid(c2w), res, res, 0.05, 10.0)
            r = passes.render_view(Path(tmp), 1)
            _save(out / f"{name}_{args.tag}.png", r["rgba"])
            print(f"{name}: {r['render_seconds']:.1f} s -> {out / f'{name}_{args.tag}.png'}")


def cost(args) -> None:
    from benchmarks import render as rb

    from synth.model.head import HeadModel

    with tempfile.TemporaryDirectory(prefix="synth-bench-") as d:
        tmp = Path(d)
        plan = rb._plan_one(tmp, args.identities, "preview", args.views, args.seed)
        hm = HeadModel(plan.model_data())
        times = []
        for sid in plan.shard_ids()[: args.identities]:
            sc, ident = rb._scene(plan, sid, hm)
            for f in ident.expressions[0].frames:
                t = [sc.render(f, tmp)[0]["render_seconds"] for _ in range(args.repeats)]
                times.append(min(t))
            sc.close()
    t = np.array(times)
    print(f"preview Cycles s/frame over {len(t)} frames: mean {t.mean():.2f}, median {np.median(t):.2f}, "
          f"per frame {np.round(t, 2).tolist()}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    c = sub.add_parser("crops")
    c.add_argument("out")
    c.add_argument("--tag", default="after")
    c.add_argument("--spp", type=int, default=16)
    k = planned_options(sub.add_parser("cost"), 3)
    k.add_argument("--views", type=int, default=2)
    k.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    {"crops": crops, "cost": cost}[args.what](args)


if __name__ == "__main__":
    main()
