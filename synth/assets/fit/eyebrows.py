"""Eyebrows: strands in a parametric brow shape around the ibug68 brow landmarks
(assets_manifest/eyebrows.toml): arch, thickness profile (thick head, thin tail), density,
unruliness, monobrow. Hairs lie nearly flat on the skin, pointing up at the head of the brow
and outward/down along the tail.

The band under the strands (:func:`band`). A render carries a few hundred strands per face, each a
fraction of a pixel wide at ``preview``: together they cover about a third of the brow, so a brow
read as a thin, faint line whatever its thickness (docs/realism.md, "Eyebrows at the render's
resolution"). Real brows read as a dense band at that size. The band is the optical density the
strands do not carry: a coverage layer on the skin material in the brow's own shape
(:func:`brow_shape`: the strands' thickness profile and arch, :func:`hair_reach` above the roots,
the monobrow's glabella patch), with an
optical depth of :data:`BAND_DEPTH` x density at full coverage, less what the strands of this
render already give (:func:`strand_depth`: their projected area over the brow's, which grows with
the strand count and so with the resolution). So the brow's total optical depth is the style's at
every resolution, and the strands keep the hair-by-hair structure where the pixels resolve it.
The band's colour is the hair mass's (:func:`band_colour`). It is drawn per shading point from
per-vertex brow coordinates (:func:`band_coordinates`, written once at build, so the band moves
with the skin under expressions exactly as the strands' root triangles do); it draws no random
number."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.appearance import pigment as pig
from synth.assets.fit.groom import Groom, Styling, setup
from synth.assets.fit.strands import LEFT, UP, arc_length, push_out_strands, scale_count
from synth.assets.params import AssetPick
from synth.geometry.normals import normalize
from synth.model.meshutil import smoothstep

#: the band's optical depth at full coverage per unit of the ``density`` parameter (the strands'
#: share included): calibrated on preview renders against real photos (docs/realism.md)
BAND_DEPTH = 3.0
#: across the brow, w being the offset from the middle of what the hairs cover over half its height
#: (:func:`band_coordinates`): full coverage from -BAND_LOW[0] to BAND_UP[0], none below -BAND_LOW[1]
#: or above BAND_UP[1]: a defined lower edge, a feathered upper one
BAND_LOW, BAND_UP = (0.7, 1.2), (0.45, 1.5)
#: the monobrow's glabella patch: full up to g = BAND_FULL, none from BAND_EDGE
BAND_FULL, BAND_EDGE = 0.6, 1.35
#: along it: faded in from the head's end (s = -BAND_END) to s = BAND_HEAD (a feathered head), out
#: over BAND_END after the tail
BAND_END, BAND_HEAD = 0.04, 0.1
#: the head's outline is rounded: its fade moves along the brow by BAND_ROUND x w^2 (at the
#: band's upper and lower edges, |w| = 1, about 4 mm toward the tail)
BAND_ROUND = 0.1
#: the share of a hair's mean tip height (:func:`hair_reach`) the band covers above the roots
REACH_SHARE = 0.6
#: the tail carries this much less density than the head
BAND_TAIL = 0.35
#: the monobrow's glabella patch at this share of the brows' density (the groom keeps half its roots)
MONO_SHARE = 0.5
#: what a vertex far from the brows gets as its across-coordinate (no band)
FAR = 8.0
#: how far (m) a vertex may lie from the brow line other than vertically and still carry the band
#: (faded out over the last 3 mm)
DEPTH_REACH = 0.012
#: the hair mass's colour (:func:`band_colour`): the share of light a fibre scatters back after
#: twice its absorption, the specular reflection of its cuticle, an unpigmented fibre's albedo
MASS_SCATTER, MASS_SHEEN, WHITE_MASS = 0.6, 0.03, 0.3
#: the shader's texture (``blender_scripts.assets.eyebrows.band_nodes``): the shape times
#: 1 + TEXTURE x (2 noise - 1), a Noise texture over the brow coordinates, TEXTURE_SCALE cells per
#: unit of s and w (about 1.5 mm along, 1-2 mm across): hair-scale unevenness, mean one
TEXTURE, TEXTURE_SCALE = 0.35, (30.0, 2.5)


def counts(resolution: int, density: float = 1.0) -> int:
    return max(40, int(scale_count(resolution, 1.6, 160, 1600) * float(density)))


def brow_shape(s, thick: float, arch: float) -> tuple[np.ndarray, np.ndarray]:
    """The brow's centre line (vertical offset from the landmark polyline, m) and thickness (m) at
    ``s`` (0 inner end, 1 outer; clamped): the roots of the strands lie within half the thickness
    of the centre line, and the band follows the same shape."""
    s = np.clip(s, 0, 1)
    centre = (arch - 0.3) * 0.008 * np.sin(np.pi * s ** 0.8) - 0.0015
    return centre, thick * 0.0085 * (1.0 - 0.6 * s) + 0.0015


def hair_direction(s) -> np.ndarray:
    """A brow hair's mean angle above the horizontal (rad) at ``s``: up at the head, outward and
    down along the tail (the groom adds its unruliness around it)."""
    return np.radians(70.0 - 85.0 * np.asarray(s, np.float64))


def hair_length(s) -> np.ndarray:
    """A brow hair's length (m) at ``s`` before the groom's per-strand factor (0.7-1.1)."""
    return 0.008 - 0.003 * np.asarray(s, np.float64)


def hair_reach(s) -> np.ndarray:
    """How far (m) above its root a brow hair reaches densely at ``s`` (0 where the hairs point
    down): :data:`REACH_SHARE` of its mean tip height (the groom's length factor averages 0.9;
    a hair thins toward its tip). The band covers the roots' band and this much above it."""
    s = np.clip(s, 0, 1)
    return REACH_SHARE * hair_length(s) * np.maximum(np.sin(hair_direction(s)), 0.0)


def _brow_coords(p, line):
    """(s in [0,1] inner->outer, vertical offset above the line, distance) to a brow polyline
    (nearest point over its segments, each extended by 30 % at both ends; ties: the first)."""
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
    return s, v, d[i, j]


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
        s, v, _ = _brow_coords(p, line)
        on_side = np.sign(p[:, 0] - 0.5 * (lm[21, 0] + lm[22, 0])) == sign
        centre, h = brow_shape(s, thick, arch)
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
    ang = hair_direction(s) + np.radians(40.0) * unruly * rng.normal(0, 1, N)
    d = np.cos(ang)[:, None] * side[:, None] * LEFT[None] + np.sin(ang)[:, None] * UP[None]
    d = normalize(d - np.einsum("nd,nd->n", d, nrm)[:, None] * nrm)
    L = hair_length(s) * rng.uniform(0.7, 1.1, N) * (0.8 if sid == "sparse" else 1.0)
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


# --------------------------------------------------------------------------- the band under the strands


@dataclass(frozen=True)
class BrowBand:
    """What the eyebrow rig paints on the skin: per-vertex brow coordinates (V, 3) (s along the
    brow, w across it over half its thickness, g the monobrow's glabella coordinate; :data:`FAR`
    where there is no brow), the optical depth at full coverage, the colour, and the record."""

    coords: np.ndarray
    depth: float
    colour: tuple[float, float, float]
    mono_share: float
    record: dict


def band_coordinates(V: np.ndarray, lm: np.ndarray, thick: float, arch: float, mono: bool,
                     near: np.ndarray | None = None) -> np.ndarray:
    """(V, 3) brow coordinates of the vertices ``V`` for the ibug68 points ``lm`` (the strands'
    :func:`brow_shape`): s in [-0.5, 1.5] along the vertex's own side's brow; w the offset from
    the middle of what the hairs cover (the roots' band and :func:`hair_reach` above it) over half
    its height, clipped to +-:data:`FAR`; g (monobrow only, else :data:`FAR`) the larger of the
    offsets from the glabella patch's centre over its half width and half height.

    A vertex not in ``near`` (default: all) gets |w| = g = FAR, keeping the sign of its w (w = 0:
    up), so that no triangle between it and the brow interpolates a band it does not have; so,
    gradually, does one that lies off the brow line other than vertically (behind it: the eye
    sockets' lining; beyond its ends), over the last 3 mm before :data:`DEPTH_REACH` (g: off the
    glabella in depth). Continuous in the vertex positions, so that no last-bit difference flips
    a vertex in or out, and linear interpolation over a triangle draws the brow's outline finer
    than the triangles. The side: x below the brows' midpoint is the subject's right, at it or
    above the left (both give no band there: the midline lies beyond both brows' heads)."""
    V = np.asarray(V, np.float64)
    out = np.zeros((len(V), 3))
    out[:, 1:] = FAR
    keep = np.ones(len(V), bool) if near is None else np.asarray(near, bool)
    mid = 0.5 * (lm[21] + lm[22])
    left = V[:, 0] >= mid[0]
    for side, line in ((False, lm[17:22][::-1]), (True, lm[22:27])):
        on = np.flatnonzero(left == side)
        s, v, d = _brow_coords(V[on], line)
        centre, h = brow_shape(s, thick, arch)
        lo, hi = centre - 0.5 * h, centre + 0.5 * h + hair_reach(s)
        w = np.clip((v - 0.5 * (lo + hi)) / (0.5 * (hi - lo)), -FAR, FAR)
        off = np.where(keep[on], smoothstep(np.sqrt(np.maximum(d * d - v * v, 0.0)), DEPTH_REACH - 0.003,
                                            DEPTH_REACH), 1.0)
        out[on, 0] = np.clip(s, -0.5, 1.5)
        out[on, 1] = np.clip(w + np.where(w < 0.0, -FAR, FAR) * off, -FAR, FAR)
    if mono:
        half_w = 0.5 * abs(lm[22, 0] - lm[21, 0])
        g = np.maximum(np.abs(V[:, 0] - mid[0]) / half_w, np.abs(V[:, 2] - mid[2]) / (0.004 * thick))
        off = np.where(keep, smoothstep(np.abs(V[:, 1] - mid[1]), DEPTH_REACH - 0.003, DEPTH_REACH), 1.0)
        out[:, 2] = np.minimum(g + FAR * off, FAR)
    return out


def band_shape(coords: np.ndarray, mono_share: float = MONO_SHARE) -> np.ndarray:
    """The band's relative density (0..1) at brow coordinates (..., 3): across, :data:`BAND_LOW`
    and :data:`BAND_UP`; along, faded in over the head (:data:`BAND_END`, :data:`BAND_HEAD`,
    rounded by :data:`BAND_ROUND`) and out after the tail, the tail :data:`BAND_TAIL` lighter;
    the glabella patch at ``mono_share``.
    The shader evaluates the same formula per shading point (``blender_scripts.assets.eyebrows
    .band_nodes``), times its mean-one texture."""
    c = np.asarray(coords, np.float64)
    s, w, g = c[..., 0], c[..., 1], c[..., 2]
    across = smoothstep(w, -BAND_LOW[1], -BAND_LOW[0]) * smoothstep(w, BAND_UP[1], BAND_UP[0])
    head = s - BAND_ROUND * w * w
    ends = smoothstep(head, -BAND_END, BAND_HEAD) * smoothstep(s, 1.0 + BAND_END, 1.0)
    tail = 1.0 - BAND_TAIL * np.clip(s, 0.0, 1.0)
    return np.maximum(across * ends * tail, mono_share * smoothstep(g, BAND_EDGE, BAND_FULL))


def band_coverage(coords: np.ndarray, depth: float, mono_share: float = MONO_SHARE) -> np.ndarray:
    """The band's coverage: 1 - exp(-depth x :func:`band_shape`)."""
    return 1.0 - np.exp(-float(depth) * band_shape(coords, mono_share))


def brow_area(lm: np.ndarray, thick: float) -> float:
    """Both brows' area (m^2): the thickness :func:`brow_shape` gives, integrated along the
    landmark polylines (curvature of the skin ignored)."""
    s = np.linspace(0.0, 1.0, 101)
    h = brow_shape(s, thick, 0.3)[1]
    mean_h = float(np.mean(0.5 * (h[:-1] + h[1:])))
    length = sum(float(np.linalg.norm(np.diff(lm[a:b], axis=0), axis=1).sum()) for a, b in ((17, 22), (22, 27)))
    return mean_h * length


def strand_depth(g: Groom, lm: np.ndarray, thick: float) -> float:
    """The strands' mean optical depth over the brows: their projected area (length x root
    diameter x the mean of the taper profile, :func:`synth.assets.fit.groom.profile`) over
    :func:`brow_area`. Strands lie nearly flat on the skin, so their area on it is their full area."""
    from synth.assets.fit.groom import profile

    L = np.linalg.norm(np.diff(np.asarray(g.pts, np.float64), axis=1), axis=2).sum(1)
    taper = float(np.mean(profile(np.linspace(0.0, 1.0, 201), g.styling.tip_shape)))
    return float(L.sum() * 2.0 * g.styling.root_radius * taper / brow_area(lm, thick))


def band_colour(pg: pig.HairPigment) -> tuple[float, float, float]:
    """Linear RGB albedo of a mass of these hairs seen from the front: pigmented fibres scatter
    :data:`MASS_SCATTER` of the light that crosses them twice (exp(-2 sigma_a)) plus the cuticle's
    :data:`MASS_SHEEN`; the unpigmented share (``white_fraction``) :data:`WHITE_MASS`."""
    pigmented = MASS_SCATTER * np.exp(-2.0 * pg.absorption()) + MASS_SHEEN
    wf = float(pg.white_fraction)
    return tuple(float(x) for x in (1.0 - wf) * pigmented + wf * WHITE_MASS)


def band(ctx, entry, g: Groom) -> BrowBand:
    """The band under the strands of ``g`` (the groom of ``entry`` on ``ctx``), module docstring."""
    prm = AssetPick.coerce("eyebrows", entry).params
    thick, dens, arch, mono = float(prm.thickness), float(prm.density), float(prm.arch), bool(prm.monobrow)
    lm = np.asarray(ctx.landmarks["ibug68"], np.float64)
    V = np.asarray(ctx.vertices, np.float64)
    regions = np.zeros(len(V), bool)
    for r in ("brow", "face"):
        if r in ctx.data.regions:
            regions[np.asarray(ctx.data.regions[r])] = True
    coords = band_coordinates(V, lm, thick, arch, mono, regions)
    strands = strand_depth(g, lm, thick)
    depth = max(0.0, BAND_DEPTH * dens - strands)
    colour = band_colour(g.pigment)
    record = {"optical_depth": round(depth, 4), "strand_depth": round(strands, 4),
              "colour": [round(c, 4) for c in colour]}
    return BrowBand(coords, depth, colour, MONO_SHARE if mono else 0.0, record)
