"""Eyebrows: strands in a parametric brow shape around the ibug68 brow landmarks
(assets_manifest/eyebrows.toml): arch, thickness profile (thick head, thin tail), density,
unruliness, monobrow. Hairs lie nearly flat on the skin, pointing up at the head of the brow
and outward/down along the tail."""

from __future__ import annotations

import numpy as np

from synth.assets.fit.groom import Groom, Styling, setup
from synth.assets.fit.strands import LEFT, UP, arc_length, push_out_strands, scale_count
from synth.geometry.normals import normalize


def counts(resolution: int, density: float = 1.0) -> int:
    return max(40, int(scale_count(resolution, 1.6, 160, 1600) * float(density)))


def _brow_coords(p, line):
    """(s in [0,1] inner->outer, vertical offset above the line, distance) to a brow polyline."""
    a, b = line[:-1], line[1:]
    ab = b - a
    seg_len = np.linalg.norm(ab, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    t = np.clip(np.einsum("nkd,kd->nk", p[:, None] - a[None], ab) / np.maximum(seg_len ** 2, 1e-12), -0.3, 1.3)
    q = a[None] + t[..., None] * ab[None]
    d = np.linalg.norm(p[:, None] - q, axis=2)
    j = d.argmin(1)
    i = np.arange(len(p))
    s = (cum[j] + t[i, j] * seg_len[j]) / cum[-1]
    v = p[:, 2] - q[i, j, 2]
    return s, v


def groom(ctx, entry) -> Groom:
    st = setup(ctx, entry, "eyebrows")
    rng, sid, prm, surface, hf, colour, pg = st.rng, st.sid, st.prm, st.surface, st.hf, st.colour, st.pg
    lm = hf["lm"]
    thick, dens, arch = float(prm.thickness), float(prm.density), float(prm.arch)
    unruly, mono = float(prm.unruliness), bool(prm.monobrow)
    # brows: ibug 17-21 (subject's right, -X) and 22-26 (left); inner ends are 21 and 22
    right = lm[17:22][::-1]
    left = lm[22:27]
    cand = surface.region_triangles(("brow", "face"), "all")
    cen = surface.V[surface.T[cand]].mean(1)
    near = np.minimum(np.linalg.norm(cen[:, None] - lm[None, 17:27], axis=2).min(1), 1.0) < 0.02
    cand = cand[near]
    n = counts(ctx.resolution, dens)
    t, b = surface.sample(cand, 12 * n + 64, rng)
    p = surface.points(t, b)
    keep = np.zeros(len(p), bool)
    s_all = np.zeros(len(p))
    side_all = np.zeros(len(p))
    for sign, line in ((-1.0, right), (1.0, left)):
        s, v = _brow_coords(p, line)
        on_side = np.sign(p[:, 0] - 0.5 * (lm[21, 0] + lm[22, 0])) == sign
        arch_off = (arch - 0.3) * 0.008 * np.sin(np.pi * np.clip(s, 0, 1) ** 0.8)
        h = thick * 0.0085 * (1.0 - 0.6 * np.clip(s, 0, 1)) + 0.0015
        centre = arch_off - 0.0015
        inside = on_side & (s > -0.03) & (s < 1.02) & (np.abs(v - centre) < 0.5 * h)
        keep |= inside
        s_all = np.where(inside, s, s_all)
        side_all = np.where(inside, sign, side_all)
    if mono:
        mid = 0.5 * (lm[21] + lm[22])
        glab = (np.abs(p[:, 0] - mid[0]) < abs(lm[22, 0] - lm[21, 0]) * 0.5) & (np.abs(p[:, 2] - mid[2]) < 0.004 * thick)
        glab &= rng.random(len(p)) < 0.5
        keep |= glab
        side_all = np.where(glab & (side_all == 0), np.sign(p[:, 0] - mid[0] + 1e-9), side_all)
    idx = np.flatnonzero(keep)[:n]
    tri, bary, s, side = t[idx], b[idx], np.clip(s_all[idx], 0, 1), side_all[idx]
    N = len(tri)
    R = surface.points(tri, bary)
    nrm = surface.normals(tri, bary)
    ang = np.radians(70.0 - 85.0 * s) + np.radians(40.0) * unruly * rng.normal(0, 1, N)
    d = np.cos(ang)[:, None] * side[:, None] * LEFT[None] + np.sin(ang)[:, None] * UP[None]
    d = normalize(d - np.einsum("nd,nd->n", d, nrm)[:, None] * nrm)
    L = (0.008 - 0.003 * s) * rng.uniform(0.7, 1.1, N) * (0.8 if sid == "sparse" else 1.0)
    lift = rng.uniform(0.3, 0.5 + 0.4 * unruly, N)
    k = np.linspace(0.0, 1.0, 5)[None, :, None]
    # a flat arc: leaves the skin at ``lift`` rad and bends back toward it
    up = np.sin(lift)[:, None, None] * nrm[:, None] * (k * (1.2 - k)) * L[:, None, None]
    pts = R[:, None] + k * L[:, None, None] * d[:, None] + up
    layer = np.full(N, 0.0004)
    pts = push_out_strands(surface, pts, layer, exact=True)
    clr = np.minimum(layer[:, None], 0.6 * arc_length(pts))
    styling = Styling(root_radius=float(np.clip(7e-5 * np.sqrt(600.0 / max(N, 1)), 6e-5, 1.6e-4)), tip_shape=0.35,
                        frizz=0.0, seed=int(rng.integers(0, 2 ** 31)))
    info = {"style": sid, "colour": colour, "pigment": pg.as_dict(), "guides": N, "thickness": thick, "arch": arch,
            "monobrow": mono}
    return Groom("eyebrows", f"eyebrows_{sid}", surface, pts, tri, bary, clr, styling, info, pg,
                 roughness=0.35, exact=True)
