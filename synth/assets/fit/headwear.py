"""Procedural headwear (``procedural:headwear_shell``): beanie and baseball cap, fitted to the skull.

Pure numpy; the Blender rig (``blender_scripts/assets/headwear.py``) only makes the mesh
object and the cloth materials. Both are built from the head surface of the identity:

* a **cut plane** through three points: the brow centre (mean of ibug68 19 and 24) raised by
  2.5 cm (beanie) / 3.5 cm (cap), and the top of each ear (+8 / +12 mm), so the plane runs
  across the forehead, just over the ears and down over the occiput;
* the skin triangles of the ``scalp``, ``face``, ``ears`` and ``neck`` regions above the
  plane are clipped exactly there (``meshops.clip_by_field``), subdivided, offset along the
  normals (beanie: knit thickness, crown slack and the folded cuff ``fold_height_m`` as an
  extra layer; cap: thin crown with a slight dome), smoothed, and pushed out to at least
  ``CLEARANCE`` from the skin, so they never intersect the skull;
* extras: a rolled rim tube on the cut, a pompom (beanie, ``pompom``), a button and a brim
  (cap: ``brim_yaw_deg`` 0 = forward, 180 = backward; ``brim_curve`` bends its sides down),
  4 mm thick;
* fit and update: :func:`synth.assets.fit.body.fit_shell` and ``FittedShell.follow``
  (binding to the head triangles + push-out, shared with garments).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from synth.assets.fit.attach import push_out
from synth.assets.fit.body import Body, Cloth, Parts, Shell, WaveNoise
from synth.assets.fit.meshops import grid_faces, icosphere, laplacian_smooth, oriented_boundary_loops, sweep_tube
from synth.assets.params import AssetPick
from synth.geometry.normals import normalize
from synth.model.meshutil import smoothstep

CLEARANCE = 0.0015


#: cut plane of each headwear (metres): the brow centre raised by the first, the top of each
#: ear by the second (module doc)
CUT_RAISE_M = {"beanie": (0.025, 0.008), "baseball_cap": (0.035, 0.012)}


def cut_plane(V: np.ndarray, regions: dict, ibug68: np.ndarray, front_up: float, ear_up: float):
    """(origin, unit normal pointing up) of the plane through the brow centre raised by
    ``front_up`` and the top of each ear raised by ``ear_up`` (head vertices ``V``)."""
    lm = np.asarray(ibug68, np.float64)
    V = np.asarray(V, np.float64)
    Fp = 0.5 * (lm[19] + lm[24]) + np.array([0.0, 0.0, front_up])
    pts = []
    for r in ("ear_l", "ear_r"):
        idx = np.asarray(regions[r], np.int64) if r in regions else None
        if idx is None or len(idx) == 0:
            side = 16 if r == "ear_l" else 0
            pts.append(lm[side] + np.array([0.0, 0.0, 0.05]))
            continue
        e = V[idx]
        pts.append(e[np.argmax(e[:, 2])] + np.array([0.0, 0.0, ear_up]))
    n = normalize(np.cross(pts[0] - Fp, pts[1] - Fp))
    if n[2] < 0:
        n = -n
    return Fp, n


def headwear_cut(V: np.ndarray, regions: dict, ibug68: np.ndarray, entry: AssetPick | Mapping | None):
    """The cut plane (origin, normal) of a plan's headwear pick on this head, or None without
    headwear: what the headwear covers lies on the normal's side (the hair rig leaves it out)."""
    if not entry:
        return None
    raise_m = CUT_RAISE_M.get(AssetPick.coerce("headwear", entry).id)
    return None if raise_m is None else cut_plane(V, regions, ibug68, *raise_m)


def _crown(body: Body, front_up, ear_up, off_fn, smooth=3):
    o, n = cut_plane(body.V, body.regions, body.lm, front_up, ear_up)
    h = (body.V - o) @ n
    P, F, cut = body.shell(body.head_tris, h, lambda p, nn: off_fn(p, nn, (p - o) @ n))
    P = laplacian_smooth(P, F, smooth, 0.5)
    P = push_out(P, body.query, CLEARANCE + 0.002)
    return P, F, cut, o, n


def headwear_shell(body: Body, entry: AssetPick | Mapping, rng: np.random.Generator) -> Shell:
    """The headwear of a plan pick on ``body`` (``rng``: the rig's generator, ctx.rng("headwear"))."""
    entry = AssetPick.coerce("headwear", entry)
    aid, p = entry.id, entry.params
    colour = p.colour_hsv
    seed = float(rng.uniform(0, 100))
    parts = Parts()
    info = {"id": aid, "colour": colour if isinstance(colour, str) else list(colour)}
    if aid == "beanie":
        fold, knit = float(p.fold_height_m), float(p.knit_scale_m)
        cloths = [Cloth("headwear_beanie", colour, "wool_knit", knit, seed)]
        noise = WaveNoise(rng, 0.04, 10)

        def off(P, N, h):
            slack = 0.006 * smoothstep(h, 0.03, 0.12)
            cuff = 0.004 * (1.0 - smoothstep(h, fold - 0.003, fold)) if fold > 0.002 else 0.0
            return 0.005 + slack + cuff + 0.001 * (0.5 + 0.5 * noise(P))
        P, F, cut, o, n = _crown(body, *CUT_RAISE_M["beanie"], off)
        parts.add(P, F, 0)
        loops = [lp for lp in oriented_boundary_loops(F) if cut[lp].mean() > 0.5 and len(lp) > 8]
        for lp in loops:
            Vt, Ft = sweep_tube(P[lp], 0.005 if fold > 0.002 else 0.003, 8, closed=True)
            parts.add(push_out(Vt, body.query, CLEARANCE + 0.001), Ft, 0)
        pom = bool(p.pompom)
        if pom:
            top = P[np.argmax((P - o) @ n)]
            Vs, Fs = icosphere(3)
            fuzz = WaveNoise(rng, 0.012, 16)
            r = 0.035 * (1.0 + 0.08 * fuzz(Vs * 0.035))
            parts.add(top + n * 0.028 + Vs * r[:, None], Fs, 0)
        info.update(fold_height_m=fold, knit_scale_m=knit, pompom=pom)
    elif aid == "baseball_cap":
        yaw, curve = float(p.brim_yaw_deg), float(p.brim_curve)
        cloths = [Cloth("headwear_cap", colour, "cotton_twill", 0.005, seed)]

        def off(P, N, h):
            return 0.003 + 0.006 * smoothstep(h, 0.0, 0.08)
        P, F, cut, o, n = _crown(body, *CUT_RAISE_M["baseball_cap"], off)
        parts.add(P, F, 0)
        loops = [lp for lp in oriented_boundary_loops(F) if cut[lp].mean() > 0.5 and len(lp) > 8]
        for lp in loops:
            Vt, Ft = sweep_tube(P[lp], 0.0025, 6, closed=True)
            parts.add(push_out(Vt, body.query, CLEARANCE + 0.001), Ft, 0)
        # button
        top = P[np.argmax((P - o) @ n)]
        Vs, Fs = icosphere(1)
        parts.add(top + n * 0.002 + Vs * np.array([0.006, 0.006, 0.003]), Fs, 0)
        # brim
        if loops:
            lp = max(loops, key=len)
            rim = P[lp]
            c = rim.mean(0)
            a = np.radians(yaw)
            d = np.array([np.sin(a), -np.cos(a), 0.0])  # yaw 0: toward -Y (the face)
            rel = rim - c
            phi = np.arctan2(rel[:, 0] * d[1] - rel[:, 1] * d[0], rel[:, 0] * d[0] + rel[:, 1] * d[1])
            sel = np.abs(phi) < np.radians(80)
            o_ = np.argsort(phi[sel])
            inner, ph = rim[sel][o_], phi[sel][o_]
            if len(inner) >= 4:
                ph_n = ph / np.radians(80)
                radial = normalize(np.concatenate([(inner - c)[:, :2], np.zeros((len(inner), 1))], 1))
                outdir = normalize(0.6 * d + 0.4 * radial)
                L = 0.075 * np.sqrt(np.clip(np.cos(ph_n * np.pi / 2), 0.0, 1.0)) + 0.004
                rows = []
                for s in np.linspace(0.0, 1.0, 6):
                    q = inner + outdir * (L * s)[:, None]
                    q[:, 2] -= 0.012 * s + curve * 0.03 * (ph_n ** 2) * s
                    rows.append(q)
                G = np.stack(rows, 1)  # (na, 6, 3)
                na, ns = G.shape[:2]
                top_s = G.reshape(-1, 3) + np.array([0.0, 0.0, 0.002])
                bot_s = G.reshape(-1, 3) - np.array([0.0, 0.0, 0.002])
                Fg = grid_faces(na, ns)
                # outer edge + sides: stitch the boundary of the two grids
                ring = np.concatenate([np.arange(na) * ns + ns - 1, (na - 1) * ns + np.arange(ns - 2, -1, -1),
                                       np.arange(na - 2, 0, -1) * ns, np.arange(0, ns - 1)])
                side = np.stack([ring, np.roll(ring, -1), np.roll(ring, -1) + na * ns, ring + na * ns], 1)
                Fb = np.concatenate([Fg, Fg[:, ::-1] + na * ns, side[:, [0, 1, 2]], side[:, [0, 2, 3]]])
                Vb = push_out(np.concatenate([top_s, bot_s]), body.query, CLEARANCE + 0.001)
                parts.add(Vb, Fb, 0)
        info.update(brim_yaw_deg=yaw, brim_curve=curve)
    else:
        raise ValueError(f"unknown headwear id '{aid}'")
    return Shell("headwear", f"headwear_{aid}", parts, body.head_tris, cloths, info)
