"""Measurements on the dressed planned heads (numpy rigs): ``hats``, ``hair``, ``shoulders``,
``drape``, ``beard`` (docs/realism.md)."""

from __future__ import annotations

import numpy as np

from .common import _neutral_context, _planned_heads

def hats(args) -> dict:
    """Hair under headwear: for planned identities, each hair style a hat may go with and each
    hat, the groom without the hat and with it: strands, the share of
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
    (neutral), each garment of ``--garments``, the widest extent side to side of the dressed body
    (the garment, the torso below it and the bust's skin: its bare arms; with the bust's arms, at
    the deltoids: from 12 cm under to 8 cm over the armholes' centres) over the head's breadth
    (its scalp, above the ears), against bideltoid over head breadth of measured adults; and hair
    (``--hair``, a crew T-shirt) within the sleeves' reach of the upper arms, as groomed and after
    synth.assets.fit.arms.ArmKeepOut."""
    from synth.assets.fit import arms as arms_fit
    from synth.assets.fit import torso
    from synth.assets.fit.body import Body, fit_shell
    from synth.assets.fit.garment import CLEARANCE, garment_shell

    model, hm, ids, codes = _planned_heads(args.seed, args.identities)
    scalp = np.asarray(model.regions["scalp"])
    bust = np.asarray(model.regions.get("bust", model.regions.get("shoulders", [])), np.int64)
    print(f"\n### Body breadth over head breadth ({len(ids)} identities of seed {args.seed}, neutral)\n")
    ref = {k: BIDELTOID_MM[k][0] / HEAD_BREADTH_MM[k][0] for k in BIDELTOID_MM}
    print("measured adults (bideltoid / head breadth of the means): "
          + ", ".join(f"{k} {v:.2f}" for k, v in ref.items()) + "\n")
    print("| garment | head breadth mm (min / median / max) | body breadth mm (min / median / max) | "
          "ratio (min / median / max) |\n|---|---:|---:|---:|")
    rows = []
    for gid in args.garments:
        m = []
        for n, i in enumerate(ids.tolist()):
            ctx, _ = _neutral_context(model, hm, codes[n], i, args.seed, 256, {})
            body = Body.of(ctx)
            s = fit_shell(body, garment_shell(body, {"id": gid, "params": {}}, ctx.rng("garment")), CLEARANCE)
            head = ctx.vertices[scalp, 0].max() - ctx.vertices[scalp, 0].min()
            Vt, _ = torso.garment_torso(s)
            P = np.concatenate([np.asarray(s.P), Vt, ctx.vertices[bust]])
            if body.arms is not None:  # at the deltoids: from 12 cm under to 8 cm over the armholes' centres
                # (bust.measures' bideltoid band; the elbows, hanging out, are wider still)
                z0 = 0.5 * (body.arms.shoulder["L"][2] + body.arms.shoulder["R"][2])
                P = P[(P[:, 2] > z0 - 0.12) & (P[:, 2] < z0 + 0.08)]
            m.append([head, P[:, 0].max() - P[:, 0].min()])
        m = 1000.0 * np.asarray(m)
        r = m[:, 1] / m[:, 0]
        rows.append({"garment": gid, "head_mm": m[:, 0].tolist(), "body_mm": m[:, 1].tolist()})
        q = lambda v, f=".2f": f"{v.min():{f}} / {np.median(v):{f}} / {v.max():{f}}"  # noqa: E731
        print(f"| {gid} | {q(m[:, 0], '.0f')} | {q(m[:, 1], '.0f')} | {q(r)} |")
    hair_rows = []
    if args.hair and arms_fit.has_arms(model.regions):
        from synth.assets.fit.hair import groom

        k = min(args.hair_identities, len(ids))
        print(f"\nHair within the sleeves' reach of the upper arms ({k} identities, tshirt_crew: strand points "
              "whose closest skin point is on an arm, closer to it than the cloth's reach plus 2 mm and less "
              "than 7 cm inside): groomed (the hair alone) / kept out (synth.assets.fit.arms.ArmKeepOut)\n")
        print("| style | strands | strands too close | deepest mm under the reach | after keep-out: strands / points |\n"
              "|---|---:|---:|---:|---:|")
        for sid in args.hair:
            acc = np.zeros(4)
            deep = 0.0
            for n, i in enumerate(ids[:k].tolist()):
                ctx, _ = _neutral_context(model, hm, codes[n], i, args.seed, 256, {})
                body = Body.of(ctx)
                s = garment_shell(body, {"id": "tshirt_crew", "params": {}}, ctx.rng("garment"))
                keep = arms_fit.ArmKeepOut(body.V, body.F, body.regions,
                                           arms_fit.HAIR_CLEARANCE + s.info["cloth_reach_m"])
                pts = np.asarray(groom(ctx, {"id": sid, "params": {}}).pts)
                kept, _ = keep.push(pts)
                for j, q in enumerate((pts, kept)):
                    d, on_arm = keep.distance(q[:, 1:].reshape(-1, 3))
                    close = (d < keep.clearance - 1e-6) & (d > -arms_fit.HAIR_MAX_DEPTH) & on_arm
                    acc[2 * j] += close.reshape(q.shape[0], -1).any(1).sum()
                    acc[2 * j + 1] += close.sum()
                    if j == 0 and close.any():
                        deep = max(deep, float((keep.clearance - d[close]).max()))
            hair_rows.append({"style": sid, "strands_close": acc[0], "points_close": acc[1],
                              "after_strands": acc[2], "after_points": acc[3], "deepest_m": deep})
            print(f"| {sid} | {k * pts.shape[0]} | {acc[0]:.0f} | {1000 * deep:.0f} | {acc[2]:.0f} / {acc[3]:.0f} |")
    return {"reference": ref, "rows": rows, "hair": hair_rows}


def drape_table(args) -> dict:
    """How loose styles hang (synth.assets.fit.hair.drape), with the loose styles' sweep floor
    and volume of a flaring field (3 cm below the centre, 0.15: "before") and as set ("now"), on
    the neutral heads of planned identities."""
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
    heads of planned identities: without the beard rules (the region's own cheek line, the 8 mm fade
    at the lips and nose too, long beards along the skin and ungathered) and with them (cheek line
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


def hair_mix(args) -> dict:
    """The default mix of scalp hair as the planner draws it: per style its share of ``--identities``
    identities of ``--seed`` (bald or shaved: no hair pick), how many of them wear a fringe and
    which partings, and the colours; from the manifest and the rules, so it follows any change."""
    from collections import Counter

    from synth.assets.catalogue import load_catalogue
    from synth.plan.assets import sample_assets_batch

    n = int(args.identities)
    picks = [a.get("hair") for a in sample_assets_batch(args.seed, np.arange(n), load_catalogue(None))]
    styles = Counter("(none: bald or shaved)" if p is None else p["id"] for p in picks)
    fringe = Counter(p["id"] for p in picks if p is not None and p["params"].get("fringe"))
    parting = {s: Counter(str(p["params"]["parting"]) for p in picks if p is not None and p["id"] == s
                          and "parting" in p["params"]) for s in styles}
    colours = Counter(str(p["params"].get("colour")) for p in picks if p is not None)
    print(f"\n### The hair mix ({n:,} planned identities of seed {args.seed})\n")
    print("| style | share | with a fringe | partings |\n|---|---:|---:|---|")
    rows = {}
    for s, k in sorted(styles.items(), key=lambda kv: (-kv[1], kv[0])):
        part = ", ".join(f"{name} {c / k:.0%}" for name, c in sorted(parting.get(s, Counter()).items()))
        rows[s] = {"share": k / n, "fringe": fringe.get(s, 0) / k, "parting": dict(parting.get(s, {}))}
        print(f"| {s} | {k / n:.1%} | {fringe.get(s, 0) / k:.0%} | {part or '-'} |")
    total = sum(colours.values())
    print("\n| colour | " + " | ".join(c for c, _ in colours.most_common()) + " |")
    print("|---|" + "---:|" * len(colours))
    print("| share of the haired | " + " | ".join(f"{k / total:.1%}" for _, k in colours.most_common()) + " |")
    return {"styles": rows, "colours": {c: k / total for c, k in colours.items()}}
