"""Scalp hair: procedural strand grooms on the ``scalp`` region (assets_manifest/hair.toml).

Free-flowing styles grow a few hundred to a few thousand guide strands in a style direction
field (parting sweep, gravity, volume) with collision push-out, then interpolate children
in the guides' root-triangle frames. Gathered styles (bun, ponytail, braids) compute every
strand from a shared path (scalp -> tie point -> bun coil / tail / plait).
"""

from __future__ import annotations

import numpy as np

from synth.assets.fit.groom import Groom, Styling, setup
from synth.assets.fit.headwear import headwear_cut
from synth.assets.fit.keepout import envelope, face_keep_out, follow_the_leader, keep_out
from synth.assets.fit.masks import hair_grows
from synth.assets.fit.strands import (BACK, DOWN, FORWARD, LEFT, UP, add_curl, arc_length, grow, interpolate, settle,
                                      push_out_strands, resample_fast, scale_count, transport_frames, trim_at_plane,
                                      trim_below)
from synth.geometry import exact
from synth.geometry.normals import normalize
from synth.model.meshutil import smoothstep

POINTS = {"buzz_cut": 4, "short_straight": 10, "short_curly": 14, "undercut": 14, "short_back_and_sides": 12,
          "medium_wavy": 22, "bob": 20, "long_straight": 28, "long_layered": 28, "long_curly": 40, "afro": 32,
          "bun": 28, "ponytail": 30, "braids": 40, "locs": 36}
#: the styles whose strands are plaited or matted into ropes from a few bases (synth.assets.fit.hair._gathered)
ROPES = ("braids", "locs")


def counts(resolution: int, density: float = 1.0) -> tuple[int, int]:
    """(strands, guides) for a render resolution: ~30 strands per pixel of resolution."""
    n = int(scale_count(resolution, 30.0, 1500, 60000) * float(density))
    g = scale_count(resolution, 2.5, 200, 2000)
    return max(n, 200), min(g, max(n, 200))


#: the strands' taper ("Set Hair Curve Profile" shape, synth.assets.fit.groom.profile): full for
#: most of the length and thinning over the last third (cut hair ends bluntly); the mean radius is
#: 0.76 of the root's (0.4, near linear: 0.58)
TIP_SHAPE = 0.2
#: a real head's scalp hairs and their radius (about 100,000 hairs of 0.05-0.09 mm diameter)
HEAD_HAIRS, HAIR_RADIUS_M = 100000, 3.5e-5


def root_radius(n: int) -> float:
    """The root radius of a groom of ``n`` strands at density 1: a render carries fewer strands than a head has
    hairs, each as much thicker as it stands for more hairs (the strands' summed width is a real
    head's, as a groom's level of detail keeps its coverage), within 0.05-0.5 mm (a pixel is about
    0.8 mm of head at 512 px, 1.6 mm at 256 px: the strands are not resolved one by one)."""
    return float(np.clip(HAIR_RADIUS_M * HEAD_HAIRS / max(int(n), 1), 5e-5, 5e-4))


def _tie_point(surface, hf, direction):
    V = surface.V
    sc = V[surface.data.regions["scalp"]]
    c = hf["centre"]
    u = normalize(np.asarray(direction, np.float64))
    j = int(np.argmax(normalize(sc - c) @ u))
    p = sc[j]
    n = normalize(p - c)
    return p, n


def _sphere_path(c, roots, target, n_points, lift=0.004):
    """Paths from roots to a target point over a sphere around c (radius interpolated)."""
    target = np.broadcast_to(np.asarray(target, np.float64), roots.shape)
    ur, ut = normalize(roots - c), normalize(target - c)
    rr, rt = np.linalg.norm(roots - c, axis=1), np.linalg.norm(target - c, axis=1)[:, None]
    cosw = np.clip(np.einsum("nd,nd->n", ur, ut), -1.0, 1.0)
    w = np.arccos(cosw)
    t = np.linspace(0.0, 1.0, n_points)[None, :]
    sw = np.maximum(np.sin(w), 1e-6)[:, None]
    a = np.where(w[:, None] > 1e-4, np.sin((1 - t) * w[:, None]) / sw, 1 - t)
    b = np.where(w[:, None] > 1e-4, np.sin(t * w[:, None]) / sw, t)
    dirs = normalize(a[..., None] * ur[:, None] + b[..., None] * ut[:, None])
    rad = (1 - t) * rr[:, None] + t * rt + lift * np.sin(np.pi * t) ** 0.5
    return c + dirs * rad[..., None]


def groom(ctx, entry) -> Groom:
    st = setup(ctx, entry, "hair")
    rng, sid, prm, surface, hf, colour, pg = st.rng, st.sid, st.prm, st.surface, st.hf, st.colour, st.pg
    c = hf["centre"]
    density = float(prm.density) * (AFRO_DENSITY if sid == "afro" else 1.0)
    n, g = counts(ctx.resolution, density)
    P = POINTS.get(sid, 20)
    tris = surface.region_triangles("scalp", "all")

    # ---- roots (rejection for receding hairlines), by area, from ctx.rng only
    rec = float(prm.hairline_recession)

    def keep(p):
        return hair_grows(p, hf, rec)

    def roots(m):
        t, b = surface.sample(tris, 2 * m + 16, rng)
        ok = keep(surface.points(t, b))
        t, b = t[ok][:m], b[ok][:m]
        return t, b

    c_tri, c_bary = roots(n)
    n = len(c_tri)
    # the radius a strand needs to stand for its share of a head's hairs at density 1: a denser
    # style (its density, the afro's) has more strands of that width, not thinner ones
    styling = Styling(root_radius=root_radius(counts(ctx.resolution)[0]), tip_shape=TIP_SHAPE,
                        frizz=0.0008, frizz_shape=0.6, seed=int(rng.integers(0, 2 ** 31)))
    info = {"style": sid, "colour": colour, "pigment": pg.as_dict()}

    # ---- under headwear: the hair it covers is not built (hidden, and it would pierce the
    # crown); the rest is cut HAT_MARGIN_M short of its cut plane, under the rim
    hat = None
    if "lm" in hf:
        hat = headwear_cut(ctx.vertices, ctx.data.regions, hf["lm"], ctx.pick("headwear"))
    if hat is not None:
        hat = (hat[0] - HAT_MARGIN_M * hat[1], hat[1])
        under = (surface.points(c_tri, c_bary) - hat[0]) @ hat[1] > 0.0
        c_tri, c_bary = c_tri[~under], c_bary[~under]

    if sid in ("bun", "ponytail") + ROPES:
        pts, clr, g_used = _gathered(ctx, sid, prm, surface, hf, c_tri, c_bary, P, rng)
        info["guides"] = g_used
        if sid == "braids":
            styling.frizz = 0.0004
        elif sid == "locs":  # matted: loose fibres stand off the rope
            styling.frizz = LOC_FRIZZ
    else:
        g_tri, g_bary = roots(g)
        if hat is not None:
            ok = (surface.points(g_tri, g_bary) - hat[0]) @ hat[1] <= 0.0
            g_tri, g_bary = g_tri[ok], g_bary[ok]
        pts, clr, extra = _free(ctx, sid, prm, surface, hf, g_tri, g_bary, c_tri, c_bary, P, rng)
        info["guides"] = int(len(g_tri))
        info.update(extra)
        if sid in ("short_curly", "long_curly", "afro"):
            styling.frizz = 0.0025 if sid == "afro" else 0.0015
            styling.clump = 0.35
            styling.clump_distance = 0.006
        if sid == "buzz_cut":
            styling.frizz = 0.0
            styling.tip_shape = BUZZ_TIP_SHAPE
    if hat is not None:
        roots_under = n - len(c_tri)
        pts, kept = trim_at_plane(pts, *hat)
        pts, c_tri, c_bary = pts[kept], c_tri[kept], c_bary[kept]
        clr = np.minimum(np.asarray(clr)[kept].max(axis=1, keepdims=True), 0.6 * arc_length(pts))
        info["under_headwear"] = {"roots_left_out": int(roots_under), "strands_left_out": int((~kept).sum()),
                                  "margin_m": HAT_MARGIN_M}
    tip = float(min(TIP_LIGHTENING_MAX, TIP_LIGHTENING_PER_M * np.median(arc_length(pts)[:, -1]))) if len(pts) else 0.0
    return Groom("hair", f"hair_{sid}", surface, pts, c_tri, c_bary, clr, styling, info, pg, roughness=0.28,
                 tip_lightening=tip, redness_jitter=REDNESS_JITTER)


#: the shader (blender_scripts.assets.strands.hair_material): the share of the melanin concentration
#: gone at a strand's tip, per metre of the groom's median strand length (the ends of long hair are
#: older, weathered and bleached: 16 % at 26 cm), at most TIP_LIGHTENING_MAX; and the +- range of
#: the Melanin Redness (the pheomelanin share) per strand, beside the BSDF's own +-12 % melanin
TIP_LIGHTENING_PER_M = 0.6
TIP_LIGHTENING_MAX = 0.25
REDNESS_JITTER = 0.08

#: hair under headwear ends this far short of the headwear's cut plane (under its rim tube,
#: 2.5-5 mm in radius: synth.assets.fit.headwear)
HAT_MARGIN_M = 0.003


# --------------------------------------------------------------------------- free styles

#: how far an afro's strands run along the envelope after reaching it (metres); its strand
#: count relative to the other styles (a volume, not a layer over the scalp)
AFRO_WRAP_M = 0.03
AFRO_DENSITY = 2.0

#: the buzz cut's strands leave the scalp at this angle above it (degrees), toward the tangential
#: part of its field there: 3-12 mm long in 3 segments, grown from the root normal they stood their
#: first segment straight up (a dot seen from above). The longer styles keep the normal: their roots
#: rise to the hair's layer before the field lays them over, and slanted roots left more of the
#: scalp uncovered (benchmarks/hair_coverage.py: 93 % against 95 % from above for medium_wavy)
BUZZ_ROOT_ANGLE_DEG = 20.0
#: a buzz cut is clipped to one length: its strands end bluntly (mean radius 0.93 of the root's)
BUZZ_TIP_SHAPE = 0.05

#: loose styles (short, medium, bob, long): the sideways part of the style's sweep (away from the
#: parting) acts above this height over the head's centre and fades over the 5 cm below it, and
#: the outward "volume" pull on every step. Roots at the front hairline keep the sideways sweep
#: down to 3 cm below the centre (it takes them round the face), as does the backward part of the
#: sweep everywhere. With the whole sweep down to 3 cm below the centre and a volume of 0.15 (as
#: the buzz cut, undercut and afro keep) long hair leaves the head sideways at the temples and
#: hangs as a tent (`python -m benchmarks.realism drape`: at eye level 85 mm past the head
#: against 34 mm with these values).
LOOSE_SWEEP_FLOOR_M = 0.03
LOOSE_VOLUME = 0.05

#: long layered hair: each root's length falls from the full length at the nape (LAYER_LOW_M below
#: the head's centre) to ``layer_ratio`` of it at the crown (LAYER_SPAN_M higher), so the ends lie at
#: different heights (face-framing layers at the front, the longest at the back) instead of one
#: curtain's edge; and the cut carries more volume off the head than a one-length cut
LAYER_LOW_M, LAYER_SPAN_M = 0.06, 0.14
LAYERED_VOLUME = 0.09

#: short back and sides: the clipper's taper from ``side_length_m`` on the sides and back to
#: ``top_length_m`` on the top, over SBS_TAPER_M of height from SBS_TAPER_FROM_M above the head's
#: centre (about where the sides turn into the top), SBS_BACK_RISE_M higher at the back (the taper
#: runs up the back of the head to the crown); the top lies close (volume SBS_VOLUME)
SBS_TAPER_FROM_M, SBS_TAPER_M, SBS_BACK_RISE_M = 0.01, 0.045, 0.03
SBS_VOLUME = 0.03


class _AfroField:
    """The afro's direction field: the radial sweep, bent by a smooth random field (3 plane
    waves, 2.5-4 cm wavelength: neighbouring strands wander together, as coily hair forms
    clumps), and turned into the envelope's tangent plane over its outer 3 cm (a per-strand
    random tangent), so that the volume ends in a shell of hair, not in radial tips."""

    def __init__(self, centre, env: float, rng: np.random.Generator, n: int):
        self.ce, self.env = np.asarray(centre, np.float64), float(env)
        self.k = normalize(rng.normal(size=(3, 3))) * (2.0 * np.pi / rng.uniform(0.025, 0.04, 3))[:, None]
        self.phase = rng.uniform(0.0, 2.0 * np.pi, 3)
        self.amp = normalize(rng.normal(size=(3, 3)))
        self.tangent = normalize(rng.normal(size=(n, 3)))

    def __call__(self, p: np.ndarray, radial: np.ndarray) -> np.ndarray:
        wave = np.sin(p @ self.k.T + self.phase) @ self.amp  # (N, 3), each component within +-sqrt(3)
        d = normalize(radial) + 0.6 * wave
        rel = p - self.ce
        r = np.linalg.norm(rel, axis=1, keepdims=True)
        u = rel / np.maximum(r, 1e-9)
        t = self.tangent - np.einsum("nd,nd->n", self.tangent, u)[:, None] * u
        shell = np.clip((r - (self.env - 0.03)) / 0.03, 0.0, 1.0)
        return (1.0 - shell) * normalize(d) + shell * (normalize(t) - 0.3 * u)


#: roots this close (m) to a parting's line are ties between its sides (broken by index)
PARTING_TIE_M = 1e-9


def _free(ctx, sid, prm, surface, hf, g_tri, g_bary, c_tri, c_bary, P, rng):
    c = hf["centre"]
    gr = surface.points(g_tri, g_bary)
    gn = surface.normals(g_tri, g_bary)
    G = len(gr)
    parting = prm.parting
    xp = {"left": c[0] + 0.028, "right": c[0] - 0.028, "centre": c[0]}.get(str(parting))
    fringe = bool(prm.fringe)
    curl = float(prm.curl)
    extra = {"parting": str(parting)}

    rel = gr - c
    front = np.clip((-rel[:, 1] - 0.02) / 0.05, 0.0, 1.0) * (gr[:, 2] > hf["brow_z"] + 0.01)
    top = np.clip((gr[:, 2] - (c[2] + 0.0)) / 0.04, 0.0, 1.0)
    # each guide's side of the parting (its sweep and its children's blend): a root within
    # PARTING_TIE_M of the line is a tie, broken by the guide's index
    dx = gr[:, 0] - (xp if xp is not None else c[0])
    side_sign = np.where(np.abs(dx) > PARTING_TIE_M, np.sign(dx), np.where(np.arange(G) % 2 == 0, 1.0, -1.0))

    group = np.zeros(G, np.int64)  # interpolation groups (children never mix groups)
    side_floor, volume = -0.03, 0.15  # buzz cut, undercut, afro; the loose styles set their own below
    if sid == "buzz_cut":
        L = rng.uniform(*sorted((float(prm.length_m) * 0.85, float(prm.length_m))), G)
        sweep = normalize(BACK[None] * 0.6 + DOWN[None] * 0.6 + 0.0 * gr)
        grav, lift, layer, bend = 0.3, 0.002, np.full(G, 0.0008), 1.0
        sweep_w = 1.0
    elif sid == "undercut":
        is_top = (np.abs(rel[:, 0]) < 0.045) & (gr[:, 2] > c[2] + 0.015) & (rel[:, 1] < 0.06)
        group = is_top.astype(np.int64)
        Lt, Ls = float(prm.top_length_m), float(prm.side_length_m)
        L = np.where(is_top, Lt * rng.uniform(0.85, 1.0, G), Ls * rng.uniform(0.8, 1.0, G))
        sw = {"back": BACK, "left": LEFT, "right": -LEFT}[str(prm.swept)]
        sweep = np.where(is_top[:, None], normalize(sw[None] + 0.15 * UP[None] + 0 * gr), normalize(DOWN + BACK * 0.4 + 0 * gr))
        grav, lift, bend = 0.25, np.where(is_top, 0.015, 0.002), 1.0
        layer = np.where(is_top, rng.uniform(0.004, 0.014, G), 0.001)
        sweep_w = 1.0
        extra["swept"] = str(prm.swept)
    elif sid == "short_back_and_sides":
        Lt, Ls = float(prm.top_length_m), float(prm.side_length_m)
        back = np.clip((rel[:, 1] - 0.02) / 0.05, 0.0, 1.0)
        h = smoothstep((rel[:, 2] - SBS_TAPER_FROM_M - SBS_BACK_RISE_M * back) / SBS_TAPER_M)  # 0 sides/back, 1 top
        L = (Ls + (Lt - Ls) * h) * rng.uniform(0.85, 1.0, G)
        # the top combed away from a side parting (or back without one), the front lifted back
        # off the forehead; the sides and back lie down and back
        top_dir = (np.where(xp is None, 0.0, 1.0) * side_sign[:, None] * LEFT[None] + BACK[None] * (0.5 + front[:, None])
                   + 0.2 * UP[None])
        sweep = normalize(h[:, None] * normalize(top_dir) + (1.0 - h[:, None]) * normalize(DOWN + 0.4 * BACK + 0 * gr))
        grav, lift, bend = 0.25, 0.002 + 0.01 * h, 1.0
        layer = 0.001 + h * rng.uniform(0.003, 0.01, G)
        sweep_w, volume = 1.0, SBS_VOLUME
    elif sid == "afro":
        R = float(prm.volume_radius_m)
        ce = c + np.array([0.0, 0.01, 0.025])
        env = 0.095 + R
        # out to the envelope, then AFRO_WRAP_M more along it: the tips lie in the outer shell
        # (radial tips read as a sea urchin's spines); the path wanders in a coherent field
        L = (np.clip(env - np.linalg.norm(gr - ce, axis=1), 0.02, None) * 1.15 + AFRO_WRAP_M) * rng.uniform(0.9, 1.0, G)
        # up from the front hairline (forward over the forehead the face keep-out would lay it flat)
        sweep = normalize(normalize(gr - ce) + (0.25 + 1.0 * front)[:, None] * UP)
        grav, lift, layer, bend = 0.05, 0.03, rng.uniform(0.01, 0.03, G), 1.0
        sweep_w = 1.0
        afro = _AfroField(ce, env, rng, G)
        extra["volume_radius_m"] = R
    else:
        Lm = float(prm.length_m)
        L = Lm * rng.uniform(0.85, 1.0, G)
        if sid == "long_layered":
            L = L * (1.0 - (1.0 - float(prm.layer_ratio)) * np.clip((gr[:, 2] - (c[2] - LAYER_LOW_M)) / LAYER_SPAN_M,
                                                                    0.0, 1.0))
            extra["layer_ratio"] = float(prm.layer_ratio)
        short = sid in ("short_straight", "short_curly")
        # sweep away from the parting on top, back over the head at the front
        part_dir = np.where(xp is None, 0.0, 1.0) * side_sign[:, None] * LEFT[None] * top[:, None]
        back_dir = BACK[None] * front[:, None] * (1.5 if xp is None else 1.0)
        sweep = part_dir + back_dir + 0.35 * BACK[None] * (xp is None)
        if fringe:
            fr = (front > 0.5) & (np.abs(rel[:, 0]) < 0.055)
            group = fr.astype(np.int64)
            sweep = np.where(fr[:, None], FORWARD[None] * 0.5 + 0 * sweep, sweep)
            extra["fringe"] = True
        sweep = np.where(np.linalg.norm(sweep, axis=1, keepdims=True) < 1e-6, DOWN[None] + 0 * sweep, sweep)
        sweep = normalize(sweep)
        grav = 0.55 if short else 1.0
        lift = 0.006 if short else 0.01
        layer = rng.uniform(0.002, 0.008 if short else 0.012, G)
        bend = 1.0
        sweep_w = 1.6 if short else 1.0
        # roots at the front hairline keep the sideways sweep down to the face: it takes them round it
        # (else they fall over the forehead and the face keep-out has to turn them at the hairline)
        side_floor = LOOSE_SWEEP_FLOOR_M + (-0.03 - LOOSE_SWEEP_FLOOR_M) * front
        volume = LAYERED_VOLUME if sid == "long_layered" else LOOSE_VOLUME

    zc = c[2]
    face_y = float(hf["scalp_lo"][1]) + 0.035
    chin_z = float(hf["chin"][2]) - 0.02 if "chin" in hf else zc - 0.12
    guard = np.ones(G) if not fringe else (group == 0).astype(np.float64)
    g_side = np.where(gr[:, 0] >= c[0], 1.0, -1.0)

    def field(p, s, k):
        # the sweep holds on the top of the head and fades below it; gravity takes over
        w = sweep_w * np.clip((p[:, 2] - (zc - 0.03)) / 0.05, 0.0, 1.0)[:, None]
        w_side = sweep_w * np.clip((p[:, 2] - (zc + side_floor)) / 0.05, 0.0, 1.0)
        if sid in ("afro", "buzz_cut"):
            w, w_side = np.ones_like(w), np.ones_like(w_side)
        sw = w * sweep
        sw[:, 0] = w_side * sweep[:, 0]  # the sideways part (away from the parting) may stop higher
        vol = volume * normalize(p - c)
        # keep hair out of the face: in front of the face plane, push sideways and back
        in_face = ((p[:, 1] < face_y) & (p[:, 2] > chin_z) & (p[:, 2] < hf["brow_z"] + 0.03)
                   & (np.abs(p[:, 0] - c[0]) < 0.08)) * guard
        fg = in_face[:, None] * (2.0 * g_side[:, None] * LEFT[None] + 1.0 * BACK[None])
        if sid == "afro":
            return afro(p, sw + grav * DOWN[None] + vol) + fg
        return sw + grav * DOWN[None] + vol + fg

    # a buzz cut's strands leave the scalp slanted the way they are combed (the others along the normal)
    guides = grow(surface, gr, gn, L, P, field, lift, layer, bend=bend,
                  root_angle=np.radians(BUZZ_ROOT_ANGLE_DEG) if sid == "buzz_cut" else None)

    # curls / waves on guides (children inherit them: coherent locks)
    if sid in ("short_curly", "long_curly", "afro"):
        r = float(prm.curl_radius_m)
        cu = float(prm.curl)
        r_g = r * rng.uniform(0.8, 1.2, G)
        per = r_g * (10.0 - 5.0 * cu) if sid != "afro" else r_g * 5.0
        guides = add_curl(guides, gn, r_g, per, rng.uniform(0, 2 * np.pi, G), start=min(0.01, 0.3 * L.min()))
        extra.update({"curl": cu, "curl_radius_m": r})
    elif curl > 0.02:
        amp = curl * 0.012
        guides = add_curl(guides, gn, amp * rng.uniform(0.8, 1.2, G), 0.05 * rng.uniform(0.85, 1.15, G),
                            rng.uniform(0, 2 * np.pi, G), start=0.03, planar=True)
        extra["curl"] = curl

    # length limits: bob at the jaw, fringe at the brows
    if sid == "bob" or (fringe and sid in ("long_straight", "long_layered", "bob", "medium_wavy")):
        chin_z = float(hf["chin"][2]) if "chin" in hf else c[2] - 0.1
        zcut = np.full(G, -np.inf)
        if sid == "bob":
            zcut[:] = chin_z + 0.015 + 0.01 * rng.random(G)
        if fringe:
            zcut = np.where(group == 1, hf["brow_z"] + 0.006, zcut)
        guides = trim_below(guides, zcut)

    clr_g = layer
    guides = push_out_strands(surface, guides, clr_g)
    if xp is not None:
        # children interpolate within their side of the parting: a child between guides combed
        # to opposite sides would take their mean, straight down through the skull
        group = group * 2 + (side_sign > 0)

    # children in the guides' root frames, within their interpolation group
    cr = surface.points(c_tri, c_bary)
    c_group = np.zeros(len(cr), np.int64)
    if group.max() > 0:
        # a child belongs to the group of its nearest guide (exact distances, lowest index on a tie)
        c_group = group[exact.nearest_index(cr, gr)]
    pts = np.empty((len(cr), guides.shape[1], 3))
    for gid in np.unique(c_group):
        sel_c = c_group == gid
        sel_g = group == gid
        if not sel_g.any():
            sel_g = np.ones(G, bool)
        pts[sel_c], _ = interpolate(surface, g_tri[sel_g], g_bary[sel_g], guides[sel_g], c_tri[sel_c], c_bary[sel_c],
                                      k=3, rng=rng, jitter=0.08)
    if "lm" in hf:  # strands turned out of the wedge in front of the inner face (keepout.py)
        pts, turned, trimmed = keep_out(face_keep_out(surface.data, surface.V, hf["lm"], c), pts)
    clr = np.minimum(float(np.median(layer)), 0.6 * arc_length(pts))
    # children blended from guides that drape over a shoulder on different sides run through it:
    # laid over it from the root on (settle), not folded onto it point by point
    pts = settle(surface, pts, clr)
    pts[:, 1:] = surface.push_out(pts[:, 1:], clr[:, 1:], iterations=2)
    return pts, clr, extra


# --------------------------------------------------------------------------- gathered styles


#: braids: distance of a braid's centre line from the head
BRAID_CLEARANCE_M = 0.01

#: locs: a rope's radius is LOC_FILL of the radius of the scalp patch it gathers (the scalp's area
#: shared among the locs; hair matted into a rope packs much denser than it grows), within
#: LOC_RADIUS_M (3-8 mm: locs are 6-16 mm thick); the strands turn once round the rope's axis every
#: LOC_TWIST radii, and its end rounds off over the last LOC_TIP of its length; loose fibres (frizz)
LOC_SCALP_AREA_M2 = 0.055
LOC_FILL = 0.35
LOC_RADIUS_M = (0.003, 0.008)
LOC_TWIST = 12.0
LOC_TIP = 0.06
LOC_FRIZZ = 0.0012
#: braids: the keep-out's margin beyond the wedge's edge is widened by the angle a braid's
#: radius subtends at the face's radius, times this (its strands wind that far off its centre)
BRAID_KEEPOUT_SPREAD = 1.5


def _braids_beside_the_face(surface, hf, c, cent: np.ndarray, rb: float, clearance: float) -> np.ndarray:
    """Braid centre lines (K, P, 3) turned out of the face keep-out (keepout.py) with a margin for
    the braid's radius ``rb``: braids rooted at the front hairline fall beside the face, not in
    front of the eyes. A braid is never trimmed (a cut braid would end in a stub at the brows):
    the turn it needs is spread along it, whatever its size. The turned lines keep
    ``clearance`` from the head, as they were grown (turned at a constant distance from the
    axis, a line from the forehead can pass the temples closer than that)."""
    ko = face_keep_out(surface.data, surface.V, hf["lm"], c)
    face_r = float(np.median(ko.radius))
    width = 6.0 + np.degrees(BRAID_KEEPOUT_SPREAD * rb / max(face_r, 1e-3))
    out, turned, _ = keep_out(ko, cent, width_deg=width, trim_deg=360.0)
    if turned.any():
        out[turned] = _clear_of_the_head(surface, ko.axis, out[turned], clearance)
    return out


def _clear_of_the_head(surface, axis: np.ndarray, L: np.ndarray, clearance: float, reach: float = 0.04,
                       passes: int = 3) -> np.ndarray:
    """Lines (N, P, 3) moved horizontally away from the vertical ``axis`` where they come closer
    to the head than ``clearance``: each point's shortfall, spread ``reach`` metres along the
    line each way with smoothstep bumps (keepout.envelope: no kinks, unlike a point-wise
    push-out), then the line rebuilt with its segment lengths (roots kept); ``passes`` times."""
    seg = np.linalg.norm(np.diff(L, axis=1), axis=2)
    for _ in range(passes):
        _, d, _ = surface.closest(L[:, 1:].reshape(-1, 3))
        need = np.zeros(L.shape[:2])
        need[:, 1:] = np.maximum(clearance - d.reshape(len(L), -1), 0.0)
        if not need.any():
            break
        s = np.zeros(L.shape[:2])
        s[:, 1:] = np.cumsum(seg, axis=1)
        push = envelope(need, s, reach, reach)
        radial = np.zeros_like(L)
        radial[..., :2] = L[..., :2] - axis
        radial /= np.maximum(np.linalg.norm(radial, axis=-1, keepdims=True), 1e-9)
        L = follow_the_leader(L + push[..., None] * radial, seg)
    return L


def _gathered(ctx, sid, prm, surface, hf, c_tri, c_bary, P, rng):
    c = hf["centre"]
    R = surface.points(c_tri, c_bary)
    N = len(R)
    n1 = 8 if sid in ROPES else 12
    n2 = P - n1
    layer = rng.uniform(0.0015, 0.004, N)
    if sid in ("bun", "ponytail"):
        if sid == "bun":
            h = str(prm.bun_height)
            d = {"low": (0.0, 1.0, -0.15), "mid": (0.0, 1.0, 0.7), "top": (0.0, 0.3, 1.0)}.get(h, (0.0, 1.0, 0.7))
        else:
            h = str(prm.tie_height)
            d = {"low": (0.0, 1.0, -0.4), "mid": (0.0, 1.0, 0.2), "top": (0.0, 0.6, 1.0), "high": (0.0, 0.6, 1.0)}.get(
                h, (0.0, 1.0, 0.2))
        Bs, Bn = _tie_point(surface, hf, d)
        B = Bs + Bn * 0.006
        part1 = _sphere_path(c, R, B, n1 + 1, lift=0.003)
        part1 = push_out_strands(surface, part1, layer)
        if sid == "bun":
            rb = float(prm.bun_radius_m)
            Bc = Bs + Bn * rb * 0.85
            e1 = normalize(B - Bc)[None].repeat(N, 0)
            rnd = normalize(rng.normal(size=(N, 3)))
            e2 = normalize(rnd - (rnd @ e1[0])[:, None] * e1)
            rr = rb * np.sqrt(rng.uniform(0.35, 1.0, N))
            turns = rng.uniform(0.9, 1.6, N)
            th = np.linspace(0.0, 1.0, n2)[1:][None] * turns[:, None] * 2 * np.pi
            coil = Bc + rr[:, None, None] * (np.cos(th)[..., None] * e1[:, None] + np.sin(th)[..., None] * e2[:, None])
            pts = np.concatenate([part1, coil], 1)
            # loose strands: some low roots fall freely instead
            loose = float(prm.loose_strands)
            sel = (rng.random(N) < loose * 0.3) & (R[:, 2] < c[2] - 0.01)
            if sel.any():
                nrm = surface.normals(c_tri[sel], c_bary[sel])
                free = grow(surface, R[sel], nrm, rng.uniform(0.06, 0.14, int(sel.sum())), P,
                              lambda p, s, k: DOWN[None] + 0.2 * normalize(p - c), 0.008, layer[sel])
                pts[sel] = free
            g_used = 1
        else:
            Lt = float(prm.tail_length_m)
            start_dir = normalize(BACK * 0.8 + (UP * 0.6 if h in ("top", "high") else DOWN * 0.3))
            centre = grow(surface, B[None], start_dir[None], np.array([Lt]), n2 + 1,
                            lambda p, s, k: DOWN[None] * 1.0 + 0.25 * BACK[None], 0.05, 0.02)[0]
            t, b1, b2 = transport_frames(centre[None], LEFT)
            disk = rng.normal(size=(N, 2)) * 0.5
            u = np.linspace(0.0, 1.0, n2 + 1)
            rad = 0.007 + 0.022 * u
            off = disk[:, None, 0:1] * (rad[None, :, None] * b1[0][None]) + disk[:, None, 1:2] * (
                rad[None, :, None] * b2[0][None])
            tail = centre[None] + off
            pts = np.concatenate([part1, tail[:, 1:]], 1)
            lt = rng.uniform(0.8, 1.0, N)
            s = arc_length(pts)
            pts = resample_fast(pts, s[:, n1] + lt * (s[:, -1] - s[:, n1]))
            curl = float(prm.curl)
            if curl > 0.02:
                pts = add_curl(pts, np.tile(BACK, (N, 1)), curl * 0.01 * rng.uniform(0.7, 1.2, N), 0.045,
                                 rng.uniform(0, 2 * np.pi, N), start=0.1, planar=False)
            g_used = 1
    else:  # braids, locs
        K = int(np.clip(int(prm.braid_count), 2, 40)) if sid == "braids" else int(np.clip(int(prm.loc_count), 8, 90))
        Lb = float(prm.length_m)
        # braid bases: farthest-point sampling over the roots (deterministic)
        # (exact squared distances; argmax/argmin take the lowest index on a tie)
        base_idx = [int(np.argmax(R[:, 2]))]
        dmin = exact.squared_distances(R, R[base_idx[0]][None])[:, 0]
        for _ in range(K - 1):
            j = int(np.argmax(dmin))
            base_idx.append(j)
            dmin = np.minimum(dmin, exact.squared_distances(R, R[j][None])[:, 0])
        bases = R[base_idx]
        bn = surface.normals(c_tri[base_idx], c_bary[base_idx])
        assign = exact.nearest_index(R, bases)
        Bk = bases + bn * 0.005
        part1 = _sphere_path(c, R, Bk[assign], n1 + 1, lift=0.002)
        # per-braid centre lines hanging down from their bases
        cent = grow(surface, Bk, bn, Lb * rng.uniform(0.85, 1.0, K), n2 + 1,
                      lambda p, s, k: DOWN[None] + 0.3 * normalize(p - c), 0.01, BRAID_CLEARANCE_M)
        if sid == "braids":
            rb = float(np.clip(0.012 * np.sqrt(6.0 / K), 0.003, 0.012))
        else:  # a loc's radius from the scalp area each one gathers (its section's share), within LOC_RADIUS_M
            rb = float(np.clip(LOC_FILL * np.sqrt(LOC_SCALP_AREA_M2 / (np.pi * K)), *LOC_RADIUS_M))
        if "lm" in hf:
            cent = _braids_beside_the_face(surface, hf, c, cent, rb, BRAID_CLEARANCE_M)
        _, b1, b2 = transport_frames(cent, np.tile(LEFT, (K, 1)))
        u = arc_length(cent)  # (K, n2+1)
        if sid == "braids":
            sub = np.arange(N) % 3
            lam = 6.0 * rb
            ph = 2 * np.pi * sub / 3.0
            ang = 2 * np.pi * u[assign] / lam + ph[:, None]
            taper = 1.0 - 0.5 * u[assign] / np.maximum(u[assign][:, -1:], 1e-6)
            jit = rng.normal(size=(N, 2)) * 0.18
            x = rb * taper * (np.sin(ang) + jit[:, :1])
            y = 0.5 * rb * taper * (np.sin(2 * ang) + jit[:, 1:])
        else:  # a rope of matted hair: the strands spread over its round section, slowly twisted,
            # the section even down to a rounded end (its last LOC_TIP of the length)
            frac = u[assign] / np.maximum(u[assign][:, -1:], 1e-6)
            r_s = np.sqrt(rng.uniform(0.0, 1.0, N))[:, None]
            ang = rng.uniform(0.0, 2 * np.pi, N)[:, None] + 2 * np.pi * u[assign] / (LOC_TWIST * rb)
            taper = np.sqrt(np.clip((1.0 - frac) / LOC_TIP, 0.0, 1.0))
            x = rb * r_s * taper * np.cos(ang)
            y = rb * r_s * taper * np.sin(ang)
        plait = cent[assign] + x[..., None] * b1[assign] + y[..., None] * b2[assign]
        pts = np.concatenate([part1, plait[:, 1:]], 1)
        g_used = K
    pts[:, 0] = R
    clr = np.minimum(layer[:, None], 0.6 * arc_length(pts))
    pts[:, 1:] = surface.push_out(pts[:, 1:], clr[:, 1:], iterations=2)
    return pts, clr, g_used


def drape(vertices: np.ndarray, ibug68: np.ndarray, pts: np.ndarray) -> dict:
    """How a groom hangs, in metres (head frame: z up, x across): ``beyond_head`` how far the hair
    reaches past the head at eye level (95th percentile of the hair points' distance from the
    eyes' midline within 1 cm of eye height, less the head's own: 99th percentile of its
    vertices, ears included); ``half_width_below_chin`` the same 95th percentile 5 cm and more
    below the chin (NaN where no hair is); ``standoff`` the median distance of the hair points
    between the chin and 2 cm above the eyes from the nearest head vertex."""
    from scipy.spatial import cKDTree

    V = np.asarray(vertices, np.float64)
    P = np.asarray(pts, np.float64).reshape(-1, 3)
    eye = np.asarray(ibug68, np.float64)[[36, 45]].mean(axis=0)
    chin_z = float(ibug68[8][2])
    head = np.abs(V[:, 2] - eye[2]) < 0.01
    at_eyes = np.abs(P[:, 2] - eye[2]) < 0.01
    below = P[:, 2] < chin_z - 0.05
    band = (P[:, 2] < eye[2] + 0.02) & (P[:, 2] > chin_z)
    pct = lambda sel, q: float(np.percentile(np.abs(P[sel, 0] - eye[0]), q)) if sel.any() else float("nan")  # noqa: E731
    return {"beyond_head": pct(at_eyes, 95) - float(np.percentile(np.abs(V[head, 0] - eye[0]), 99)),
            "half_width_below_chin": pct(below, 95),
            "standoff": float(np.median(cKDTree(V).query(P[band])[0])) if band.any() else float("nan")}
