"""Closest point on triangles, vectorised (Ericson, Real-Time Collision Detection 5.1.5).

The one implementation used by every fitting module (strands, garment and headwear shells,
glasses). It is geometry, not asset code: it belongs in ``synth/geometry/`` when that
package exists (issue 9, item 4).
"""

from __future__ import annotations

import numpy as np


def dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def closest_on_triangles(p, a, b, c):
    """Closest points of p to triangles (a, b, c) (all broadcastable (..., 3)), after Ericson,
    Real-Time Collision Detection 5.1.5, vectorised. Returns (point, barycentric (..., 3));
    vertex/edge regions give exact 0/1 coordinates; a degenerate triangle gives its centroid
    weights. The one implementation used by every rig (strands, garments, glasses)."""
    p, a, b, c = np.broadcast_arrays(p, a, b, c)
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp = p - b
    d3, d4 = dot(ab, bp), dot(ac, bp)
    cp = p - c
    d5, d6 = dot(ab, cp), dot(ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v_in = np.where(den != 0, vb / den, 1.0 / 3.0)
        w_in = np.where(den != 0, vc / den, 1.0 / 3.0)
        t_ab = np.where(d1 - d3 != 0, d1 / (d1 - d3), 0.0)
        t_ac = np.where(d2 - d6 != 0, d2 / (d2 - d6), 0.0)
        e1, e2 = d4 - d3, d5 - d6
        t_bc = np.where(e1 + e2 != 0, e1 / (e1 + e2), 0.0)
    z = np.zeros_like(d1)
    o = np.ones_like(d1)
    bary = np.stack([1.0 - v_in - w_in, v_in, w_in], -1)
    conds = [
        (va <= 0) & (e1 >= 0) & (e2 >= 0),  # edge BC
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),  # edge AC
        (d6 >= 0) & (d5 <= d6),  # vertex C
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),  # edge AB
        (d3 >= 0) & (d4 <= d3),  # vertex B
        (d1 <= 0) & (d2 <= 0),  # vertex A
    ]
    vals = [
        np.stack([z, 1.0 - t_bc, t_bc], -1),
        np.stack([1.0 - t_ac, z, t_ac], -1),
        np.stack([z, z, o], -1),
        np.stack([1.0 - t_ab, t_ab, z], -1),
        np.stack([z, o, z], -1),
        np.stack([o, z, z], -1),
    ]
    # Ericson's tests run A, B, AB, C, AC, BC, inside and the first match wins: apply them in
    # reverse so that earlier tests overwrite later ones.
    for cond, val in zip(conds, vals):
        bary = np.where(cond[..., None], val, bary)
    q = bary[..., 0:1] * a + bary[..., 1:2] * b + bary[..., 2:3] * c
    return q, bary
