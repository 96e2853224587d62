"""The pieces garments are made of, fitted to a :class:`~synth.assets.fit.body.Body`; pure numpy.

Necklines are height functions ``z(theta)`` around the neck base (``theta`` from
:class:`~synth.assets.fit.body.NeckFrame`: 0 in front); the torso shell is the skin of the
``neck`` and ``shoulders`` regions clipped under a neckline and offset along the normals by
the fabric thickness plus folds (:mod:`synth.assets.fit.folds`). Add-ons: rim tubes on the cut
(shirt collars and a turtleneck's roll: :mod:`synth.assets.fit.collars`), ties,
tubes around the neck (rolled collars, scarves, hoods down), strips hanging down the chest
(scarf ends, drawstrings) and a raised hood. Each adds its mesh to a
:class:`~synth.assets.fit.body.Parts` with a material slot.
"""

from __future__ import annotations

import numpy as np

from synth.assets.fit.attach import push_out
from synth.assets.fit.body import Body, Parts
from synth.assets.fit.hem import CAP_INSET, HEM_BAND, cap, hem_loops, smooth_loops
from synth.assets.fit.masks import jaw_line

#: passes of averaging along a torso shell's neckline loops (then evenly respaced)
NECK_SMOOTHING = 12
#: radius (m) of the rounded tip of a V neckline
V_TIP_RADIUS = 0.01
#: an opening of a torso shell's field must span this many body vertices (smaller ones are closed)
MIN_OPENING = 8
#: a torso shell is subdivided once (the body's 2 cm triangles halved: 8-10 mm edges, five or more
#: a fold's wavelength, synth.assets.fit.folds) but within this distance (m, along the body) of
#: the hem: the hem keeps the body's triangles, so it is smoothed and pushed out as before
HEM_COARSE = 0.03
from synth.assets.fit.meshops import (grid_faces, icosphere, laplacian_smooth, negative_regions,
                                      oriented_boundary_loops, sweep_tube)


def front_weight(th):
    return np.maximum(np.cos(th), 0.0)


def crew_neckline(body: Body, rise: float, drop: float):
    fr = body.frame

    def z(th):
        return np.minimum(fr.z_ring(th) + rise + 0.008 * (1 - np.cos(th)) - drop * front_weight(th) ** 3, fr.z_cap(th))
    return z


def vee_neckline(body: Body, rise: float, depth: float, half_angle: float):
    """A V ``depth`` deep, ``half_angle`` wide (radians around the neck) on a crew line; its tip
    rounded to a radius of about :data:`V_TIP_RADIUS` (a hyperbola in theta: a sharp tip is one
    loop vertex turning by 100-130 degrees)."""
    fr = body.frame
    slope = depth / max(half_angle * fr.radius, 1e-6)  # height per length along the neck
    a = V_TIP_RADIUS * slope / fr.radius  # hyperbola parameter (radians) for that tip radius

    def z(th):
        v = depth * np.maximum(0.0, 1.0 - (np.sqrt(np.asarray(th) ** 2 + a * a) - a) / half_angle)
        return np.minimum(fr.z_ring(th) + rise + 0.008 * (1 - np.cos(th)) - v, fr.z_cap(th))
    return z


def torso_shell(body: Body, parts: Parts, z_fn, off_fn, slot=0, extra_field=None, rim: float = 0.0,
                rim_slot=None, rim_flatten: float = 1.0, sleeves: str = "long"):
    """Torso shell under the neckline ``z_fn`` and above the hem (:mod:`synth.assets.fit.hem`),
    with an optional rim tube on the neckline (and the sleeves' ends) and a cap closing the hem
    from below. ``sleeves``: over the bust's upper arms, 'long' (to the elbows), 'short' or 'none'
    (:func:`synth.assets.fit.arms.sleeve_field`; a model without the arms ignores it)."""
    from synth.assets.fit.arms import sleeve_field

    th = body.frame.theta(body.V)
    f = z_fn(th) - body.V[:, 2]
    if extra_field is not None:
        f = extra_field(f)
    sl = sleeve_field(body.arms, sleeves)
    if sl is not None:
        f = np.minimum(f, sl)
    hem_f = body.hem
    # a neckline never reaches the hem (a deep V on a short torso): it stops HEM_BAND above it
    f = np.maximum(f, HEM_BAND - hem_f)
    # pinholes (a field just under 0 at a few vertices) would be openings of a dozen vertices
    lab = negative_regions(body.F[body.torso_tris], np.where(np.isin(np.arange(len(f)), body.F[body.torso_tris]), f, 1.0))
    size = np.bincount(lab)
    f = np.where((f < 0) & (size[lab] < MIN_OPENING), 0.0, f)
    # off the hem's band: the nearest body vertex's hem distance (ties to the lowest index: the
    # same faces on every machine for the same vertices)
    from scipy.spatial import cKDTree

    tree = cKDTree(body.V)

    def off_hem(C):
        return hem_f[tree.query(C)[1]] > HEM_COARSE
    P, F, cut, W = body.shell(body.torso_tris, np.minimum(f, hem_f), off_fn, weights=True, refine=off_hem)
    on_hem = cut & (np.abs(np.asarray(W @ hem_f)) < 1e-7)
    P = smooth_loops(P, F, on_hem)
    # every other boundary loop (the neckline, a tank top's arm holes), spread evenly along itself
    P = smooth_loops(P, F, ~on_hem, NECK_SMOOTHING, min_fraction=1.0, resample=True)
    # the rim tubes are laid on the necklines after the fit (``trim.add_rims``): the trim and the
    # push-out move them
    spec = (rim, rim_flatten, slot if rim_slot is None else rim_slot) if rim > 0 else None
    parts.add(P, F, slot, trim=True, smooth_edge=~on_hem, rim=spec)
    for loop in hem_loops(F, on_hem):
        Vc, Fc = cap(P, loop, inset=CAP_INSET)
        parts.add(Vc, Fc, slot, inside=True)
    return P, F, cut


def necktie(body: Body, parts: Parts, slot: int, base_off: float):
    fr = body.frame
    knot_z = min(float(fr.z_ring(0.0)) + 0.012, float(fr.z_cap(0.0)) - 0.02)
    top = body.neck_loop(lambda t: np.full_like(t, knot_z), 48, angle0=np.pi)[0]
    zs = np.linspace(knot_z - 0.015, body.V[:, 2].min() + 0.005, 12)
    path = np.stack([np.zeros_like(zs) + top[0], np.full_like(zs, top[1] - 0.03), zs], 1)
    path = push_out(path, body.query, base_off + 0.006)
    path = laplacian_smooth(path, np.stack([np.arange(11), np.arange(1, 12), np.arange(1, 12)], 1), 3, 0.5,
                                pinned=np.isin(np.arange(12), [0, 11]))
    w = np.linspace(0.018, 0.04, len(zs))
    Vt, Ft = sweep_tube(path, w, 8, closed=False, flatten=0.12, up_hint=np.array([0.0, 1.0, 0.0]))
    parts.add(push_out(Vt, body.query, base_off + 0.003), Ft, slot)
    Vs, Fs = icosphere(2)
    knot = top + np.array([0.0, -0.008, -0.005]) + fr.outward(top[None])[0] * base_off
    Vk = knot + Vs * np.array([0.016, 0.009, 0.014])
    parts.add(push_out(Vk, body.query, base_off + 0.003), Fs, slot)


def neck_tube(body: Body, parts: Parts, slot: int, z_fn, radial: float, radius_v: float, angles=None,
               n: int = 48, taper: bool = False):
    """Tube around (part of) the neck at height z_fn(theta): section ``radius_v`` high and
    ``radial`` thick, sitting ``radial`` outside the skin."""
    fr = body.frame
    loop = body.neck_loop(z_fn, n, angle0=np.pi)
    th = fr.theta(loop)
    if angles is not None:
        lo, hi = angles
        m = (np.mod(th, 2 * np.pi) >= lo) & (np.mod(th, 2 * np.pi) <= hi)
        loop = loop[m][np.argsort(np.mod(th[m], 2 * np.pi))]
    path = body.query.query(loop).point + fr.outward(loop) * (radial + 0.003)
    closed = angles is None
    r = np.full(len(path), radius_v)
    if taper and not closed:
        s = np.linspace(0, 1, len(path))
        r = radius_v * np.clip(np.sin(np.pi * s) * 1.6, 0.15, 1.0)
    Vt, Ft = sweep_tube(path, r, 12, closed=closed, flatten=radial / radius_v)
    parts.add(Vt, Ft, slot)
    return path


def hanging_strip(body: Body, parts: Parts, slot: int, start: np.ndarray, length: float, width: float, thick: float,
             clearance: float, n: int = 10):
    """A flat strip/tail hanging down the chest from ``start`` (scarf ends, drawstrings)."""
    zs = start[2] - np.linspace(0.0, length, n)
    zs = np.maximum(zs, body.V[:, 2].min() + 0.01)
    path = np.stack([np.full(n, start[0]), np.full(n, start[1]), zs], 1)
    path = push_out(path, body.query, clearance + thick, iterations=4)
    Vt, Ft = sweep_tube(path, width, 8, closed=False, flatten=thick / width, up_hint=np.array([0.0, 1.0, 0.0]))
    parts.add(Vt, Ft, slot)


def hood_up(body: Body, parts: Parts, slot: int, base_off: float):
    lm = body.lm
    brow = 0.5 * (lm[19] + lm[24])
    jaw = jaw_line(lm)
    ear_y = 0.5 * (jaw[0, 1] + jaw[16, 1]) + 0.012
    z0, z1 = 0.5 * (jaw[0, 2] + jaw[16, 2]), brow[2] + 0.045
    y1 = brow[1] + 0.03
    V = body.V
    t = np.clip((V[:, 2] - z0) / (z1 - z0), 0.0, 1.0)
    y_open = ear_y + (y1 - ear_y) * t
    fr = body.frame
    f = np.minimum(V[:, 1] - y_open, V[:, 2] - (fr.z_ring(fr.theta(V)) + 0.02))
    P, F, cut = body.shell(body.head_tris, f, lambda p, n: np.full(len(p), 0.022), subdiv=1)
    P = laplacian_smooth(P, F, 12, 0.5)
    P = push_out(P, body.query, 0.01)
    P = laplacian_smooth(P, F, 4, 0.5)
    P = push_out(P, body.query, 0.008)
    parts.add(P, F, slot)
    for loop in oriented_boundary_loops(F):
        if cut[loop].mean() > 0.5 and len(loop) > 8:
            Vt, Ft = sweep_tube(P[loop][::2], 0.006, 8, closed=True)
            parts.add(push_out(Vt, body.query, 0.004), Ft, slot)
