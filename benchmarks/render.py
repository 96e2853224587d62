"""Rendering benchmarks. Prints Markdown tables for docs/performance.md.

    .venv/bin/python benchmarks/render.py overhead [--identities 1 --expressions 2 --views 15]
    .venv/bin/python benchmarks/render.py quality  [--views 2 --reference-spp 1024]
    .venv/bin/python benchmarks/render.py memory   [--scenes 20]
    .venv/bin/python benchmarks/render.py settings --plan PLAN [--variants base fastpf spp14 ...]
    .venv/bin/python benchmarks/render.py all

overhead: the whole `synth render` (planning, worker start, model load, scene and asset
  build, EXR + JSON writing, commit) at the `preview` preset, over the time spent inside
  Cycles' render call (``render_seconds`` in the worker's events: scene sync, sampling,
  denoising). Target <= 1.10.
quality: speed against error. One planned identity (with its assets) at 256x256; spp in
  {4, 16, 64, 256} x denoiser {off, on}, PSNR against a high-spp, non-denoised reference,
  over the pixels the reference's alpha covers (> 0.5), on sRGB-encoded RGB clipped to [0, 1].
settings: Cycles settings against the preset's, on every frame of a plan's first expression
  per identity (``--identities``): seconds in Cycles' render call and PSNR / fringe RMSE against
  a ``--reference-spp`` render (denoised), paired per frame. Variants are ``+``-joined parts:
  base, sppN, adN (adaptive threshold N/1000), noad, adminN (adaptive minimum samples),
  nodenoise, fastpf (denoising prefilter FAST), dqbalanced / dqfast (OIDN quality), noguides
  (OIDN without albedo/normal), diffN / glossN / transN / transpN / maxN (bounces), nocaustics,
  blurglossyN (N/10), nolt (no light tree), guiding (path guiding, CPU), thick / ribbons (hair
  curve shape), burley (skin subsurface), sssrN (skin subsurface radius N %), nbcloth / nbskin (no bump on cloth / skin),
  threadsN, tileN, nopd (no persistent data), hide<class> (hair, beard, eyebrows, eyelashes,
  clothing, glasses, headwear). Each identity renders its variants
  in turn (reversed every other identity), each from a dropped render cache.
memory: RSS of one process building, rendering (1 view, ci preset) and resetting 20
  identity scenes in turn (what a worker does between recycles).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def machine() -> str:
    return f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


# --------------------------------------------------------------------------- overhead

def overhead(args) -> None:
    from renderer_jobs.local import LocalBackend
    from renderer_jobs.submit import prepare_plan, render_plan

    rows = []
    for views in args.views:
        with tempfile.TemporaryDirectory(prefix="synth-bench-") as d:
            out = Path(d) / "ds"
            t0 = time.perf_counter()
            pdir = prepare_plan(out, args.identities, None,
                                [f"dataset.expressions_per_identity={args.expressions}",
                                 f"dataset.views_per_expression={views}", f'render.preset="{args.preset}"'],
                                args.seed, None)
            t_plan = time.perf_counter() - t0
            res = render_plan(out, pdir, LocalBackend(workers=1), shards_per_worker=2, quiet=True)
            total = time.perf_counter() - t0
        n = res["frames_rendered"]
        rows.append((args.identities, args.expressions, views, n, total, t_plan, res["render_seconds"],
                     total / max(res["render_seconds"], 1e-9), n / total))
    print(f"\n### Pipeline overhead at `{args.preset}` ({machine()})\n")
    print("| identities | expressions | views | frames | total s | planning s | Cycles s | total / Cycles | frames/s |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]:.1f} | {r[5]:.2f} | {r[6]:.1f} | {r[7]:.3f} | {r[8]:.2f} |")


# --------------------------------------------------------------------------- scenes

def _plan_one(tmp: Path, n: int, preset: str, views: int, seed: int):
    from synth.config import load_config
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan

    cfg = load_config(None, [f'render.preset="{preset}"', "dataset.expressions_per_identity=1",
                             f"dataset.views_per_expression={views}"])
    run_plan(cfg, n, tmp / "plan", seed=seed)
    return load_plan(tmp / "plan")


def _scene(plan, shard_id: str, hm, render_cfg=None):
    from blender_scripts.worker import IdentityScene, software_versions
    from synth.plan.records import RenderSettings

    spec = plan.shard_spec(shard_id)
    ident = spec.identities[0]
    sc = IdentityScene(ident, hm, render_cfg or RenderSettings.from_json(plan.render_settings()), spec.run_seed,
                       {"name": hm.data.name, "sha256": plan.model_sha256()}, software_versions(), shard_id)
    sc.set_expression(ident.expressions[0])
    return sc, ident


def psnr_masked(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    from synth.appearance.srgb import linear_to_srgb

    a = np.clip(linear_to_srgb(np.clip(img[..., :3].astype(np.float64), 0, None)), 0, 1)[mask]
    b = np.clip(linear_to_srgb(np.clip(ref[..., :3].astype(np.float64), 0, None)), 0, 1)[mask]
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(1.0 / mse)


def fringe_rmse(img: np.ndarray, ref: np.ndarray, background: float = 0.5) -> float:
    """RMS error (linear) of the image composited over a grey ``background`` against the
    reference's, over the reference's fringe pixels (0.02 < alpha < 0.98: hair ends, the
    silhouette), where a noisy alpha shows."""
    a = ref[..., 3]
    m = (a > 0.02) & (a < 0.98)
    comp = lambda x: x[..., :3].astype(np.float64) + (1.0 - x[..., 3:4].astype(np.float64)) * background  # noqa: E731
    return float(np.sqrt(np.mean((comp(img) - comp(ref))[m] ** 2))) if m.any() else 0.0


def quality(args) -> None:
    from blender_scripts import scene as bscene
    from synth.model.head import HeadModel

    with tempfile.TemporaryDirectory(prefix="synth-bench-") as d:
        tmp = Path(d)
        plan = _plan_one(tmp, 1, "preview", args.views, args.seed)
        hm = HeadModel(plan.model_data())
        sc, ident = _scene(plan, "shard_000000", hm)
        frames = ident.expressions[0].frames[: args.views]

        def render_all(spp: int, denoise: bool):
            bscene.configure_render(dataclasses.replace(sc.render_cfg, samples=spp, denoise=denoise,
                                                        adaptive_sampling=False), sc.width, sc.height)
            outs, secs = [], 0.0
            for f in frames:
                t0 = time.perf_counter()
                out, _ = sc.render(f, tmp)
                secs += time.perf_counter() - t0
                outs.append(out)
            return outs, secs / len(frames)

        ref, ref_s = render_all(args.reference_spp, False)
        masks = [r["rgba"][..., 3] > 0.5 for r in ref]
        rows = []
        for spp in args.spp:
            for dn in (False, True):
                outs, s = render_all(spp, dn)
                p = np.mean([psnr_masked(o["rgba"], r["rgba"], m) for o, r, m in zip(outs, ref, masks)])
                fr = np.mean([fringe_rmse(o["rgba"], r["rgba"]) for o, r in zip(outs, ref)])
                rows.append((spp, dn, s, p, fr))
                print(f"  spp {spp:4d} denoise {dn!s:5}: {s:6.2f} s/frame, PSNR {p:.2f} dB, fringe {fr:.4f}",
                      file=sys.stderr)
    assets = sorted(c for c, e in ident.assets.items() if e)
    print(f"\n### Speed against error at 256x256 ({machine()})\n")
    print(f"Identity 0 of seed {args.seed} with assets: {', '.join(assets)}; {args.views} views; reference "
          f"{args.reference_spp} spp without denoising ({ref_s:.1f} s/frame). PSNR over the reference's "
          "alpha > 0.5 pixels, sRGB-encoded, clipped to [0, 1]; fringe: RMS error (linear) composited over "
          "grey, over the reference's pixels with 0.02 < alpha < 0.98.\n")
    print("| spp | denoiser | s / frame | PSNR (dB) | fringe RMSE |")
    print("|---:|:---:|---:|---:|---:|")
    for spp, dn, s, p, fr in rows:
        print(f"| {spp} | {'OIDN' if dn else 'off'} | {s:.2f} | {p:.2f} | {fr:.4f} |")


# --------------------------------------------------------------------------- settings

_DEFAULTS = ("diffuse_bounces", "glossy_bounces", "transmission_bounces", "transparent_max_bounces",
             "volume_bounces", "use_light_tree", "denoising_prefilter", "denoising_quality", "denoising_input_passes",
             "caustics_reflective", "caustics_refractive", "blur_glossy", "tile_size", "use_auto_tile",
             "adaptive_min_samples", "use_guiding", "use_surface_guiding", "use_deterministic_guiding")
#: segmentation classes a ``hide<class>`` variant part can hide (benchmarks/render_cost.py's cost per class)
HIDEABLE = ("hair", "beard", "eyebrows", "eyelashes", "clothing", "glasses", "headwear")


def _hide_class(cls: str, undo: list) -> None:
    """Hide from the render every object all of whose materials belong to ``cls``."""
    import bpy

    from synth.dataset.segmentation import CLASSES

    for ob in bpy.data.objects:
        mats = [s.material for s in getattr(ob, "material_slots", ()) if s.material is not None]
        if mats and all(m.pass_index == CLASSES[cls] for m in mats) and not ob.hide_render:
            ob.hide_render = True
            undo.append(lambda ob=ob: setattr(ob, "hide_render", False))


def _apply_variant(variant: str, sc, defaults: dict, undo: list) -> None:
    """Configure the preset's render settings, then the variant's parts (see ``settings``)."""
    import bpy

    from blender_scripts import scene as bscene

    while undo:  # links removed by nbcloth / nbskin, subsurface methods changed by burley
        undo.pop()()
    parts = variant.split("+")
    cfg = dataclasses.replace(sc.render_cfg, denoise=False) if "nodenoise" in parts else sc.render_cfg
    bscene.configure_render(cfg, sc.width, sc.height)  # also the compositor's alpha denoiser, on or off
    scene = bpy.context.scene
    c = scene.cycles
    for k, v in defaults.items():
        if k == "curve_shape":
            scene.cycles_curves.shape = v
        else:
            setattr(c, k, v)
    for part in parts:
        if part in ("base", "nodenoise"):
            continue
        head = part.rstrip("0123456789")
        num = int(part[len(head):]) if part[len(head):] else None
        attr = {"spp": "samples", "diff": "diffuse_bounces", "gloss": "glossy_bounces", "tile": "tile_size",
                "trans": "transmission_bounces", "transp": "transparent_max_bounces", "max": "max_bounces",
                "admin": "adaptive_min_samples"}
        if head in attr and num is not None:
            setattr(c, attr[head], num)
            if head == "tile":
                c.use_auto_tile = True
        elif head == "ad" and num is not None:  # adaptive sampling, threshold in thousandths
            c.use_adaptive_sampling, c.adaptive_threshold = True, num / 1000.0
        elif part == "noad":
            c.use_adaptive_sampling = False
        elif head == "threads" and num is not None:
            scene.render.threads_mode, scene.render.threads = "FIXED", num
        elif part == "nopd":
            scene.render.use_persistent_data = False
        elif part == "noguides":
            c.denoising_input_passes = "RGB"
        elif part == "nocaustics":
            c.caustics_reflective = c.caustics_refractive = False
        elif head == "blurglossy" and num is not None:  # in tenths
            c.blur_glossy = num / 10.0
        elif part in ("thick", "ribbons"):
            scene.cycles_curves.shape = part.upper()
        elif part.startswith("hide") and part[4:] in HIDEABLE:
            _hide_class(part[4:], undo)
        elif head == "sssr" and num is not None:  # skin subsurface radius in percent of the planned
            for m in bpy.data.materials:
                for n in (m.node_tree.nodes if m.node_tree else ()):
                    if n.bl_idname == "ShaderNodeBsdfPrincipled" and n.inputs["Subsurface Weight"].default_value > 0:
                        sock = n.inputs["Subsurface Scale"]
                        old = sock.default_value
                        sock.default_value = old * num / 100.0
                        undo.append(lambda sock=sock, old=old: setattr(sock, "default_value", old))
        elif part == "fastpf":
            c.denoising_prefilter = "FAST"
        elif part in ("dqbalanced", "dqfast"):
            c.denoising_quality = part[2:].upper()
        elif part == "nolt":
            c.use_light_tree = False
        elif part == "guiding":  # path guiding (Open PGL, CPU only): surfaces, deterministic training
            c.use_guiding, c.use_surface_guiding, c.use_deterministic_guiding = True, True, True
        elif part in ("burley", "nbcloth", "nbskin"):
            for m in bpy.data.materials:
                for n in (m.node_tree.nodes if m.node_tree else ()):
                    if n.bl_idname != "ShaderNodeBsdfPrincipled":
                        continue
                    cloth = m.get("fabric") is not None
                    sss = n.inputs["Subsurface Weight"].default_value > 0
                    if part == "burley" and n.subsurface_method == "RANDOM_WALK":
                        n.subsurface_method = "BURLEY"
                        undo.append(lambda n=n: setattr(n, "subsurface_method", "RANDOM_WALK"))
                    elif (part == "nbcloth" and cloth) or (part == "nbskin" and sss and not cloth):
                        for link in list(n.inputs["Normal"].links):
                            a, b, nt = link.from_socket, n.inputs["Normal"], m.node_tree
                            nt.links.remove(link)
                            undo.append(lambda a=a, b=b, nt=nt: nt.links.new(a, b))
        else:
            raise SystemExit(f"unknown variant part {part!r} (see benchmarks/render.py's docstring)")


def engine_defaults() -> dict:
    """The Cycles settings a variant may change, as the scene has them (restored before each variant)."""
    import bpy

    scene = bpy.context.scene
    return {**{k: getattr(scene.cycles, k) for k in _DEFAULTS}, "curve_shape": scene.cycles_curves.shape}


def settings(args) -> None:
    import bpy

    from blender_scripts import scene as bscene
    from blender_scripts.worker import IdentityScene, software_versions
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan
    from synth.plan.records import RenderSettings

    plan = load_plan(args.plan)
    hm = HeadModel(plan.model_data())
    variants = list(args.variants)
    rows: dict[str, list] = {v: [] for v in variants}
    defaults, undo = None, []
    with tempfile.TemporaryDirectory(prefix="synth-bench-") as d:
        tmp = Path(d)
        for n, sid in enumerate(plan.shard_ids()[: args.identities]):
            spec = plan.shard_spec(sid)
            ident = spec.identities[0]
            sc = IdentityScene(ident, hm, RenderSettings.from_json(plan.render_settings()), spec.run_seed,
                               {"name": hm.data.name, "sha256": plan.model_sha256()}, software_versions(), sid)
            sc.set_expression(ident.expressions[0])
            if defaults is None:
                defaults = engine_defaults()
            frames = ident.expressions[0].frames
            _apply_variant("base", sc, defaults, undo)
            bscene.configure_render(dataclasses.replace(sc.render_cfg, samples=args.reference_spp, denoise=True),
                                    sc.width, sc.height)
            bscene.drop_render_cache()
            ref = [sc.render(f, tmp)[0]["rgba"] for f in frames]
            for v in (variants if n % 2 == 0 else variants[::-1]):
                _apply_variant(v, sc, defaults, undo)
                bscene.drop_render_cache()
                for f, r in zip(frames, ref):
                    out, _ = sc.render(f, tmp)
                    rows[v].append((out["render_seconds"], psnr_masked(out["rgba"], r, r[..., 3] > 0.5),
                                    fringe_rmse(out["rgba"], r)))
                    print(f"  {sid} {f['seed']} {v}: {out['render_seconds']:.2f} s", file=sys.stderr)
            _apply_variant("base", sc, defaults, undo)
            sc.close()
            bscene.reset()
    base = np.array([x[0] for x in rows[variants[0]]])
    print(f"\n### Render settings against the `{plan.render_settings().get('preset')}` preset ({machine()})\n")
    print(f"{len(base)} frames of {args.plan}; error against {args.reference_spp} spp, denoised; times paired "
          f"per frame against `{variants[0]}`.\n")
    print("| variant | s / frame (mean) | time / first, median of frames | time / first, sums | PSNR (dB) | fringe RMSE |")
    print("|---|---:|---:|---:|---:|---:|")
    for v in variants:
        t = np.array([x[0] for x in rows[v]])
        print(f"| {v} | {t.mean():.2f} | {np.median(t / base):.3f} | {t.sum() / base.sum():.3f} | "
              f"{np.mean([x[1] for x in rows[v]]):.2f} | {np.mean([x[2] for x in rows[v]]):.4f} |")


# --------------------------------------------------------------------------- memory

def memory(args) -> None:
    from synth.io.process import rss_mb
    from synth.model.head import HeadModel

    with tempfile.TemporaryDirectory(prefix="synth-bench-") as d:
        tmp = Path(d)
        plan = _plan_one(tmp, args.scenes, "ci", 1, args.seed)
        hm = HeadModel(plan.model_data())
        rss = []
        for k, sid in enumerate(plan.shard_ids()):
            sc, ident = _scene(plan, sid, hm)
            sc.render(ident.expressions[0].frames[0], tmp)
            sc.close()
            rss.append(rss_mb())
            print(f"  scene {k + 1:2d}: RSS {rss[-1]:.0f} MB", file=sys.stderr)
    r = np.asarray(rss)
    half = len(r) // 2
    slope = np.polyfit(np.arange(half, len(r)), r[half:], 1)[0] if len(r) >= 4 else float("nan")
    print(f"\n### Worker memory over {len(r)} scenes (`ci`, one view each; {machine()})\n")
    print("| scene | " + " | ".join(str(i + 1) for i in range(0, len(r), max(1, len(r) // 10))) + " |")
    print("|---|" + "---:|" * len(range(0, len(r), max(1, len(r) // 10))))
    print("| RSS (MB) | " + " | ".join(f"{r[i]:.0f}" for i in range(0, len(r), max(1, len(r) // 10))) + " |")
    print(f"\nFirst {r[0]:.0f} MB, last {r[-1]:.0f} MB, peak {r.max():.0f} MB; growth over the second half "
          f"{slope:+.2f} MB per scene.")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("overhead", "quality", "memory", "settings", "all"))
    ap.add_argument("--plan", help="settings: a plan directory (synth plan)")
    ap.add_argument("--variants", nargs="+", default=["base", "fastpf", "spp14", "dqbalanced", "burley"])
    ap.add_argument("--identities", type=int, default=1)
    ap.add_argument("--expressions", type=int, default=2)
    ap.add_argument("--views", type=int, nargs="+", default=None)
    ap.add_argument("--preset", default="preview")
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16, 64, 256])
    ap.add_argument("--reference-spp", type=int, default=1024)
    ap.add_argument("--scenes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.what in ("overhead", "all"):
        a = argparse.Namespace(**vars(args))
        a.views = args.views or [5, 15]
        overhead(a)
    if args.what in ("quality", "all"):
        a = argparse.Namespace(**vars(args))
        a.views = (args.views or [2])[0]
        quality(a)
    if args.what in ("memory", "all"):
        memory(args)
    if args.what == "settings":
        if not args.plan:
            ap.error("settings needs --plan")
        a = argparse.Namespace(**vars(args))
        a.reference_spp = args.reference_spp if args.reference_spp != 1024 else 128
        settings(a)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    main()
