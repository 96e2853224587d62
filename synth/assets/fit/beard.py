"""Facial hair on the ``beard`` region (assets_manifest/beard.toml).

Style masks are built from the current ibug68 landmarks (mouth corners, upper lip, chin, jaw
contour), strands grow downward along the skin (tangential gravity blended with the surface
normal), moustaches sweep outward from the philtrum; long beards fall with gravity and are
pushed out of the head/neck.
"""

from __future__ import annotations

import numpy as np

from synth.assets.fit.groom import Groom, Styling, setup
from synth.assets.fit.masks import beard_area, below_cheek_line, jaw_line
from synth.assets.fit.strands import DOWN, LEFT, UP, add_curl, arc_length, grow, push_out_strands, scale_count
from synth.geometry.normals import normalize


#: fewest strands of a partial style (goatee, moustache, chin strap, mutton chops) at low resolution
MIN_PARTIAL_STRANDS = 24
#: strands per area of a partial style relative to a full beard's mean over the region: the
#: chin and the upper lip carry a beard's densest hair (chosen by eye at 256 px; docs/realism.md)
PARTIAL_DENSITY = {"goatee": 2.0, "moustache": 2.0}


#: a long beard's strands leave the skin along its normal over this arc length (m; at 0.01 the
#: beard stands off the face as a curtain)
LONG_LIFT_M = 0.004
#: a long beard's largest clearance from the skin (m)
LONG_LAYER_M = 0.008
#: the share of a long beard's growth direction that is straight down from the root on (at 0 the
#: strands follow the skin for their first 2 cm and hang from the cheeks as curtains)
LONG_FALL = 0.5
#: how strongly a long beard's hair gathers toward the middle below the jaw (per 6 cm off it)
LONG_GATHER = 0.5


def counts(resolution: int, density: float = 1.0) -> int:
    return max(60, int(scale_count(resolution, 14.0, 700, 25000) * float(density)))


def _polyline_distance(p, line):
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.einsum("nkd,kd->nk", p[:, None] - a[None], ab) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
    q = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None] - q, axis=2).min(1)


def groom(ctx, entry) -> Groom:
    st = setup(ctx, entry, "beard")
    rng, sid, prm, surface, hf, colour, pg = st.rng, st.sid, st.prm, st.surface, st.hf, st.colour, st.pg
    lm = hf["lm"]
    # the styles that cover the whole region fade out over BEARD_FEATHER_M at its edge (roots kept
    # with the smoothed region's probability) instead of ending on the region's 7-11 mm triangles
    whole = sid in ("stubble", "short_full", "full_long")
    tris = surface.region_triangles("beard", "any" if whole else "all",
                                    exclude=("lips", "mouth_interior", "teeth", "nose"))
    corner_r, corner_l = lm[48], lm[54]
    x_c = 0.5 * (corner_l[0] + corner_r[0])
    half_w = 0.5 * abs(corner_l[0] - corner_r[0])
    lip_top, lip_bot, subnasal, chin = lm[51], lm[57], lm[33], lm[8]
    jaw = jaw_line(lm)
    moustache = bool(prm.moustache)
    mstyle = str(prm.style)

    def mask(p):
        x = p[:, 0] - x_c
        upper_lip = (p[:, 2] > lip_top[2] - 0.002) & (p[:, 2] < subnasal[2] - 0.001) & (np.abs(x) < half_w + 0.008)
        upper_lip &= p[:, 1] < lip_top[1] + 0.025
        if sid == "stubble" or sid == "short_full" or sid == "full_long":
            m = np.ones(len(p), bool)
            if not moustache:
                m &= ~upper_lip
            return m
        if sid == "goatee":
            chin_zone = (np.abs(x) < half_w + 0.004) & (p[:, 2] < lip_bot[2] + 0.002) & (p[:, 1] < chin[1] + 0.03)
            return chin_zone | (upper_lip if moustache else False)
        if sid == "moustache":
            if mstyle == "pencil":
                return upper_lip & (p[:, 2] < lip_top[2] + 0.005)
            if mstyle == "horseshoe":
                bars = (np.abs(np.abs(x) - half_w - 0.004) < 0.006) & (p[:, 2] < lip_top[2] + 0.004) & (
                    p[:, 2] > chin[2] + 0.01) & (p[:, 1] < chin[1] + 0.03)
                return upper_lip | bars
            return upper_lip
        if sid == "chin_strap":
            w = float(prm.width_m)
            return (_polyline_distance(p, jaw[2:15]) < w) & (p[:, 2] < lip_bot[2])
        if sid == "mutton_chops":
            return (np.abs(x) > half_w + 0.012) & (p[:, 2] > chin[2] + 0.015)
        return np.ones(len(p), bool)

    n = counts(ctx.resolution, float(prm.density))  # over the whole beard region
    t, b = surface.sample(tris, 6 * n + 64, rng)
    P0 = surface.points(t, b)
    ok = mask(P0)
    # the cheek line: how far up the cheek the hair grows (masks.cheek_line); the same line bounds
    # the stubble shadow of the skin-detail rig
    cheek = below_cheek_line(P0, lm, float(prm.reach))
    if whole:
        soft = beard_area(surface.data, surface.V)
        feathered = np.einsum("nk,nk->n", b, soft[surface.T[t]])
        ok &= rng.random(len(t)) < feathered * cheek
        # n strands over the feathered region's area: the draws that many need, whatever the
        # cheek line leaves of it (taking the first n hits packed a low line's beard denser)
        keep = np.nonzero(ok[:int(np.ceil(n / max(float(feathered.mean()), 0.2)))])[0]
    else:
        if sid == "mutton_chops":
            ok &= cheek > 0.5
        # a partial style keeps the region's density (times PARTIAL_DENSITY): of the first n draws
        # (n per region area), those in its mask; taking n from the mask packed a goatee or a
        # moustache with a whole beard's strands (2.3-7.6 times denser: an opaque block). At
        # least MIN_PARTIAL_STRANDS.
        hits = np.nonzero(ok)[0]
        keep = hits[hits < PARTIAL_DENSITY.get(sid, 1.0) * n]
        if len(keep) < MIN_PARTIAL_STRANDS:
            keep = hits[:MIN_PARTIAL_STRANDS]
    tri, bary = t[keep], b[keep]
    if len(tri) < 10:  # degenerate mask on an extreme identity: fall back to the whole region
        tri, bary = t[:n], b[:n]
    N = len(tri)
    R = surface.points(tri, bary)
    nrm = surface.normals(tri, bary)
    x = R[:, 0] - x_c
    upper = (R[:, 2] > lip_top[2] - 0.002) & (R[:, 2] < subnasal[2]) & (np.abs(x) < half_w + 0.008)

    length = float(prm.length_m)
    if sid == "moustache":
        length = {"pencil": min(length, 0.007), "walrus": max(length, 0.02)}.get(mstyle, length)
    L = length * rng.uniform(0.75, 1.0, N)
    side = np.where(x >= 0, 1.0, -1.0)
    curl = float(prm.curl)
    long = sid == "full_long"
    npts = 3 if sid == "stubble" else (16 if long else 6)
    lift = 0.0015 if not long else LONG_LIFT_M
    layer = rng.uniform(0.0005, 0.002 if not long else LONG_LAYER_M, N)

    def field(p, s, k):
        tdown = DOWN[None] - np.einsum("nd,d->n", nrm, DOWN)[:, None] * nrm
        d = normalize(tdown + 1e-9) + 0.35 * nrm
        # moustache hair sweeps outward from the philtrum (handlebar ends turn up)
        mo = upper[:, None] * (0.7 * side[:, None] * LEFT[None])
        if mstyle == "handlebar" and sid == "moustache":
            out = np.clip((np.abs(p[:, 0] - x_c) - half_w) / 0.01, 0.0, 1.0)[:, None]
            mo = mo * 1.5 + out * 1.8 * UP[None]
        if long:
            # from the root on, part straight down and part along the skin (LONG_FALL)
            f = LONG_FALL
            d = (1.0 - f) * normalize(tdown + 1e-9) + (0.35 - 0.2 * f) * nrm + (
                f + 0.8 * np.clip(s / 0.02, 0, 1))[:, None] * DOWN[None]
            # below the jaw the hair gathers toward the middle: a long beard narrows to its end
            # (without this the cheeks' strands hung as two curtains as wide as the face)
            under = np.clip((chin[2] + 0.015 - p[:, 2]) / 0.04, 0.0, 1.0)
            d = d - (LONG_GATHER * under * (p[:, 0] - x_c) / 0.06)[:, None] * LEFT[None]
        return d + mo

    pts = grow(surface, R, nrm, L, npts, field, lift, layer)
    if long and curl > 0.02:
        pts = add_curl(pts, nrm, curl * 0.006 * rng.uniform(0.7, 1.3, N), 0.02, rng.uniform(0, 2 * np.pi, N),
                         start=0.01)
    pts = push_out_strands(surface, pts, layer, exact=True)
    clr = np.minimum(layer[:, None], 0.6 * arc_length(pts))
    radius = float(np.clip(6e-5 * np.sqrt(20000.0 / n), 6e-5, 2.5e-4))  # from the region's density
    styling = Styling(root_radius=radius, tip_shape=0.45, frizz=0.0006 if long else 0.0,
                        seed=int(rng.integers(0, 2 ** 31)))
    info = {"style": sid, "colour": colour, "pigment": pg.as_dict(), "guides": N, "length_m": length}
    if sid == "moustache":
        info["moustache_style"] = mstyle
    return Groom("beard", f"beard_{sid}", surface, pts, tri, bary, clr, styling, info, pg, roughness=0.32, exact=True)


def shape(data, vertices, lm, g: Groom) -> dict:
    """Where a beard grows and how it hangs (docs/realism.md, "Beards"), from its groom ``g`` on
    the head ``vertices`` with ibug68 points ``lm``:

    - ``cheek_roots``: roots on the cheek above the nostrils' wing height, between the moustache's
      outer end and the sideburn (the low cheek line's span);
    - ``upper_lip`` / ``under_lip``: roots per area on the skin between the mouth corners above
      the upper lip (to the subnasale) and in the 12 mm under the lower lip, relative to the
      whole region's;
    - ``spread_below_chin``: the 95th percentile of the strand points' distance from the middle
      3 cm or more below the chin, in jaw half widths (masks.jaw_line); nan without such points."""
    from synth.assets.fit.masks import cheek_line, region_mask

    V, T = np.asarray(vertices, np.float64), np.asarray(data.triangles)
    lm = np.asarray(lm, np.float64)
    r = g.pts[:, 0]
    jaw = jaw_line(lm)
    xc, x0 = 0.5 * (jaw[0, 0] + jaw[16, 0]), 0.5 * abs(jaw[16, 0] - jaw[0, 0])
    xs, _ = cheek_line(lm, 0.0)
    z_wing = 0.5 * (lm[31, 2] + lm[35, 2])
    ax = np.abs(r[:, 0] - xc)
    cheek = int(((ax > xs[3]) & (ax < xs[4]) & (r[:, 2] > z_wing)).sum())
    C = V[T].mean(1)
    area = 0.5 * np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1)
    region = region_mask(data.regions, ("beard",), len(V))[T].all(1)
    per = np.bincount(g.tri, minlength=len(T))
    mean = per[region].sum() / max(area[region].sum(), 1e-12)
    mx, hw = 0.5 * (lm[48, 0] + lm[54, 0]), 0.5 * abs(lm[54, 0] - lm[48, 0])
    between = region & (np.abs(C[:, 0] - mx) < hw)
    upper = between & (C[:, 2] > lm[51, 2]) & (C[:, 2] < lm[33, 2]) & (C[:, 1] < lm[51, 1] + 0.02)
    under = between & (C[:, 2] < lm[57, 2]) & (C[:, 2] > lm[57, 2] - 0.012) & (C[:, 1] < lm[57, 1] + 0.02)

    def rel(sel):
        return float(per[sel].sum() / area[sel].sum() / mean) if sel.any() and mean > 0 else float("nan")

    low = g.pts[g.pts[..., 2] < lm[8, 2] - 0.03]
    spread = float(np.percentile(np.abs(low[:, 0] - xc), 95) / x0) if len(low) else float("nan")
    return {"cheek_roots": cheek, "upper_lip": rel(upper), "under_lip": rel(under), "spread_below_chin": spread}
