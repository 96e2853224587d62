"""Measurements of the eyelids on evaluated vertices, independent of the rig's own maths
(``synth.model.eyelids``): the eyeball is measured from its vertices, not from the joints.

- :func:`margin_gaps`: for every lid-margin vertex, its distance from the eyeball's surface
  (negative: inside). The surface radius along a direction is interpolated from the eyeball's
  own vertices by their angle from the eye's axis (sphere and corneal bulge alike).
- :func:`medial_distances`: for every lid-margin vertex, its distance along the fissure (x on
  the template) from the medial canthus: the lids' lacrimal part, which the rig leaves off the
  eyeball (``synth.model.eyelids.CANTHAL_HOLD_M``), is the margin within a few millimetres of it.
- :func:`lid_opening`: the largest distance from an upper-margin vertex to the lower margin
  (a polyline in the margin's order): the opening when open, ~0 when the upper margin lies on
  the lower one.
"""

from __future__ import annotations

import numpy as np

from synth.geometry.normals import normalize
from synth.model.meshutil import fit_sphere


def _eye(data, V: np.ndarray, side: str):
    """(centre, forward axis, (angle, radius) profile sorted by angle) of one eye."""
    c = fit_sphere(V[np.asarray(data.regions[f"sclera_{side}"], np.int64)])[0]
    f = normalize(V[np.asarray(data.regions[f"iris_{side}"], np.int64)].mean(0) - c)
    q = V[np.asarray(data.regions[f"eye_{side}"], np.int64)] - c
    r = np.linalg.norm(q, axis=1)
    t = np.arccos(np.clip(q @ f / r, -1.0, 1.0))
    o = np.argsort(t)
    return c, f, t[o], r[o]


def margin_gaps(data, vertices, side: str) -> dict[str, np.ndarray]:
    """{"upper": gaps, "lower": gaps} in metres for the margin vertices of eye ``side``."""
    V = np.asarray(vertices, np.float64)
    c, f, t_prof, r_prof = _eye(data, V, side)
    out = {}
    for lid in ("upper", "lower"):
        q = V[np.asarray(data.regions[f"eyelid_{side}_{lid}"], np.int64)] - c
        r = np.linalg.norm(q, axis=1)
        t = np.arccos(np.clip(q @ f / r, -1.0, 1.0))
        out[lid] = r - np.interp(t, t_prof, r_prof)
    return out


def medial_distances(data, side: str) -> dict[str, np.ndarray]:
    """{"upper": d, "lower": d}: each margin vertex's distance (metres, along x on the template)
    from the medial canthus (the margin's end on the nose side) of eye ``side``, in the order of
    :func:`margin_gaps`."""
    T = np.asarray(data.template, np.float64)
    out = {}
    for lid in ("upper", "lower"):
        x = T[np.asarray(data.regions[f"eyelid_{side}_{lid}"], np.int64), 0]
        out[lid] = np.abs(x - x[np.argmin(np.abs(x))])
    return out


def _point_polyline_distance(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.einsum("psk,sk->ps", p[:, None] - a[None], ab) / np.maximum((ab * ab).sum(1), 1e-30), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None] - closest, axis=2).min(1)


def lid_opening(data, vertices, side: str) -> float:
    """Largest distance (metres) from an upper-margin vertex to the lower margin of eye ``side``, a
    polyline through its vertices in their order along the margin: by x on the template, where the
    margin runs from canthus to canthus. (Sorted by x as posed, a closed lid's margin, which folds
    near the canthi, joined vertices that are not neighbours: 0.78 mm read where it lies 0.11 mm.)"""
    V = np.asarray(vertices, np.float64)
    up = V[np.asarray(data.regions[f"eyelid_{side}_upper"], np.int64)]
    lo = np.asarray(data.regions[f"eyelid_{side}_lower"], np.int64)
    lo = V[lo[np.argsort(np.asarray(data.template)[lo, 0])]]
    return float(_point_polyline_distance(up, lo).max())
