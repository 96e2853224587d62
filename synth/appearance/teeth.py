"""Tooth enamel colour, from spectrophotometric measurements of natural teeth.

The head's teeth were a flat (0.85, 0.82, 0.72) linear sRGB: CIELAB L* 92.5, b* 6.8, whiter
and lighter than teeth are; open mouths showed a bright white band. Intraoral measurements of
maxillary central incisors (Vita Easyshade) give L* 80.6 at ages 11-15 and L* 84.0, a* 0.17,
b* 24.1 over ages 7-15 (Oh et al., J Korean Acad Pediatr Dent 2022;49(4):414-427); adult teeth
are reported darker still. The teeth take the 11-15 group's lightness and the reported a*; b* is
14, chosen by eye below the measured 24 (docs/realism.md, "Teeth"): at 24 the teeth rendered
olive in the mouth's shade, the instrument measures the enamel under its own light.
"""

from __future__ import annotations

from synth.appearance.skin import linear_srgb_from_cielab

#: CIELAB (D65) the teeth's base colour is set to
TOOTH_CIELAB = (80.6, 0.17, 14.0)
#: linear sRGB of :data:`TOOTH_CIELAB` (about 0.65, 0.57, 0.42)
TOOTH_ALBEDO = tuple(round(float(c), 4) for c in linear_srgb_from_cielab(TOOTH_CIELAB))


# ----------------------------------------------------------------------------- per-tooth shading

import numpy as np  # noqa: E402

#: mesiodistal crown widths (mm) from the midline back, central incisor to second molar: mean
#: values of the standard dental-anatomy tables (Wheeler's Dental Anatomy, Physiology and
#: Occlusion): maxillary and mandibular. The head's teeth are one coarse arch per jaw (no
#: separate teeth); these widths place the gaps between teeth along it, scaled to its length.
CROWN_WIDTHS_MM = {
    "upper": (8.5, 6.5, 7.5, 7.0, 6.5, 10.0, 9.0),
    "lower": (5.0, 5.5, 7.0, 7.0, 7.0, 11.0, 10.5),
}
#: angle bins of the arch's centre line (around the back of the arch)
ARCH_BINS = 48


def arch_coordinate(P: np.ndarray, jaw: str = "upper") -> np.ndarray:
    """(N,) position of each vertex of one jaw's teeth ``P`` (N, 3; x across the face, y front
    negative, z up) along its dental arch in **tooth units**: 0 on the midline, +-k at the gap
    after the k-th tooth from the midline (sign: the side of x), so the gaps between teeth lie at
    the integers. The arch's centre line is the mean of the vertices per angle around the arch's
    back midpoint (both halves folded together); the arc length along it from the midline is
    mapped to teeth by :data:`CROWN_WIDTHS_MM`, scaled to fill the arch."""
    P = np.asarray(P, np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 8 or not np.isfinite(P).all():
        raise ValueError("the teeth need at least 8 finite 3D vertices")
    widths = np.asarray(CROWN_WIDTHS_MM[jaw], np.float64)
    c = np.array([0.5 * (P[:, 0].min() + P[:, 0].max()), P[:, 1].max()])
    d = P[:, :2] - c
    # angle from the front (-y) toward +x; the arch is star-shaped around its back midpoint. Both
    # halves are folded onto one (|x|), so mirror vertices get opposite values exactly.
    th = np.arctan2(d[:, 0], -d[:, 1])
    a = np.abs(th)
    fold = np.column_stack([np.abs(d[:, 0]), d[:, 1]])
    edges = np.linspace(0.0, a.max() * (1 + 1e-9) + 1e-12, ARCH_BINS + 1)
    b = np.clip(np.searchsorted(edges, a, side="right") - 1, 0, ARCH_BINS - 1)
    cnt = np.bincount(b, minlength=ARCH_BINS)
    ok = cnt > 0
    mid = np.stack([np.bincount(b, fold[:, k], ARCH_BINS)[ok] / cnt[ok] for k in (0, 1)], 1)
    tmid = 0.5 * (edges[:-1] + edges[1:])[ok]
    # the centre line from the midline (angle 0, at the first bin's depth) along the arch
    mid = np.vstack([[0.0, mid[0, 1]], mid])
    tmid = np.concatenate([[0.0], tmid])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(mid, axis=0), axis=1))])
    sv = np.interp(a, tmid, s)  # arc length of every vertex from the midline (by its angle)
    bounds = np.concatenate([[0.0], np.cumsum(widths)]) * (max(s[-1], 1e-9) / widths.sum())
    return np.sign(d[:, 0]) * np.interp(sv, bounds, np.arange(len(bounds), dtype=np.float64))


#: the ``tooth_arch`` point attribute is the arch coordinate plus this (0 where it is missing
#: then reads as the middle of a tooth, not as a gap)
ARCH_OFFSET = 0.5
#: half width (tooth units) of the dark gap between two teeth, and the width of its soft edge
GAP_HALF = 0.008
GAP_SOFT = 0.045
#: how much darker the gap is (fraction of the enamel colour taken away)
GAP_DARK = 0.5
#: per-tooth brightness variation (full range, fraction)
TOOTH_VARIATION = 0.08
#: the teeth's surface rounds off over this much of a tooth from each gap (a bump)
ROUNDING = 0.3


def arch_attribute(n_vertices: int, regions: dict, vertices: np.ndarray) -> np.ndarray | None:
    """(V,) the head's ``tooth_arch`` point attribute: :func:`arch_coordinate` plus
    :data:`ARCH_OFFSET` on the upper and lower teeth, :data:`ARCH_OFFSET` elsewhere; None when
    the model does not name its upper and lower teeth."""
    if "teeth_upper" not in regions or "teeth_lower" not in regions:
        return None
    out = np.full(n_vertices, ARCH_OFFSET)
    V = np.asarray(vertices, np.float64)
    for name, jaw in (("teeth_upper", "upper"), ("teeth_lower", "lower")):
        idx = np.asarray(regions[name], np.int64)
        out[idx] = arch_coordinate(V[idx], jaw) + ARCH_OFFSET
    return out
