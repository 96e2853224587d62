"""Realism measurements (issue 13, part A). Prints Markdown tables for docs/realism.md.

    .venv/bin/python benchmarks/realism.py skin [--identities 200 --seed 0] [--frames DATASET ...]
    .venv/bin/python benchmarks/realism.py framing DATASET [DATASET ...]
    .venv/bin/python benchmarks/realism.py body-end DATASET [DATASET ...]
    .venv/bin/python benchmarks/realism.py shoulders [--identities 40 --seed 0 --garments tshirt_crew ...]
        [--hair long_straight ... --hair-identities 6]
    .venv/bin/python benchmarks/realism.py hair [--identities 12 --seed 0 --style braids]
    .venv/bin/python benchmarks/realism.py hats [--identities 3 --seed 0 --resolution 256]
    .venv/bin/python benchmarks/realism.py judge DATASET [--mp-python PY] [--max-azimuth 45]
        [--detections MP.json]
    .venv/bin/python benchmarks/realism.py jaw DATASET [--detections MP.json]
    .venv/bin/python benchmarks/realism.py mapping [--relax convex 1e-2 1e-3 ...] [--dataset D --detections MP.json]
    .venv/bin/python benchmarks/realism.py timing DATASET [DATASET ...]
    .venv/bin/python benchmarks/realism.py fringe REFERENCE DATASET [DATASET ...]

skin: the ITA histogram (six categories) and the CIELAB range of the skin albedo of the planned
  identities (``synth.appearance.skin.skin_albedo``, what the worker gives the shader); with
  ``--frames``, the same figures for the mean skin-class pixel of each rendered frame whose camera
  is within 30 degrees of frontal (uniform environment), next to its albedo.
framing: the fraction of frames in which head classes touch the left, right or top image
  border: eyes, mouth, teeth, hair, beard, brows, lashes, glasses, headwear anywhere on those
  borders, or skin on the top row or on the side columns above the chin (ibug68 point 8; skin
  below it is neck and bust).
body-end: the fraction of frames in which the body ends inside the image: no skin or clothing
  pixel on the bottom row while the frame shows skin or clothing (the bust's lower end floating
  in the frame; a portrait's body leaves through the bottom border), overall and by camera
  elevation.
shoulders: the body's breadth over the head's for planned identities (neutral) and garments: the
  widest extent side to side of the garment and the body below it, without and with the arms
  (synth.assets.fit.torso.arms), over the breadth of the scalp; next to bideltoid over head
  breadth of measured adults (Pheasant's tables); and hair (--hair styles, tshirt_crew) through
  the arms as groomed and after synth.assets.fit.torso.keep_strands_out.
hair: strands in front of the inner face (synth.assets.fit.occlusion) for the planned hair of
  identities that have hair, seen from cameras at azimuth 0, +-30, +-45 (elevation 0); with
  --style S, of the first --identities planned identities whose hair is S.
scalp: skin seen between hair strands above the brows, its luminance over the face skin's
  and the hair's, by hair colour (docs/realism.md, "The scalp under the hair").
hats: hair under a beanie or cap, groomed without and with the hat: strands, share of hair points
  beyond the hat's cut plane (through its crown), groom seconds.
judge: mediapipe 0.10.21 (the fit extra; benchmarks/mediapipe_judge.py, in a subprocess) on the frames
  whose camera azimuth is within --max-azimuth, composited over mid grey: face-detection
  rate, face-mesh rate, and the error of its points (shifted by +0.5 px to synth's pixel
  convention) against the frame's ``landmarks_2d``, in units of the inter-ocular distance
  (outer eye corners, ibug 36-45): 68-point NME with and without the jaw, per region and by
  azimuth (its mesh mapped to ibug68, benchmarks/realism_judge.py), the issue's direct 7-point
  error (eye corners, nose tip, mouth corners) and mediapipe against itself on the mirrored
  image. --detections caches mediapipe's output.
mapping: the judge's mediapipe -> ibug68 mapping for each ridge --relax (or convex): its error on
  held-out model samples and, given a dataset and the judge's cached detections, on those frames.
timing: Cycles seconds per frame (the worker's frame events).
fringe: datasets against a reference of the same plan rendered with more samples: RMS error of
  the composite over grey and of the alpha on the reference's fringe pixels (0.02 < alpha <
  0.98), and of the whole composite (median over frames).
plot-skin OUT --inputs A.json B.json --labels before after: ITA histogram and L*-b* plot.
sheet OUT DATASET ...: the most frontal frame of the first identities, one row per dataset.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CATS = ("very light", "light", "intermediate", "tan", "brown", "dark")
HEAD_NOT_SKIN = (2, 3, 4, 5, 6, 7, 8, 10, 11)  # synth.dataset.segmentation.CLASSES, skin = 1


def _lab_table(lab: np.ndarray, ita: np.ndarray) -> None:
    from synth.appearance.skin import ita_category

    h = np.bincount(ita_category(ita), minlength=6)
    print("| " + " | ".join(CATS) + " |\n|" + "---:|" * 6)
    print("| " + " | ".join(str(int(x)) for x in h) + " |\n")
    print("| | min | median | max |\n|---|---:|---:|---:|")
    for k, name in enumerate(("L*", "a*", "b*")):
        print(f"| {name} | {lab[:, k].min():.1f} | {np.median(lab[:, k]):.1f} | {lab[:, k].max():.1f} |")
    print(f"| ITA | {ita.min():.1f} | {np.median(ita):.1f} | {ita.max():.1f} |\n")


def _lips_table(assets, lab: np.ndarray, ita: np.ndarray) -> dict:
    """The lips' albedo (synth.appearance.lips) against the skin's, by ITA category: CIELAB
    lightness, chroma and hue differences (median, min..max)."""
    from synth.appearance.lips import lip_albedo
    from synth.appearance.skin import cielab, ita_category

    lips = cielab(np.array([lip_albedo(a["skin"]["params"]["melanin"], a["skin"]["params"]["haemoglobin"])
                            for a in assets]))

    def lch(x):
        return x[:, 0], np.hypot(x[:, 1], x[:, 2]), np.degrees(np.arctan2(x[:, 2], x[:, 1]))

    (ls, cs, hs), (ll, cl, hl) = lch(lab), lch(lips)
    d = {"dL": ll - ls, "dC": cl - cs, "dh": hl - hs}
    cat = ita_category(ita)
    print("Lips against the skin (lip albedo minus skin albedo, CIELAB; median, min..max):\n")
    print("| ITA category | identities | lips L\\* | ΔL\\* | ΔC\\* | Δh, degrees |\n|---|---:|---:|---:|---:|---:|")
    for k, name in enumerate(CATS):
        m = cat == k
        if not m.any():
            continue
        cells = [f"{np.median(v[m]):+.1f} ({v[m].min():+.1f}..{v[m].max():+.1f})" for v in d.values()]
        print(f"| {name} | {int(m.sum())} | {np.median(ll[m]):.1f} | " + " | ".join(cells) + " |")
    print()
    return {"lab": lips.tolist(), **{k: v.tolist() for k, v in d.items()}}


def skin(args) -> dict:
    from synth.appearance.skin import cielab, individual_typology_angle, skin_albedo
    from synth.assets.catalogue import load_catalogue
    from synth.config import load_config
    from synth.plan.assets import sample_assets_batch

    ids = np.arange(args.identities)
    cfg = load_config()
    assets = sample_assets_batch(args.seed, ids, load_catalogue(None))
    try:
        from synth.plan.skin import apply_skin_tones
        apply_skin_tones(args.seed, ids, assets, cfg.skin)
    except ImportError:  # before the skin-tone sampling existed
        pass
    alb = np.array([skin_albedo(a["skin"]["params"]["melanin"], a["skin"]["params"]["haemoglobin"]) for a in assets])
    lab, ita = cielab(alb), individual_typology_angle(alb)
    print(f"\n### Skin albedo of {len(ids)} planned identities (seed {args.seed})\n")
    _lab_table(lab, ita)
    out = {"albedo": {"lab": lab.tolist(), "ita": ita.tolist()}, "lips": _lips_table(assets, lab, ita)}
    if args.frames:
        rows = _skin_pixels(args.frames)
        if rows:
            a, p = np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
            ita_a, ita_p = individual_typology_angle(a), individual_typology_angle(p)
            print(f"### Mean skin pixel of {len(rows)} near-frontal frames (uniform environment)\n")
            _lab_table(cielab(p), ita_p)
            print(f"ITA of the mean skin pixel vs ITA of the albedo: correlation "
                  f"{np.corrcoef(ita_a, ita_p)[0, 1]:.3f}, median difference {np.median(ita_p - ita_a):+.1f} deg, "
                  f"category agreement {np.mean(_cat(ita_a) == _cat(ita_p)):.0%}\n")
            out["pixels"] = {"albedo_ita": ita_a.tolist(), "pixel_ita": ita_p.tolist(), "pixel_lab": cielab(p).tolist()}
    return out


def _cat(ita):
    from synth.appearance.skin import ita_category

    return ita_category(ita)


def _polygon_mask(poly: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W) pixels whose centres (synth convention, +0.5) lie inside the polygon (pixels)."""
    y, x = np.mgrid[0:height, 0:width] + 0.5
    inside = np.zeros((height, width), bool)
    p = np.asarray(poly, np.float64)
    for (x0, y0), (x1, y1) in zip(p, np.roll(p, -1, axis=0)):  # even-odd rule, rays toward +x
        crosses = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (x < xc)
    return inside


def _skin_pixels(sources) -> list:
    from synth.dataset.reader import iter_frames

    rows = []
    for src in sources:
        for fr in iter_frames(src):
            c = fr.meta["camera"]
            if abs(c["azimuth_deg"]) > 30 or abs(c["elevation_deg"]) > 30 or fr.meta.get("skin") is None:
                continue
            m = (fr.segmentation == 1) & (fr.alpha > 0.99)
            lm = np.asarray(fr.meta["landmarks_2d"], np.float64)
            m &= ~_polygon_mask(lm[48:60], fr.height, fr.width)  # the lips have their own colour
            # the face only: rows above the chin (ibug 8), so neck and bust do not count
            chin = float(lm[8, 1])
            m[int(np.clip(chin, 0, fr.height)):] = False
            if m.sum() < 20:
                continue
            rows.append((fr.meta["skin"]["albedo_linear_srgb"], fr.rgb[m].mean(axis=0)))
    return rows


def touches_border(seg: np.ndarray, chin_y: float) -> bool:
    """Head classes on the left, right or top border (see the module doc)."""
    top, left, right = seg[0], seg[:, 0], seg[:, -1]
    if np.isin(np.concatenate([top, left, right]), HEAD_NOT_SKIN).any() or (top == 1).any():
        return True
    above = slice(0, int(np.clip(np.floor(chin_y), 0, seg.shape[0])))
    return bool((left[above] == 1).any() or (right[above] == 1).any())


BODY = (1, 9)  # skin (neck, bust) and clothing
ELEVATION_BANDS = ((-90.0, -15.0), (-15.0, 15.0), (15.0, 45.0), (45.0, 90.0))


def body_ends_in_frame(seg: np.ndarray) -> bool:
    """The body (skin, clothing) is in the frame but does not reach its bottom row."""
    body = np.isin(seg, BODY)
    return bool(body.any() and not body[-1].any())


def body_end(args) -> dict:
    from synth.dataset.reader import iter_frames

    out = {}
    bands = " | ".join(f"elevation {a:+.0f} to {b:+.0f}" for a, b in ELEVATION_BANDS)
    print(f"\n| dataset | frames | body ends in the frame | {bands} |")
    print("|---|---:|---:|" + "---:|" * len(ELEVATION_BANDS))
    for src in args.datasets:
        rows = [(body_ends_in_frame(fr.segmentation), float(fr.meta["camera"]["elevation_deg"]))
                for fr in iter_frames(src)]
        flags = np.array([r[0] for r in rows], bool)
        el = np.array([r[1] for r in rows])
        cells, per = [], {}
        for a, b in ELEVATION_BANDS:
            m = (el >= a) & (el < b) if b < 90 else (el >= a)
            per[f"{a:+.0f}..{b:+.0f}"] = [int(flags[m].sum()), int(m.sum())]
            cells.append(f"{flags[m].sum()}/{m.sum()}")
        out[src] = {"frames": len(flags), "ends_in_frame": int(flags.sum()), "by_elevation": per}
        print(f"| {src} | {len(flags)} | {flags.sum()} ({flags.mean():.0%}) | " + " | ".join(cells) + " |")
    return out


def framing(args) -> dict:
    from synth.dataset.reader import iter_frames

    out = {}
    print("\n| dataset | frames | head at the border | fraction | any skin counted (neck, bust) |")
    print("|---|---:|---:|---:|---:|")
    for src in args.datasets:
        flags, loose = [], []
        for fr in iter_frames(src):
            flags.append(touches_border(fr.segmentation, float(np.asarray(fr.meta["landmarks_2d"])[8, 1])))
            loose.append(touches_border(fr.segmentation, fr.height))
        out[src] = {"frames": len(flags), "touching": int(sum(flags)), "touching_any_skin": int(sum(loose))}
        print(f"| {src} | {len(flags)} | {sum(flags)} | {np.mean(flags):.1%} | {np.mean(loose):.1%} |")
    return out


def _planned_heads(seed: int, n: int, ids=None):
    """(model, HeadModel, identity indices, identity codes) of the first n planned identities
    (or of the identities ``ids``)."""
    from synth.config import load_config
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from synth.plan import identities

    model = load_default_model()
    cfg = load_config()
    ids = np.arange(n) if ids is None else np.asarray(ids, np.int64)
    codes = identities.sample_identities(seed, ids, identities.prior_of(model),
                                         identities.truncation_radius(model.identity_dims, cfg.identity))
    return model, HeadModel(model, np.float64), ids, codes


def _neutral_context(model, hm, code, identity: int, seed: int, resolution: int, assets: dict):
    """(the rigs' HeadContext of an identity's neutral head, its evaluation)."""
    from blender_scripts.assets import HeadContext

    ev = hm.evaluate(code, np.zeros(model.expression_dims), np.zeros((hm.J, 3)))
    verts = ev.vertices[0]
    ctx = HeadContext(data=model, head=None, materials={}, rest_vertices=verts, vertices=verts,
                      joint_transforms=ev.joint_transforms[0], joint_index=dict(hm.joint_index),
                      landmarks={k: v[0] for k, v in ev.landmarks.items()}, resolution=resolution,
                      identity_index=identity, run_seed=seed, assets=assets)
    return ctx, ev


def hats(args) -> dict:
    """Hair under headwear: for planned identities, each hair style a hat may go with and each
    hat, the groom without the hat (as before 2026-12-01) and with it: strands, the share of
    hair points beyond the hat's cut plane (through the crown), groom seconds."""
    import time

    from synth.assets.fit.hair import groom
    from synth.assets.fit.headwear import CUT_RAISE_M, headwear_cut

    model, hm, ids, codes = _planned_heads(args.seed, args.identities)
    styles = ("buzz_cut", "short_straight", "short_curly", "undercut", "medium_wavy", "bob")
    print(f"\n### Hair under headwear ({len(ids)} identities of seed {args.seed}, {args.resolution} px strand density)\n")
    print("| hat | style | strands without / with the hat | hair points beyond the cut plane without / with | "
          "groom s without / with |\n|---|---|---:|---:|---:|")
    rows = []
    for hat in CUT_RAISE_M:
        for sid in styles:
            acc = np.zeros(6)
            for n, i in enumerate(ids.tolist()):
                for k, with_hat in enumerate((False, True)):
                    ctx, _ = _neutral_context(model, hm, codes[n], i, args.seed, args.resolution,
                                              {"headwear": {"id": hat}} if with_hat else {})
                    o, nrm = headwear_cut(ctx.vertices, model.regions, ctx.landmarks["ibug68"], {"id": hat})
                    t = time.perf_counter()
                    g = groom(ctx, {"id": sid, "params": {}})
                    acc[4 + k] += time.perf_counter() - t
                    acc[k] += len(g.pts)
                    acc[2 + k] += float(np.mean((g.pts - o) @ nrm > 0.0)) / len(ids)
            rows.append({"hat": hat, "style": sid, "strands": acc[:2].tolist(), "beyond": acc[2:4].tolist(),
                         "seconds": acc[4:].tolist()})
            print(f"| {hat} | {sid} | {acc[0]:.0f} / {acc[1]:.0f} | {acc[2]:.1%} / {acc[3]:.1%} | "
                  f"{acc[4]:.2f} / {acc[5]:.2f} |")
    return {"rows": rows}


def hair(args) -> dict:
    import importlib

    from synth.assets.catalogue import load_catalogue
    from synth.assets.fit.occlusion import inner_face_triangles, strands_in_front_of_face
    from synth.conventions import spherical_offset
    from synth.plan.assets import sample_assets_batch

    cat = load_catalogue(None)
    if args.style:  # the first planned identities with that style, with their planned parameters
        pool = np.arange(args.identities * 400)
        pool_assets = sample_assets_batch(args.seed, pool, cat)
        pick = [i for i in pool.tolist() if (pool_assets[i].get("hair") or {}).get("id") == args.style][:args.identities]
        if not pick:
            raise SystemExit(f"hair: no identity of seed {args.seed} among the first {len(pool)} has hair "
                             f"'{args.style}'; check the style's name (assets_manifest/hair.toml)")
        model, hm, ids, codes = _planned_heads(args.seed, len(pick), pick)
        assets = [pool_assets[i] for i in pick]
    else:
        model, hm, ids, codes = _planned_heads(args.seed, args.identities)
        assets = sample_assets_batch(args.seed, ids, cat)
    az = np.array([0.0, -30.0, 30.0, -45.0, 45.0])
    print(f"\n### Hair strands in front of the inner face (seed {args.seed}, 64 px strand density"
          + (f"; the first {len(ids)} identities with {args.style}" if args.style else "") + ")\n")
    print("| identity | style | strands | in front of the inner face, az 0 / -30 / +30 / -45 / +45 | "
          "of its centre (eyes, nose, mouth) |\n|---:|---|---:|---|---|")
    rows = []
    for n, i in enumerate(ids.tolist()):
        entry = assets[n].get("hair")
        if entry is None:
            continue
        ctx, ev = _neutral_context(model, hm, codes[n], i, args.seed, 64, assets[n])
        verts = ev.vertices[0]
        g = importlib.import_module("synth.assets.fit.hair").groom(ctx, entry)
        lm = ev.landmarks["ibug68"][0]
        cams = 0.5 * (lm[36] + lm[45]) + 1.0 * spherical_offset(az, np.zeros_like(az))
        r = strands_in_front_of_face(g.pts, cams, verts, inner_face_triangles(model, verts, lm))
        rc = strands_in_front_of_face(g.pts, cams, verts, inner_face_triangles(model, verts, lm, centre_only=True))
        rows.append({"identity": i, "style": entry["id"], "strands": len(g.pts), "in_front": r["strands"].tolist(),
                     "in_front_centre": rc["strands"].tolist()})
        print(f"| {i} | {entry['id']} | {len(g.pts)} | {' / '.join(str(x) for x in r['strands'])} | "
              f"{' / '.join(str(x) for x in rc['strands'])} |")
    views = sum(len(r["in_front"]) for r in rows)
    bad = sum(int(x > 0) for r in rows for x in r["in_front"])
    bad_c = sum(int(x > 0) for r in rows for x in r["in_front_centre"])
    print(f"\nviews with any strand in front of the inner face: {bad}/{views}; of its centre: {bad_c}/{views}\n")
    return {"rows": rows, "views": views, "views_with_strands_in_front": bad, "views_centre": bad_c}


#: bideltoid and head breadth (mm; mean, SD) of British adults 19-65 (Pheasant, "Bodyspace", the
#: tables reproduced in the City University of Hong Kong's online anthropometry, items 17 and 27)
BIDELTOID_MM = {"men": (465.0, 28.0), "women": (395.0, 24.0)}
HEAD_BREADTH_MM = {"men": (155.0, 6.0), "women": (145.0, 6.0)}


def shoulders(args) -> dict:
    """The body's breadth against the head's (docs/realism.md, "Arms"): for planned identities
    (neutral), each garment of ``--garments``, the widest extent side to side of the garment
    and the body below it, without the arms (as before 2026-12-01) and with them
    (synth.assets.fit.torso.arms), over the head's breadth (its scalp, above the ears), against
    bideltoid over head breadth of measured adults."""
    from synth.assets.fit import torso
    from synth.assets.fit.body import Body, fit_shell
    from synth.assets.fit.garment import CLEARANCE, garment_shell

    model, hm, ids, codes = _planned_heads(args.seed, args.identities)
    scalp = np.asarray(model.regions["scalp"])
    print(f"\n### Body breadth over head breadth ({len(ids)} identities of seed {args.seed}, neutral)\n")
    ref = {k: BIDELTOID_MM[k][0] / HEAD_BREADTH_MM[k][0] for k in BIDELTOID_MM}
    print("measured adults (bideltoid / head breadth of the means): "
          + ", ".join(f"{k} {v:.2f}" for k, v in ref.items()) + "\n")
    print("| garment | head breadth mm (min / median / max) | body breadth mm without / with arms (median) | "
          "ratio without arms (min / median / max) | ratio with arms (min / median / max) |\n|---|---:|---:|---:|---:|")
    rows = []
    for gid in args.garments:
        m = []
        for n, i in enumerate(ids.tolist()):
            ctx, _ = _neutral_context(model, hm, codes[n], i, args.seed, 256, {})
            body = Body.of(ctx)
            s = fit_shell(body, garment_shell(body, {"id": gid, "params": {}}, ctx.rng("garment")), CLEARANCE)
            head = ctx.vertices[scalp, 0].max() - ctx.vertices[scalp, 0].min()
            Vt, _ = torso.garment_torso(s, with_arms=False)
            Q = np.asarray(s.P)[torso.torso_shell_vertices(s)]
            Va, _ = torso.arms(Q)
            x = np.concatenate([np.asarray(s.P)[:, 0], Vt[:, 0]])
            before = x.max() - x.min()
            xa = np.concatenate([x, Va[:, 0]])
            after = xa.max() - xa.min()
            m.append([head, before, after])
        m = 1000.0 * np.asarray(m)
        r0, r1 = m[:, 1] / m[:, 0], m[:, 2] / m[:, 0]
        rows.append({"garment": gid, "head_mm": m[:, 0].tolist(), "without_mm": m[:, 1].tolist(),
                     "with_mm": m[:, 2].tolist()})
        q = lambda v: f"{v.min():.2f} / {np.median(v):.2f} / {v.max():.2f}"  # noqa: E731
        print(f"| {gid} | {m[:, 0].min():.0f} / {np.median(m[:, 0]):.0f} / {m[:, 0].max():.0f} | "
              f"{np.median(m[:, 1]):.0f} / {np.median(m[:, 2]):.0f} | {q(r0)} | {q(r1)} |")
    hair_rows = []
    if args.hair:
        from synth.assets.fit.hair import groom
        from synth.geometry.raycast import ray_hit_counts

        k = min(args.hair_identities, len(ids))
        print(f"\nHair through the arms ({k} identities, tshirt_crew; strand points inside an arm by ray parity; "
              "strands with such a point, their deepest point): groomed (the hair alone) / kept out "
              "(synth.assets.fit.torso.keep_strands_out)\n")
        print("| style | strands | strands through an arm | deepest mm | after keep-out: strands / points |\n|---|---:|---:|---:|---:|")
        for sid in args.hair:
            acc = np.zeros(4)
            deep = 0.0
            for n, i in enumerate(ids[:k].tolist()):
                ctx, _ = _neutral_context(model, hm, codes[n], i, args.seed, 256, {})
                body = Body.of(ctx)
                s = fit_shell(body, garment_shell(body, {"id": "tshirt_crew", "params": {}}, ctx.rng("garment")), CLEARANCE)
                arms = torso.arm_params(np.asarray(s.P)[torso.torso_shell_vertices(s)])
                Va, Fa = torso.arms(np.asarray(s.P)[torso.torso_shell_vertices(s)])
                pts = np.asarray(groom(ctx, {"id": sid, "params": {}}).pts)
                kept, _ = torso.keep_strands_out(arms, pts)
                for j, q in enumerate((pts, kept)):
                    flat = q.reshape(-1, 3)
                    near = np.zeros(len(flat), bool)
                    for a in arms:
                        dxy = np.linalg.norm(flat[:, :2] - a.axis, axis=1)
                        near |= dxy < a.radius * 1.01
                    inside = np.zeros(len(flat), bool)
                    if near.any():
                        up = np.tile([0.0, 0.0, 1.0], (int(near.sum()), 1))
                        inside[near] = ray_hit_counts(flat[near], up, Va, Fa) % 2 == 1
                    per = inside.reshape(q.shape[0], -1).any(1)
                    acc[2 * j] += per.sum()
                    acc[2 * j + 1] += inside.sum()
                    if j == 0 and inside.any():
                        for a in arms:
                            m = inside & (np.linalg.norm(flat[:, :2] - a.axis, axis=1) < a.radius * 1.01)
                            if m.any():
                                moved, _ = a.push_out(flat[m], 0.0)
                                deep = max(deep, float(np.linalg.norm(moved - flat[m], axis=1).max()))
            hair_rows.append({"style": sid, "strands_through": acc[0], "points_through": acc[1],
                              "after_strands": acc[2], "after_points": acc[3], "deepest_m": deep})
            print(f"| {sid} | {k * pts.shape[0]} | {acc[0]:.0f} | {1000 * deep:.0f} | {acc[2]:.0f} / {acc[3]:.0f} |")
    return {"reference": ref, "rows": rows, "hair": hair_rows}


def drape_table(args) -> dict:
    """How loose styles hang (synth.assets.fit.hair.drape), with the loose styles' sweep floor
    and volume as before 2026-12-01 and as now, on the neutral heads of planned identities."""
    from synth.assets.fit import hair as H

    model, hm, ids, codes = _planned_heads(args.seed, args.identities)
    styles = ("short_straight", "short_curly", "medium_wavy", "bob", "long_straight", "long_curly")
    settings = {"before": (-0.03, 0.15), "now": (H.LOOSE_SWEEP_FLOOR_M, H.LOOSE_VOLUME)}
    print(f"\n### Drape of the loose styles ({len(ids)} identities of seed {args.seed}, neutral, "
          f"{args.resolution} px strand density; mm, mean over identities; before / now)\n")
    print("| style | beyond the head at eye level | half-width 5 cm below the chin | standoff, chin to eyes |\n"
          "|---|---:|---:|---:|")
    rows = []
    saved = H.LOOSE_SWEEP_FLOOR_M, H.LOOSE_VOLUME
    try:
        for sid in styles:
            got = {}
            for name, (floor, volume) in settings.items():
                H.LOOSE_SWEEP_FLOOR_M, H.LOOSE_VOLUME = floor, volume
                m = []
                for n, i in enumerate(ids.tolist()):
                    ctx, ev = _neutral_context(model, hm, codes[n], i, args.seed, args.resolution, {})
                    g = H.groom(ctx, {"id": sid, "params": {}})
                    d = H.drape(ctx.vertices, ctx.landmarks["ibug68"], g.pts)
                    m.append([d["beyond_head"], d["half_width_below_chin"], d["standoff"]])
                m = np.asarray(m, np.float64)
                got[name] = 1000.0 * np.array([np.mean(c[np.isfinite(c)]) if np.isfinite(c).any() else np.nan
                                               for c in m.T])
            rows.append({"style": sid, **{k: v.tolist() for k, v in got.items()}})
            b, a = got["before"], got["now"]
            print(f"| {sid} | " + " | ".join(f"{b[k]:.0f} / {a[k]:.0f}" for k in range(3)) + " |")
    finally:
        H.LOOSE_SWEEP_FLOOR_M, H.LOOSE_VOLUME = saved
    return {"rows": rows}


def beard_table(args) -> dict:
    """Where beards grow and how long beards hang (synth.assets.fit.beard.shape) on the neutral
    heads of planned identities: as before 2026-12-01 (the region's own cheek line, the 8 mm fade
    at the lips and nose too, long beards along the skin and ungathered) and now (cheek line
    ``--reach``)."""
    from synth.assets.fit import beard as B
    from synth.assets.fit import masks as M

    model, hm, ids, codes = _planned_heads(args.seed, args.identities)

    def old_area(data, V):
        return M.soft_region(V, M.region_mask(data.regions, ("beard",), len(V)), M.BEARD_FEATHER_M)

    settings = {"before": (1.0, old_area, 0.0, 0.0, 0.01, 0.01),
                "now": (args.reach, B.beard_area, B.LONG_FALL, B.LONG_GATHER, B.LONG_LIFT_M, B.LONG_LAYER_M)}
    names = ("beard_area", "LONG_FALL", "LONG_GATHER", "LONG_LIFT_M", "LONG_LAYER_M")
    saved = tuple(getattr(B, k) for k in names)
    got = {}
    try:
        for name, (reach, *consts) in settings.items():
            for k, v in zip(names, consts):
                setattr(B, k, v)
            rows = []
            for n, i in enumerate(ids.tolist()):
                ctx, ev = _neutral_context(model, hm, codes[n], i, args.seed, args.resolution, {})
                lm = ctx.landmarks["ibug68"]
                full = B.groom(ctx, {"id": "short_full", "params": {"reach": reach, "moustache": True}})
                long = B.groom(ctx, {"id": "full_long", "params": {"reach": reach, "length_m": 0.12}})
                a, b = B.shape(model, ctx.vertices, lm, full), B.shape(model, ctx.vertices, lm, long)
                rows.append([a["cheek_roots"], len(full.pts), a["upper_lip"], a["under_lip"],
                             b["spread_below_chin"]])
            got[name] = np.asarray(rows, np.float64)
    finally:
        for k, v in zip(names, saved):
            setattr(B, k, v)
    print(f"\n### Beards ({len(ids)} identities of seed {args.seed}, neutral, {args.resolution} px strand "
          f"density; now with reach {args.reach}; mean over identities, before / now)\n")
    print("| short_full: roots on the cheek above the nostrils' wing | strands | upper-lip roots per area "
          "(region = 1) | under the lower lip | full_long (12 cm): spread 3 cm below the chin (jaw half "
          "widths, 95th pct.) |\n|---:|---:|---:|---:|---:|")
    b, a = np.nanmean(got["before"], 0), np.nanmean(got["now"], 0)
    fmt = ("{:.0f}", "{:.0f}", "{:.2f}", "{:.2f}", "{:.2f}")
    print("| " + " | ".join(f"{f.format(x)} / {f.format(y)}" for f, x, y in zip(fmt, b, a)) + " |")
    return {k: v.tolist() for k, v in got.items()}


def _srgb8(fr) -> np.ndarray:
    """(H, W, 3) uint8 sRGB of a frame composited over mid grey."""
    from synth.appearance.srgb import srgb8

    return srgb8(fr.rgb_premultiplied + (1.0 - fr.alpha[..., None]) * 0.5)  # composited in linear


def _png(fr, path: Path) -> None:
    from PIL import Image

    Image.fromarray(_srgb8(fr)).save(path)


def fringe(args) -> dict:
    """Datasets against a reference dataset of the same plan (more samples): RMS errors over
    the reference's fringe pixels (0.02 < alpha < 0.98) of the composite over mid grey and of
    the alpha, and of the whole composite; median over the frames both have."""
    from synth.dataset.reader import iter_frames

    def comp(fr):
        return fr.rgb_premultiplied.astype(np.float64) + (1.0 - fr.alpha[..., None]) * 0.5

    ref = {fr.meta["frame_id"]: fr for fr in iter_frames(args.reference)}
    out = {}
    print("\n| dataset | frames | fringe pixels | composite, fringe | alpha, fringe | composite, whole image |")
    print("|---|---:|---:|---:|---:|---:|")
    for src in args.datasets:
        rows = []
        for fr in iter_frames(src):
            r = ref.get(fr.meta["frame_id"])
            if r is None:
                continue
            m = (r.alpha > 0.02) & (r.alpha < 0.98)
            e, ea = comp(fr) - comp(r), fr.alpha.astype(np.float64) - r.alpha
            rows.append((int(m.sum()), float(np.sqrt((e[m] ** 2).mean())) if m.any() else 0.0,
                         float(np.sqrt((ea[m] ** 2).mean())) if m.any() else 0.0, float(np.sqrt((e ** 2).mean()))))
        a = np.asarray(rows).reshape(-1, 4)
        out[src] = {"frames": len(rows), "fringe_pixels": int(a[:, 0].sum()), "composite_fringe": float(np.median(a[:, 1])),
                    "alpha_fringe": float(np.median(a[:, 2])), "composite": float(np.median(a[:, 3]))}
        o = out[src]
        print(f"| {src} | {o['frames']} | {o['fringe_pixels']} | {o['composite_fringe']:.4f} | {o['alpha_fringe']:.4f} | "
              f"{o['composite']:.4f} |")
    return out


def timing(args) -> dict:
    out = {}
    print("\n| dataset | frames | Cycles s/frame (median) | Cycles s/frame (mean) |\n|---|---:|---:|---:|")
    for src in args.datasets:
        secs = []
        for log in Path(src, "logs").rglob("*.log"):
            for line in log.read_text(errors="replace").splitlines():
                if line.startswith("{") and '"event": "frame"' in line:
                    m = re.search(r'"render_seconds": ([0-9.eE+-]+)', line)
                    if m:
                        secs.append(float(m.group(1)))
        out[src] = secs
        print(f"| {src} | {len(secs)} | {np.median(secs):.2f} | {np.mean(secs):.2f} |")
    return out


def plot_skin(args) -> dict:
    """ITA histograms and the L*-b* plane of the planned albedos, before / after."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    edges = [-90, -30, 10, 28, 41, 55, 120]
    for path, label in zip(args.inputs, args.labels):
        d = json.loads(Path(path).read_text())["albedo"]
        ita, lab = np.asarray(d["ita"]), np.asarray(d["lab"])
        h = np.histogram(ita, bins=edges)[0][::-1]
        ax[0].bar(np.arange(6) + (0.2 if label == args.labels[-1] else -0.2), h, width=0.4, label=label)
        ax[1].scatter(lab[:, 2], lab[:, 0], s=6, label=label)
    ax[0].set_xticks(np.arange(6), CATS, rotation=20)
    ax[0].set_ylabel("identities")
    ax[0].legend()
    ax[1].add_patch(plt.Rectangle((6, 28), 20, 54, fill=False, ls="--", color="k"))
    ax[1].set_xlabel("b*")
    ax[1].set_ylabel("L*")
    ax[1].set_title("dashed: envelope of published skin colour", fontsize=9)
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    return {}


def sheet(args) -> dict:
    """The frames nearest to frontal of the first identities of each dataset, one row per dataset."""
    from PIL import Image

    from synth.dataset.reader import iter_frames

    rows = []
    for src in args.datasets:
        best: dict[int, tuple[float, object]] = {}
        for fr in iter_frames(src):
            c = fr.meta["camera"]
            a = abs(c["azimuth_deg"]) + abs(c["elevation_deg"])
            if fr.identity_index < args.identities and a < best.get(fr.identity_index, (1e9, None))[0]:
                best[fr.identity_index] = (a, fr)
        tiles = [_srgb8(best[i][1]) for i in sorted(best)]
        cols = args.columns or len(tiles)
        for k in range(0, len(tiles), cols):  # one dataset may wrap onto several rows
            row = tiles[k:k + cols]
            row += [np.zeros_like(tiles[0])] * (cols - len(row))
            rows.append(np.concatenate(row, axis=1))
    w = min(r.shape[1] for r in rows)
    Image.fromarray(np.concatenate([r[:, :w] for r in rows], axis=0)).save(args.out)
    return {}


def scalp_measure(seg, rgb_premultiplied, alpha, landmarks_2d, min_pixels: int = 20):
    """One frame of :func:`scalp`: (skin pixels more than 0.6 inter-ocular distances above the
    brows, their median luminance over the face skin's, the hair's over the face skin's), or None
    when scalp, face skin or hair has fewer than ``min_pixels`` pixels."""
    from synth.dataset.segmentation import CLASSES as SEG

    lm = np.asarray(landmarks_2d, np.float64)
    iod = float(np.linalg.norm(lm[45] - lm[36]))
    y = np.arange(seg.shape[0])[:, None]
    skin = seg == SEG["skin"]
    lum = (rgb_premultiplied / np.maximum(alpha[..., None], 1e-6)) @ np.array([0.2126, 0.7152, 0.0722])
    top = skin & (y < lm[17:27, 1].min() - 0.6 * iod)
    face = skin & (y > lm[[36, 45], 1].mean()) & (y < lm[51, 1])
    strands = seg == SEG["hair"]
    if min(top.sum(), face.sum(), strands.sum()) < min_pixels:
        return None
    f = float(np.median(lum[face]))
    return int(top.sum()), float(np.median(lum[top])) / f, float(np.median(lum[strands])) / f


def scalp(args) -> dict:
    """Scalp seen between hair strands: per frame with scalp hair, the skin-class pixels more
    than 0.6 inter-ocular distances above the brows (the scalp, between strands) and the median
    luminance of their colour (alpha divided out) over the face skin's (rows between the eyes
    and the upper lip); the hair's for reference. Medians over frames by hair colour."""
    from synth.dataset.reader import iter_frames

    rows = {}
    for fr in iter_frames(args.dataset):
        hair = (fr.meta["assets"].get("hair") or {})
        if not hair:
            continue
        m = scalp_measure(fr.segmentation, fr.rgb_premultiplied, fr.alpha, fr.meta["landmarks_2d"])
        if m is None:
            continue
        colour = str((hair.get("params") or {}).get("colour") or (hair.get("build") or {}).get("colour"))
        rows.setdefault(colour, []).append(m)
    print(f"\n### Scalp between strands ({args.dataset}; frames with at least 20 such pixels)\n")
    print("| hair colour | frames | scalp pixels (median) | scalp / face luminance | hair / face |\n|---|---:|---:|---:|---:|")
    out = {}
    for colour, r in sorted(rows.items()):
        a = np.asarray(r)
        out[colour] = {"frames": len(r), "pixels": float(np.median(a[:, 0])), "scalp_over_face": float(np.median(a[:, 1])),
                       "hair_over_face": float(np.median(a[:, 2]))}
        print(f"| {colour} | {len(r)} | {np.median(a[:, 0]):.0f} | {np.median(a[:, 1]):.2f} | {np.median(a[:, 2]):.2f} |")
    return out


def eyes(args) -> dict:
    """The eyes' proportions of the first planned identities (neutral, rest pose) against
    published measurements (benchmarks/realism_eyes.py)."""
    from realism_eyes import eyeball_diameters, eyes_table, margin_reflex_distances

    model, hm, ids, codes = _planned_heads(args.seed, args.identities)
    n = len(ids)
    ev = hm.evaluate(codes, np.zeros((n, model.expression_dims)), np.zeros((n, hm.J, 3)))
    return eyes_table(args, np.asarray(ev.landmarks["ibug68"], np.float64),
                      margin_reflex_distances(ev.vertices, model.regions), eyeball_diameters(ev.vertices, model.regions))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("skin")
    p.add_argument("--identities", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--frames", nargs="*", default=[])
    p = sub.add_parser("framing")
    p.add_argument("datasets", nargs="+")
    p = sub.add_parser("body-end")
    p.add_argument("datasets", nargs="+")
    p = sub.add_parser("hats")
    p.add_argument("--identities", type=int, default=3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--resolution", type=int, default=256)
    p = sub.add_parser("shoulders")
    p.add_argument("--identities", type=int, default=40)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--garments", nargs="+", default=["tshirt_crew", "tank_top", "jacket_blazer", "coat"])
    p.add_argument("--hair", nargs="*", default=["long_straight", "long_curly", "braids", "ponytail", "medium_wavy"])
    p.add_argument("--hair-identities", type=int, default=6)
    p = sub.add_parser("scalp")
    p.add_argument("dataset")
    p = sub.add_parser("hair")
    p.add_argument("--identities", type=int, default=12)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--style", default=None, help="only identities planned with this hair style")
    p = sub.add_parser("drape")
    p.add_argument("--identities", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--resolution", type=int, default=256)
    p = sub.add_parser("beard")
    p.add_argument("--identities", type=int, default=8)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--resolution", type=int, default=256)
    p.add_argument("--reach", type=float, default=0.3)
    p = sub.add_parser("judge")
    p.add_argument("dataset")
    p.add_argument("--mp-python", default=sys.executable, help="a Python with mediapipe==0.10.21 (default: this one)")
    p.add_argument("--max-azimuth", type=float, default=45.0)
    p.add_argument("--detections", help="mediapipe's JSON: read it if it exists (no mediapipe run), else write it")
    p = sub.add_parser("jaw")
    p.add_argument("dataset")
    p.add_argument("--detections", help="mediapipe's JSON written by judge --detections")
    p.add_argument("--max-azimuth", type=float, default=45.0)
    p = sub.add_parser("eyes")
    p.add_argument("--identities", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p = sub.add_parser("mapping")
    p.add_argument("--relax", nargs="+", default=["convex", "1e-2", "3e-3", "1e-3", "3e-4", "1e-4"])
    p.add_argument("--dataset")
    p.add_argument("--detections")
    p = sub.add_parser("timing")
    p.add_argument("datasets", nargs="+")
    p = sub.add_parser("fringe")
    p.add_argument("reference")
    p.add_argument("datasets", nargs="+")
    p = sub.add_parser("plot-skin")
    p.add_argument("out")
    p.add_argument("--inputs", nargs="+", required=True, help="JSON files written by 'skin --json'")
    p.add_argument("--labels", nargs="+", required=True)
    p = sub.add_parser("sheet")
    p.add_argument("out")
    p.add_argument("datasets", nargs="+")
    p.add_argument("--identities", type=int, default=8)
    p.add_argument("--columns", type=int, default=0, help="tiles per row (0: one row per dataset)")
    for q in sub.choices.values():
        q.add_argument("--json", help="also write the figures to this JSON file")
    args = ap.parse_args(argv)
    from realism_judge import jaw_table, judge, mapping_table

    res = {"mapping": mapping_table, "skin": skin, "hats": hats, "framing": framing, "body-end": body_end, "shoulders": shoulders, "hair": hair, "scalp": scalp, "drape": drape_table, "beard": beard_table, "judge": lambda a: judge(a, _png, CATS), "jaw": jaw_table, "eyes": eyes, "timing": timing, "fringe": fringe, "plot-skin": plot_skin,
           "sheet": sheet}[args.cmd](args)
    if args.json:
        Path(args.json).write_text(json.dumps(res))


if __name__ == "__main__":
    main()
