"""Eyelashes: rows of strands along the lid margins (regions ``eyelid_{l,r}_{upper,lower}``),
curling away from the eye (assets_manifest/eyelashes.toml: natural, mascara)."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from synth.appearance import pigment as pig
from synth.assets.fit.groom import Groom, Styling, attach, colour_of
from synth.assets.fit.strands import DOWN, FORWARD, LEFT, UP, Surface, arc_length, push_out_strands, scale_count
from synth.assets.params import AssetPick
from synth.geometry.normals import normalize


#: the closed eye meshes no lash point may enter
EYEBALLS = ("eye_l", "eye_r")


def counts(resolution: int, density: float = 1.0) -> int:
    """Upper lashes per eye (lower rows get 40 %)."""
    return max(12, int(scale_count(resolution, 0.25, 40, 140) * float(density)))


def _lid_line(surface, region, eye_mask):
    """Vertices of a lid margin in order along x, with for each consecutive pair the triangle
    that holds that edge on the skin side (-1 where the pair is not a mesh edge)."""
    vids = np.asarray(surface.data.regions[region], np.int64)
    vids = vids[np.argsort(surface.V[vids, 0])]
    T = surface.T
    out = []
    for a, b in zip(vids[:-1], vids[1:]):
        has = ((T == a).any(1)) & ((T == b).any(1))
        cand = np.flatnonzero(has)
        cand = [c for c in cand if not eye_mask[T[c]].all()]
        out.append(cand[0] if cand else -1)
    return vids, np.asarray(out, np.int64)


def _bary_on_edge(surface, tri, a, b, u):
    bary = np.zeros((len(tri), 3))
    for k in range(3):
        bary[:, k] += np.where(surface.T[tri, k] == a, 1.0 - u, 0.0) + np.where(surface.T[tri, k] == b, u, 0.0)
    return bary


def groom(ctx, entry: AssetPick | Mapping) -> Groom:
    entry = AssetPick.coerce("eyelashes", entry)
    rng = ctx.rng("eyelashes")
    sid, prm = entry.id, entry.params
    surface = Surface(ctx)
    mascara = sid == "mascara"
    lscale, curl, dens, clumping = float(prm.length_scale), float(prm.curl), float(prm.density), float(prm.clumping)
    base = colour_of(None, ctx, "dark_brown")
    colour = "black" if mascara else pig.darker(base)
    pg = pig.sample(colour, rng, spread=0.05)
    eye_mask = surface.mask("eyes")
    n_up = counts(ctx.resolution, dens)
    tris, barys, dirs_up, s_par, lens, sides, is_upper = [], [], [], [], [], [], []
    for side in ("l", "r"):
        eye_c = surface.V[surface.data.regions[f"eye_{side}"]].mean(0)
        for lid in ("upper", "lower"):
            reg = f"eyelid_{side}_{lid}"
            if reg not in surface.data.regions:
                continue
            vids, etri = _lid_line(surface, reg, eye_mask)
            ok = etri >= 0
            if not ok.any():
                continue
            P = surface.V[vids]
            seg = np.linalg.norm(np.diff(P, axis=0), axis=1) * ok
            m = n_up if lid == "upper" else max(6, int(0.4 * n_up))
            # stratified positions along the lid line (fewer at the inner corner)
            q = (np.arange(m) + rng.uniform(0.2, 0.8, m)) / m
            cum = np.concatenate([[0.0], np.cumsum(seg)])
            pos = q * cum[-1]
            j = np.clip(np.searchsorted(cum, pos, side="right") - 1, 0, len(seg) - 1)
            good = ok[j]
            j, pos, q = j[good], pos[good], q[good]
            u = np.clip((pos - cum[j]) / np.maximum(seg[j], 1e-12), 0.0, 1.0)
            tri = etri[j]
            bary = _bary_on_edge(surface, tri, vids[j], vids[j + 1], u)
            R = surface.points(tri, bary)
            # outer corner: the end of the line farther from the face midline
            s_out = np.abs(R[:, 0]) - np.abs(P[:, 0]).min()
            s_out = s_out / max(np.ptp(np.abs(P[:, 0])), 1e-6)
            vert = UP if lid == "upper" else DOWN
            lat = np.sign(eye_c[0]) * LEFT
            d = normalize(FORWARD[None] * 1.0 + vert[None] * 0.35 + lat[None] * (0.5 * s_out[:, None] ** 2))
            L = (0.0095 if lid == "upper" else 0.0055) * lscale * (0.55 + 0.45 * np.sin(np.pi * (0.15 + 0.8 * s_out)))
            L *= rng.uniform(0.85, 1.1, len(L))
            tris.append(tri)
            barys.append(bary)
            dirs_up.append(np.repeat(vert[None], len(tri), 0))
            s_par.append(d)
            lens.append(L)
            is_upper.append(np.full(len(tri), lid == "upper"))
    tri = np.concatenate(tris)
    bary = np.concatenate(barys)
    vert = np.concatenate(dirs_up)
    d0 = np.concatenate(s_par)
    L = np.concatenate(lens)
    N = len(tri)
    R = surface.points(tri, bary)
    npts = 6
    k = np.linspace(0.0, 1.0, npts)
    # curl: the lash direction rotates toward ``vert`` (up for upper lids, down for lower)
    theta = np.radians(75.0) * curl * k[None, :] ** 1.5 + np.radians(5.0) * rng.normal(0, 1, (N, 1))
    seg = (L / (npts - 1))[:, None, None]
    axis_d = d0[:, None, :]
    perp = normalize(vert - np.einsum("nd,nd->n", vert, d0)[:, None] * d0)[:, None, :]
    steps = np.cos(theta)[..., None] * axis_d + np.sin(theta)[..., None] * perp
    pts = np.empty((N, npts, 3))
    pts[:, 0] = R
    pts[:, 1:] = R[:, None] + np.cumsum(steps[:, :-1] * seg, axis=1)
    layer = np.full(N, 0.0003)
    pts = push_out_strands(surface, pts, layer, exact=True)
    clr = np.minimum(layer[:, None], 0.6 * arc_length(pts))
    styling = Styling(root_radius=(1.1e-4 if mascara else 7e-5) * float(np.sqrt(140.0 / max(n_up, 1))) ** 0.5,
                        tip_shape=0.3, clump=clumping, clump_distance=0.0015, clump_shape=0.7,
                        seed=int(rng.integers(0, 2 ** 31)))
    info = {"style": sid, "colour": colour, "pigment": pg.as_dict(), "guides": N, "upper_per_eye": n_up,
            "length_scale": lscale, "curl": curl}
    g = Groom("eyelashes", f"eyelashes_{sid}", surface, pts, tri, bary, clr, styling, info, pg,
              roughness=0.25, coat=0.3 if mascara else 0.0, exact=True, keep_out=EYEBALLS, keep_skin=True)
    # out of the eyeballs and the lids (the head's push-out can miss the eye where a thin lid
    # fold is nearer): the same settling as on every posed head
    g.pts = attach(g)[1].positions(ctx)
    return g
