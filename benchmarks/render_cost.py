"""Render cost at the production framing: speed against error, and what each asset class costs.

    python benchmarks/render_cost.py pick W [--candidates 300 --seed 11 --preset production]
    python benchmarks/render_cost.py study W             # reference, then STUDY's variants one by one
    python benchmarks/render_cost.py reference W [--full-spp 512 --crop-spp 4096 --cases ...]
    python benchmarks/render_cost.py variants W --variants base spp64 ad20 ... [--cases ...]
    python benchmarks/render_cost.py classes W            # base and hide<class> for each asset class
    python benchmarks/render_cost.py persistent W --views 5
    python benchmarks/render_cost.py score W              # PSNR / LPIPS / fringe (torch; no bpy)
    python benchmarks/render_cost.py report W [--plot docs/render_cost.png]

pick: plans ``--candidates`` identities at the preset and keeps the first identity of each costly
  case (long curly hair, braids, a full beard, glasses, a hat, bare skin: no hair, beard, glasses
  or headwear) that has an expression opening the jaw (jaw rotation + jawOpen >= 0.3); of it the
  least active expression and the one with the widest jaw opening, and of each the most frontal
  of its planned views: 12 frames, named ``<case>_<neutral|open>``.
reference: per frame a converged render (``--full-spp``, no denoising, no adaptive stop) and two
  crops rendered with Cycles' border at ``--crop-spp``: 128x128 (at 512x512; scaled with the
  resolution) over the eyes, brows and hairline (from the frame's landmarks) and over the hair
  silhouette at the top of the head (from the reference's alpha). Each is the mean of two renders
  at half the spp with independent seeds; their difference measures the reference's own noise,
  which ``score`` takes out of each error (``psnr_c``: corrected; ``ref_psnr``: the noise).
study: the reference, then every variant of ``--variants`` (default :data:`STUDY`) over all the
  frames before the next one, so an interrupted study has whole variants. ``--only open`` keeps
  the six open-mouth frames (a first stage at half the cost; the chosen settings are then checked
  on all twelve).
variants: every frame with each variant (``+``-joined parts of benchmarks/render.py's
  ``_apply_variant``: samples, adaptive threshold, denoiser, bounces, caustics, light tree, hair
  curve shape, subsurface, threads, tiles, persistent data, hidden classes).
score: against the references: PSNR (sRGB, alpha > 0.5) and LPIPS (the project's VGG LPIPS, on the
  colour composited over black) of the whole frame and of each crop, and the fringe RMSE.

Every stage keeps what it made under W (renders as ``W/renders/<variant>/<frame>.npz``) and skips it
when rerun, so a long study is run in pieces. All of a study's renders must come from one commit:
the first rendering stage records it in ``W/code.json`` and later ones refuse another commit or a
changed tree (run a long study from a worktree pinned at its commit). Times are Cycles' render call (scene sync, sampling,
denoising), the frames of one identity rendered in one scene, each variant after a dropped render
cache (benchmarks/render.py ``settings``' protocol).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from synth.io import atomic_write_json  # noqa: E402

#: the costly cases of the study: name -> test on an identity's assets ({class: AssetPick or None})
CASES = {
    "long_curly": lambda a: _id(a, "hair") == "long_curly",
    "braids": lambda a: _id(a, "hair") == "braids",
    "full_beard": lambda a: _id(a, "beard") in ("full_long", "short_full"),
    "glasses": lambda a: _id(a, "glasses") is not None,
    "hat": lambda a: _id(a, "headwear") is not None,
    "bare": lambda a: all(_id(a, c) is None for c in ("hair", "beard", "glasses", "headwear")),
}
CROP = 128  # crop side at 512x512
OPEN_JAW = 0.3  # an identity is used only if one of its expressions opens the jaw at least this much
CROP_NAMES = ("eyes", "hairline")
#: the study's variants in the order it renders them: today's production, then each knob alone
#: (samples, adaptive threshold, hair curve shape, bounces, light tree, subsurface, denoiser),
#: then the asset classes' cost (``hide<class>``)
STUDY = ("base", "spp64", "ad20", "ad50", "ribbons", "diff2+gloss2", "transp4", "nolt", "burley", "spp128",
         "dqbalanced+fastpf", "noguides", "nocaustics", "spp32", "hidehair", "hidebeard", "hideeyebrows",
         "hideeyelashes", "hideclothing", "hideglasses", "hideheadwear")


def _id(assets: dict, cls: str):
    pick = assets.get(cls)
    return None if pick is None else pick.id


def _frames_file(work: Path) -> Path:
    return work / "frames.json"


def code_version() -> dict:
    """The commit of this checkout and whether its tracked files differ from it (``git``; None
    outside a git checkout)."""
    import subprocess

    def git(*a: str) -> str | None:
        try:
            return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return None

    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": git("rev-parse", "HEAD"), "dirty": None if status is None else bool(status)}


def check_code(work: Path, force: bool = False) -> None:
    """Every render of a study must come from one version of the renderer: the first rendering
    stage records it (``W/code.json``), later ones refuse another commit or a changed tree
    (``--force`` takes the risk: references and variants from different code do not compare)."""
    f = work / "code.json"
    now = code_version()
    if not f.is_file():
        if now["dirty"]:
            raise SystemExit(f"render_cost: the checkout at {ROOT} has uncommitted changes to tracked files; commit "
                             "them (a study's renders must come from one known commit) or pass --force")
        atomic_write_json(f, now)
        return
    was = json.loads(f.read_text())
    if (was.get("commit") != now["commit"] or now["dirty"]) and not force:
        raise SystemExit(f"render_cost: {work} was rendered by commit {was.get('commit')}, this checkout is "
                         f"{now['commit']}{' with changes' if now['dirty'] else ''}: run the study from a worktree "
                         f"at that commit (git worktree add DIR {was.get('commit')}), or start a new work folder")


def load_frames(work: Path) -> dict:
    f = _frames_file(work)
    if not f.is_file():
        raise SystemExit(f"{f} not found: run `render_cost.py pick {work}` first")
    return json.loads(f.read_text())


# --------------------------------------------------------------------------- pick


def pick(args) -> None:
    from synth.config import load_config
    from synth.plan.io import load_plan
    from synth.plan.planner import run_plan

    work = Path(args.work)
    if _frames_file(work).is_file():
        print(f"{_frames_file(work)} exists: kept")
        return
    cfg = load_config(None, [f'render.preset="{args.preset}"', f"dataset.expressions_per_identity={args.expressions}",
                             f"dataset.views_per_expression={args.views}"])
    run_plan(cfg, args.candidates, work / "plan", seed=args.seed)
    plan = load_plan(work / "plan")
    names = list(plan.model_data().expression_names)

    def jaw(e) -> float:  # the jaw opening: the jaw joint's rotation, or the jawOpen component
        code = dict(zip(names, e.expression_code))
        return float(np.linalg.norm(e.joint_rotations.get("jaw", (0.0, 0.0, 0.0)))) + abs(code.get("jawOpen", 0.0))

    chosen: dict[str, tuple[str, object]] = {}
    for sid in plan.shard_ids():  # in identity order: the first identity of each case, each used once
        ident = plan.shard_spec(sid).identities[0]
        if max(jaw(e) for e in ident.expressions) < OPEN_JAW:
            continue
        for case, test in CASES.items():
            if case not in chosen and test(ident.assets):
                chosen[case] = (sid, ident)
                break
    missing = sorted(set(CASES) - set(chosen))
    if missing:
        raise SystemExit(f"no identity among {args.candidates} candidates for {missing}: raise --candidates")
    frames = []
    for case in CASES:
        sid, ident = chosen[case]
        exprs = list(ident.expressions)
        neutral = min(exprs, key=lambda e: (e.kind != "neutral", round(float(np.abs(e.expression_code).sum()), 9),
                                            e.expression_index))
        others = [e for e in exprs if e is not neutral]
        opened = max(others, key=lambda e: (round(jaw(e), 9), -e.expression_index))
        for tag, e in (("neutral", neutral), ("open", opened)):
            f = min(e.frames, key=lambda f: (round(abs(f.camera.azimuth_deg) + abs(f.camera.elevation_deg), 6),
                                             f.view_index))
            frames.append({"name": f"{case}_{tag}", "case": case, "shard": sid, "expression_index": e.expression_index,
                           "frame_id": f.frame_id, "jaw": round(jaw(e), 6),
                           "assets": sorted(c for c, p in ident.assets.items() if p is not None)})
    atomic_write_json(_frames_file(work), {"plan": "plan", "seed": args.seed, "preset": args.preset,
                                           "frames": frames})
    for f in frames:
        print(f"{f['name']:20s} {f['frame_id']}  jaw {f['jaw']:.3f}  {', '.join(f['assets'])}")


# --------------------------------------------------------------------------- rendering


def _scenes(work: Path, cases: list[str] | None, expressions: list[str] | None = None):
    """(frames of one identity, its IdentityScene) in turn, for the frames of ``cases`` whose
    expression tag (``neutral``, ``open``) is in ``expressions`` (None: all)."""
    from blender_scripts import scene as bscene
    from blender_scripts.worker import IdentityScene, software_versions
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan
    from synth.plan.records import RenderSettings

    meta = load_frames(work)
    plan = load_plan(work / meta["plan"])
    hm = HeadModel(plan.model_data())
    by_shard: dict[str, list[dict]] = {}
    for f in meta["frames"]:
        if (not cases or f["case"] in cases) and (not expressions or f["name"].rsplit("_", 1)[1] in expressions):
            by_shard.setdefault(f["shard"], []).append(f)
    for sid, frames in by_shard.items():
        spec = plan.shard_spec(sid)
        ident = spec.identities[0]
        sc = IdentityScene(ident, hm, RenderSettings.from_json(plan.render_settings()), spec.run_seed,
                           {"name": hm.data.name, "sha256": plan.model_sha256()}, software_versions(), sid)
        exprs = {e.expression_index: e for e in ident.expressions}
        todo = []
        for f in frames:
            e = exprs[f["expression_index"]]
            todo.append((f, e, next(x for x in e.frames if x.frame_id == f["frame_id"])))
        try:
            yield todo, sc
        finally:
            sc.close()
            bscene.reset()


def _set_border(window: tuple[int, int, int, int] | None, width: int, height: int) -> None:
    """Render only ``window`` = (x0, y0, x1, y1) in pixels, y down (None: the whole frame)."""
    import bpy

    r = bpy.context.scene.render
    r.use_border = window is not None
    r.use_crop_to_border = False
    if window is not None:
        x0, y0, x1, y1 = window
        r.border_min_x, r.border_max_x = x0 / width, x1 / width
        r.border_min_y, r.border_max_y = 1.0 - y1 / height, 1.0 - y0 / height


def crop_windows(landmarks_2d, alpha: np.ndarray) -> dict[str, tuple[int, int, int, int]]:
    """The two crop windows of a frame (x0, y0, x1, y1, y down), inside the image: over the eyes,
    brows and hairline (centred between the eyes, its lower edge a fifth below the eye line), and
    over the hair silhouette (centred on the top of the head's outline in the middle column)."""
    h, w = alpha.shape
    side = max(16, round(CROP * w / 512))
    lm = np.asarray(landmarks_2d, np.float64)
    eyes, brows = lm[36:48], lm[17:27]
    cx = float(eyes[:, 0].mean())
    bottom = float(eyes[:, 1].mean()) + 0.2 * side
    cols = np.flatnonzero((alpha > 0.5).any(axis=0))
    mid = int(round(cx)) if cols.size == 0 else int(np.clip(round(cx), cols.min(), cols.max()))
    rows = np.flatnonzero(alpha[:, mid] > 0.5)
    top = float(rows.min()) if rows.size else float(brows[:, 1].min()) - side

    def box(x: float, y: float) -> tuple[int, int, int, int]:
        x0 = int(np.clip(round(x - side / 2), 0, w - side))
        y0 = int(np.clip(round(y - side / 2), 0, h - side))
        return x0, y0, x0 + side, y0 + side

    return {"eyes": box(cx, bottom - side / 2), "hairline": box(cx - side / 4, top)}


def _save(path: Path, **arrays) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(path)


#: seed offsets of the two halves of a reference (distinct from every frame's own seed stream)
REF_SEEDS = (1_000_003, 2_000_003)


def _render_halves(sc, fr, tmp: Path, window, stem: Path) -> dict:
    """The two halves of a reference (each at the configured spp, its own seed), each kept as
    ``<stem>.h<k>.npz`` so an interrupted study loses at most one half; returns the halves."""
    halves = []
    for k, off in enumerate(REF_SEEDS):
        hp = stem.with_name(f"{stem.name}.h{k}.npz")
        if not hp.is_file():
            out, fj = sc.render(fr, tmp, seed=int(fr.seed) + off)
            rgba = out["rgba"]
            if window is not None:
                x0, y0, x1, y1 = window
                rgba = rgba[y0:y1, x0:x1]
            _save(hp, rgba=rgba.astype(np.float32), seconds=out["render_seconds"],
                  cpu_seconds=out.get("render_cpu_seconds", np.nan), landmarks_2d=np.asarray(fj["landmarks_2d"]))
            print(f"  {stem.name} half {k}: {out['render_seconds']:.0f} s", file=sys.stderr)
        halves.append(np.load(hp))
    return halves


def _combine(path: Path, halves, **extra) -> None:
    """The reference = the mean of its two halves; ``half_diff`` = their difference (RGBA), from
    which :func:`ref_noise_mse` estimates the reference's own noise."""
    a, b = halves[0]["rgba"], halves[1]["rgba"]
    _save(path, rgba=(0.5 * (a + b)).astype(np.float32), half_diff=(a - b).astype(np.float32),
          landmarks_2d=halves[0]["landmarks_2d"],
          seconds=float(halves[0]["seconds"]) + float(halves[1]["seconds"]), **extra)


def reference(args) -> None:
    """Per frame a converged full render and two crops, each the mean of two renders at half the
    spp with independent seeds (no denoising, no adaptive stop)."""
    import dataclasses

    from blender_scripts import scene as bscene

    work = Path(args.work)
    check_code(work, args.force)
    with tempfile.TemporaryDirectory(prefix="synth-cost-") as d:
        for todo, sc in _scenes(work, args.cases, args.expressions_only):
            for f, e, fr in todo:
                full = work / "ref" / f"{f['name']}.npz"
                crops = [work / "ref" / f"{f['name']}_{c}.npz" for c in CROP_NAMES]
                if full.is_file() and all(p.is_file() for p in crops):
                    continue
                sc.set_expression(e)
                cfg = dataclasses.replace(sc.render_cfg, samples=max(1, args.full_spp // 2), denoise=False,
                                          adaptive_sampling=False)
                bscene.configure_render(cfg, sc.width, sc.height)
                _set_border(None, sc.width, sc.height)
                if not full.is_file():
                    _combine(full, _render_halves(sc, fr, Path(d), None, full.with_suffix("")),
                             spp=args.full_spp)
                ref = np.load(full)
                windows = crop_windows(ref["landmarks_2d"], ref["rgba"][..., 3])
                cfg = dataclasses.replace(cfg, samples=max(1, args.crop_spp // 2))
                bscene.configure_render(cfg, sc.width, sc.height)
                for name, path in zip(CROP_NAMES, crops):
                    if path.is_file():
                        continue
                    _set_border(windows[name], sc.width, sc.height)
                    _combine(path, _render_halves(sc, fr, Path(d), windows[name], path.with_suffix("")),
                             window=np.array(windows[name]), spp=args.crop_spp)
                _set_border(None, sc.width, sc.height)
                for p in (work / "ref").glob(f"{f['name']}*.h[01].npz"):
                    p.unlink()


#: a ``hide<class>`` part's class as a frame's asset list names it
_ASSET_OF = {"clothing": "garment"}


def _shows(variant: str, frame: dict) -> bool:
    """Whether ``variant`` changes ``frame``: a variant that hides classes only where the frame has
    one of them (hiding what is not there would time the base again)."""
    hidden = [p[4:] for p in variant.split("+") if p.startswith("hide")]
    return not hidden or any(_ASSET_OF.get(c, c) in frame["assets"] for c in hidden)


def variants(args, variant_list: list[str]) -> None:
    from benchmarks.render import _apply_variant, engine_defaults
    from blender_scripts import scene as bscene

    work = Path(args.work)
    check_code(work, args.force)
    defaults, undo = None, []
    with tempfile.TemporaryDirectory(prefix="synth-cost-") as d:
        for n, (todo, sc) in enumerate(_scenes(work, args.cases, args.expressions_only)):
            defaults = defaults or engine_defaults()
            for v in (variant_list if n % 2 == 0 else variant_list[::-1]):
                mine = [t for t in todo if _shows(v, t[0])]
                if not mine:
                    continue
                paths = [work / "renders" / v / f"{f['name']}.npz" for f, _, _ in mine]
                if all(p.is_file() for p in paths):
                    continue
                _apply_variant(v, sc, defaults, undo)
                bscene.drop_render_cache()
                for (f, e, fr), path in zip(mine, paths):
                    if path.is_file():
                        continue
                    sc.set_expression(e)
                    out, _ = sc.render(fr, Path(d))
                    _save(path, rgba=out["rgba"].astype(np.float16), seconds=out["render_seconds"],
                          cpu_seconds=out.get("render_cpu_seconds", np.nan))
                    print(f"  {f['name']} {v}: {out['render_seconds']:.1f} s", file=sys.stderr)
            _apply_variant("base", sc, defaults, undo)


def persistent(args) -> None:
    """Seconds per view (wall, and CPU under ``<variant>_cpu``) over ``--views`` views of each
    neutral expression, with and without Cycles' persistent data (BVH and shaders kept between
    the views of one scene)."""
    from benchmarks.render import _apply_variant, engine_defaults
    from blender_scripts import scene as bscene

    work = Path(args.work)
    check_code(work, args.force)
    out_file = work / "persistent.json"
    res = json.loads(out_file.read_text()) if out_file.is_file() else {}
    undo: list = []
    with tempfile.TemporaryDirectory(prefix="synth-cost-") as d:
        for todo, sc in _scenes(work, args.cases, args.expressions_only):
            defaults = engine_defaults()
            f, e, _ = todo[0]
            if f["name"] in res:
                continue
            sc.set_expression(e)
            row = {}
            for v in ("base", "nopd"):
                _apply_variant(v, sc, defaults, undo)
                bscene.drop_render_cache()
                outs = [sc.render(fr, Path(d))[0] for fr in e.frames[: args.views]]
                row[v] = [o["render_seconds"] for o in outs]
                row[v + "_cpu"] = [o["render_cpu_seconds"] for o in outs]
            res[f["name"]] = row
            atomic_write_json(out_file, res)
            _apply_variant("base", sc, defaults, undo)


# --------------------------------------------------------------------------- score and report


def _srgb(x: np.ndarray) -> np.ndarray:
    """Colour over black, sRGB in [0, 1] (float64)."""
    from synth.appearance.srgb import linear_to_srgb

    return np.clip(linear_to_srgb(np.clip(x[..., :3].astype(np.float64), 0, None)), 0, 1)


def ref_noise_mse(ref: np.ndarray, half_diff: np.ndarray, mask: np.ndarray) -> float:
    """The reference's own noise, as the sRGB mean squared error it adds to any comparison with
    it: its halves A, B = ref +- half_diff / 2 are independent, so var(mean) = E[(A - B)^2] / 4."""
    a, b = _srgb(ref + 0.5 * half_diff), _srgb(ref - 0.5 * half_diff)
    return float(np.mean((a - b)[mask] ** 2) / 4.0) if mask.any() else 0.0


def psnr_vs_ref(img: np.ndarray, ref: np.ndarray, half_diff: np.ndarray | None, mask: np.ndarray) -> tuple:
    """(PSNR against the reference, the same with the reference's noise taken out of the error,
    the reference's own noise as a PSNR), sRGB over ``mask``. The correction subtracts the noise
    estimate from the measured MSE (an independent-noise identity), floored at a tenth of it."""
    mse = float(np.mean((_srgb(img) - _srgb(ref))[mask] ** 2)) if mask.any() else 0.0
    noise = 0.0 if half_diff is None else ref_noise_mse(ref, half_diff, mask)
    db = lambda m: float("inf") if m <= 0 else 10.0 * np.log10(1.0 / m)  # noqa: E731
    return db(mse), db(max(mse - noise, 0.1 * noise) if noise > 0 else mse), db(noise)


def score(args) -> None:
    from benchmarks.render import fringe_rmse
    from prior.metrics import lpips

    work = Path(args.work)
    out_file = work / "scores.json"
    scores = json.loads(out_file.read_text()) if out_file.is_file() else {}

    def srgb(x: np.ndarray) -> np.ndarray:
        return _srgb(x).astype(np.float32)

    def compare(mine: np.ndarray, refz, prefix: str, row: dict) -> None:
        ref = refz["rgba"]
        hd = refz["half_diff"] if "half_diff" in refz.files else None
        raw, corr, noise = psnr_vs_ref(mine, ref, hd, ref[..., 3] > 0.5)
        row[f"psnr{prefix}"], row[f"psnr_c{prefix}"], row[f"ref_psnr{prefix}"] = raw, corr, noise
        row[f"lpips{prefix}"] = float(lpips(srgb(mine), srgb(ref)))

    for vdir in sorted((work / "renders").glob("*")):
        for path in sorted(vdir.glob("*.npz")):
            key = f"{vdir.name}/{path.stem}"
            if key in scores:
                continue
            img = np.load(path)
            refz = np.load(work / "ref" / f"{path.stem}.npz")
            rgba = img["rgba"].astype(np.float32)
            row = {"seconds": float(img["seconds"]),
                   "cpu_seconds": float(img["cpu_seconds"]) if "cpu_seconds" in img.files else float("nan"),
                   "fringe": fringe_rmse(rgba, refz["rgba"])}
            compare(rgba, refz, "", row)
            for c in CROP_NAMES:
                cp = work / "ref" / f"{path.stem}_{c}.npz"
                if cp.is_file():
                    cr = np.load(cp)
                    x0, y0, x1, y1 = (int(v) for v in cr["window"])
                    compare(rgba[y0:y1, x0:x1], cr, f"_{c}", row)
            scores[key] = row
            atomic_write_json(out_file, scores)
            print(f"  {key}: {row['seconds']:.1f} s, {row['psnr_c']:.2f} dB, LPIPS {row['lpips']:.4f}", file=sys.stderr)


#: a variant is "within" today's production when, over the frames they share, its mean PSNR (noise
#: corrected, whole frame and each crop) is at most this much lower and its mean LPIPS at most
#: LPIPS_TOL higher (issue 41's acceptance rule for the new presets)
PSNR_TOL, LPIPS_TOL = 0.5, 0.01
METRICS = ("psnr_c", "lpips", "psnr_c_eyes", "psnr_c_hairline", "lpips_eyes", "lpips_hairline", "fringe")


def compare_to_base(by_v: dict[str, dict[str, dict]], base: str = "base") -> list[dict]:
    """Per variant, paired with ``base`` over the frames both have: CPU and wall seconds per frame
    and their ratio to the base's, the metrics' means and their differences, and whether it is
    within the tolerances. Sorted by CPU time."""
    ref = by_v.get(base, {})
    rows = []
    for v, frames in by_v.items():
        common = sorted(f for f in frames if f in ref)
        if not common:
            continue
        mean = lambda rows_, k: float(np.nanmean([rows_[f].get(k, np.nan) for f in common]))  # noqa: E731
        cpu = lambda rows_: float(np.nansum([rows_[f].get("cpu_seconds", np.nan) for f in common]))  # noqa: E731
        wall = lambda rows_: float(sum(rows_[f]["seconds"] for f in common))  # noqa: E731
        r = {"variant": v, "frames": len(common), "cpu_s": cpu(frames) / len(common), "wall_s": wall(frames) / len(common),
             "cpu_ratio": cpu(frames) / cpu(ref) if cpu(ref) > 0 else float("nan"), "wall_ratio": wall(frames) / wall(ref)}
        for k in METRICS:
            r[k] = mean(frames, k)
            r["d_" + k] = r[k] - mean(ref, k)
        psnr_ok = all(not (r["d_" + k] < -PSNR_TOL) for k in ("psnr_c", "psnr_c_eyes", "psnr_c_hairline"))
        lpips_ok = all(not (r["d_" + k] > LPIPS_TOL) for k in ("lpips", "lpips_eyes", "lpips_hairline"))
        r["within"] = bool(psnr_ok and lpips_ok)
        rows.append(r)
    return sorted(rows, key=lambda r: (r["cpu_ratio"], r["variant"]))


def report(args) -> None:
    work = Path(args.work)
    scores = json.loads((work / "scores.json").read_text())
    by_v: dict[str, dict[str, dict]] = {}
    for key, row in scores.items():
        v, frame = key.split("/", 1)
        by_v.setdefault(v, {})[frame] = row
    base = by_v.get("base", {})
    if base:
        noise = {k: float(np.nanmean([r.get(k, np.nan) for r in base.values()]))
                 for k in ("ref_psnr", "ref_psnr_eyes", "ref_psnr_hairline")}
        print(f"references' own noise (PSNR of their mean against the truth, estimated from their halves): "
              f"frame {noise['ref_psnr']:.2f} dB, eyes crop {noise['ref_psnr_eyes']:.2f} dB, "
              f"hairline crop {noise['ref_psnr_hairline']:.2f} dB\n")
    rows = compare_to_base(by_v)
    print("| variant | frames | CPU s / frame | CPU / base | wall / base | PSNR dB | Δ | eyes PSNR | Δ | hairline PSNR | Δ "
          "| LPIPS | Δ | eyes LPIPS | hairline LPIPS | fringe RMSE | within |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---:|")
    for r in rows:
        print(f"| {r['variant']} | {r['frames']} | {r['cpu_s']:.1f} | {r['cpu_ratio']:.3f} | {r['wall_ratio']:.3f} | "
              f"{r['psnr_c']:.2f} | {r['d_psnr_c']:+.2f} | {r['psnr_c_eyes']:.2f} | {r['d_psnr_c_eyes']:+.2f} | "
              f"{r['psnr_c_hairline']:.2f} | {r['d_psnr_c_hairline']:+.2f} | {r['lpips']:.4f} | {r['d_lpips']:+.4f} | "
              f"{r['lpips_eyes']:.4f} | {r['lpips_hairline']:.4f} | {r['fringe']:.4f} | {'yes' if r['within'] else 'no'} |")
    if args.plot and rows:
        import matplotlib
        import matplotlib.ticker

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        # speed against error, each variant paired with the base over the frames both have; the classes'
        # cost (hide<class>) is a table, not a setting, and is left out
        pts = [r for r in rows if not r["variant"].startswith("hide") and "threads" not in r["variant"]]
        fig, ax = plt.subplots(1, 2, figsize=(12, 5))
        panels = ((ax[0], "d_psnr_c", "d_psnr_c_eyes", "PSNR - base's (dB; frame •, eyes crop ×)", -PSNR_TOL),
                  (ax[1], "d_lpips", "d_lpips_eyes", "LPIPS - base's (frame •, eyes crop ×)", LPIPS_TOL))
        for a, k, k_eyes, label, tol in panels:
            a.axhline(tol, color="tab:red", lw=0.8, ls="--")
            a.axhline(0.0, color="black", lw=0.5)
            for n, r in enumerate(sorted(pts, key=lambda r: r["cpu_ratio"])):
                col = "tab:green" if r["within"] else "tab:grey"
                a.scatter(r["cpu_ratio"], r[k], s=16, c=col)
                a.scatter(r["cpu_ratio"], r[k_eyes], s=14, c=col, marker="x")
                a.annotate(f"{r['variant']} ({r['frames']})", (r["cpu_ratio"], r[k]), fontsize=5.5,
                           xytext=(3, 6 if n % 2 else -9), textcoords="offset points")
            a.set_xscale("log")
            a.set_xticks([0.125, 0.25, 0.5, 1.0, 1.5], ["1/8", "1/4", "1/2", "1", "1.5"])
            a.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            a.set_xlabel("Cycles CPU time / base's (log)")
            a.set_ylabel(label)
        ax[0].set_title("green: within 0.5 dB and 0.01 LPIPS of the base (dashed: the limit)", fontsize=8)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=130)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("pick", "reference", "study", "variants", "classes", "persistent", "score",
                                     "report"))
    ap.add_argument("work")
    ap.add_argument("--candidates", type=int, default=300)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--preset", default="production-max", help="the preset of the planned frames: the study's base")
    ap.add_argument("--expressions", type=int, default=13)
    ap.add_argument("--views", type=int, default=30, help="pick: views planned per expression; persistent: views timed")
    ap.add_argument("--full-spp", type=int, default=512)
    ap.add_argument("--crop-spp", type=int, default=4096)
    ap.add_argument("--variants", nargs="+", default=None)
    ap.add_argument("--cases", nargs="+", choices=sorted(CASES), default=None)
    ap.add_argument("--only", dest="expressions_only", nargs="+", choices=("neutral", "open"), default=None,
                    help="only the frames of these expressions (the study's first stage: --only open)")
    ap.add_argument("--plot", default=None)
    ap.add_argument("--force", action="store_true", help="render into a study made by another commit (they do not compare)")
    args = ap.parse_args()
    if args.what == "pick":
        pick(args)
    elif args.what == "reference":
        reference(args)
    elif args.what == "study":
        reference(args)
        for v in args.variants or STUDY:
            variants(args, [v])
    elif args.what == "variants":
        variants(args, args.variants or ["base"])
    elif args.what == "classes":
        from benchmarks.render import HIDEABLE

        variants(args, ["base"] + [f"hide{c}" for c in HIDEABLE])
    elif args.what == "persistent":
        persistent(args)
    elif args.what == "score":
        score(args)
    else:
        report(args)


if __name__ == "__main__":
    main()
