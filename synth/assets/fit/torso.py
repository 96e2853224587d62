"""The body below the bust: a garment-covered torso that carries the silhouette out of the frame
(pure numpy; the rig is ``blender_scripts/assets/garment.py``).

The bust ends at the waist (the default model's ``bust_bottom`` loop; a model without the bust:
17-20 cm below the chin), and every garment ends on a hem just above that cut
(:mod:`synth.assets.fit.hem`) with a cap underneath. Framed to fit the head and its hair, the
bust's lower end can show in the frame: a tailor's dummy, not a person. Real portraits never
show where the body ends.

:func:`torso_continuation` builds a closed prism under the garment's hem, in the garment's cloth:

* its horizontal section follows the garment's hem (:func:`hem_rim`: the rim of the cap that
  closes the outer cloth's hem, which is the hem loop itself): around the hem's centre, per angle
  (:data:`ANGLES` bins), the largest radius of the rim's points within :data:`BAND` above its
  lowest point at that angle, minus :data:`INSET` (so that the garment's hem stays visible as a
  hem over it), smoothed around; across an opening of the hem (its lowest point
  :data:`STUMP_RISE` above its lowest overall: a model without the bust has arm stumps there)
  straight between the angles beside, at most as far out as the farther of the two;
* it starts :data:`OVERLAP` above the hem's lowest point at each angle (hidden inside the
  garment, so no gap opens at the hem), and runs straight down :data:`LENGTH` below the lowest
  point of the hem: out of every default view (``docs/realism.md``, "The body below the bust");
* its top and bottom are closed by fans on their own vertices (the smooth shading of the walls is
  not bent over the rims).

The prism is rigid; it follows the mean motion of the hem's rim (:func:`follow`). With the bust
the garment rig adds the forearms (:mod:`synth.assets.fit.arms`) to the same object
(:func:`garment_torso_parts`).
"""

from __future__ import annotations

import numpy as np

#: angle bins of the section around the hem's centre
ANGLES = 96
#: height (m) above the garment's lowest point (per angle) whose vertices shape the section
BAND = 0.01
#: the section lies this far (m) inside the garment's outermost vertices
INSET = 0.003
#: the prism starts this far (m) above the garment's lowest point, inside the garment
OVERLAP = 0.006
#: its top ring lies this much (m) further in than its wall (tucked under the garment)
TUCK = 0.006
#: how far (m) the prism runs below the lowest point of the garment: out of the frame from 70
#: degrees above (the default cameras' highest) at the closest framing
LENGTH = 0.8
#: rings of the prism's wall below its top ring
RINGS = 8
#: at angles where the hem's lowest point is this far (m) above its lowest point overall (a model
#: without the bust: the arm stumps' openings, whose hem runs up over the shoulder), the section
#: runs straight between the neighbouring angles: the lowest points there can be the opening's rim
STUMP_RISE = 0.05
#: passes of circular averaging of the section's radius and height
SMOOTHING = 3


def _fill_circular(values: np.ndarray) -> np.ndarray:
    """Empty bins (NaN) linearly interpolated around the circle from their filled neighbours."""
    ok = np.isfinite(values)
    if ok.all():
        return values
    if not ok.any():
        raise ValueError("the garment has no vertices to shape the torso from")
    k = np.arange(len(values))
    n = len(values)
    kk = np.concatenate([k[ok] - n, k[ok], k[ok] + n])
    vv = np.tile(values[ok], 3)
    return np.interp(k, kk, vv)


def _fill_chords(r: np.ndarray) -> np.ndarray:
    """Empty bins (NaN) of a radius per angle bin filled with the straight line (in the plane)
    between the filled bins on either side: across an opening the section runs straight, where
    interpolating the radius would bulge out."""
    ok = np.isfinite(r)
    if ok.all():
        return r
    if not ok.any():
        raise ValueError("the garment has no vertices to shape the torso from")
    n = len(r)
    phi = (np.arange(n) + 0.5) / n * 2 * np.pi
    u = np.stack([np.cos(phi), np.sin(phi)], 1)
    idx = np.nonzero(ok)[0]
    out = r.copy()
    for k in np.nonzero(~ok)[0]:
        p = idx[idx < k].max() if (idx < k).any() else idx.max()
        q = idx[idx > k].min() if (idx > k).any() else idx.min()
        A, B = r[p] * u[p], r[q] * u[q]
        e = B - A
        den = u[k, 0] * e[1] - u[k, 1] * e[0]
        t = (A[0] * e[1] - A[1] * e[0]) / den if abs(den) > 1e-12 else np.nan
        # a point of the chord lies no farther out than its farther end; beyond that the ray meets
        # the chord's line on the far side of the centre (an opening wider than a half turn)
        ok_t = np.isfinite(t) and 0 < t <= max(r[p], r[q]) * (1 + 1e-9)
        out[k] = t if ok_t else 0.5 * (r[p] + r[q])
    return out


def _smooth_circular(values: np.ndarray, passes: int) -> np.ndarray:
    for _ in range(passes):
        values = 0.5 * values + 0.25 * (np.roll(values, 1) + np.roll(values, -1))
    return values


def section(P: np.ndarray, angles: int = ANGLES) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centre (2,), radius per angle bin (angles,), the garment's lowest z per bin (angles,)) of the
    garment vertices ``P`` (see the module docstring)."""
    P = np.asarray(P, np.float64)
    if len(P) < 3 or not np.isfinite(P).all():
        raise ValueError("the garment's vertices are empty or not finite")
    z_low = P[:, 2].min()
    low = P[P[:, 2] <= z_low + 0.25]  # the lower torso, not the collars or a hood
    lo, hi = low[:, :2].min(0), low[:, :2].max(0)
    c = 0.5 * (lo + hi)
    d = low[:, :2] - c
    b = np.floor((np.arctan2(d[:, 1], d[:, 0]) + np.pi) / (2 * np.pi) * angles).astype(np.int64) % angles
    zmin = np.full(angles, np.inf)
    np.minimum.at(zmin, b, low[:, 2])
    zmin = np.where(np.isfinite(zmin), zmin, np.nan)
    zmin = _fill_circular(zmin)
    near = low[:, 2] <= zmin[b] + BAND
    r = np.full(angles, -np.inf)
    np.maximum.at(r, b[near], np.linalg.norm(d[near], axis=1))
    r[zmin > z_low + STUMP_RISE] = -np.inf
    r = _fill_chords(np.where(np.isfinite(r), r, np.nan))
    return c, _smooth_circular(r, SMOOTHING), _smooth_circular(zmin, SMOOTHING)


def _fan(ring: np.ndarray, centre: np.ndarray, up: bool) -> tuple[np.ndarray, np.ndarray]:
    n = len(ring)
    V = np.vstack([ring, centre[None]])
    i = np.arange(n)
    F = np.stack([i, (i + 1) % n, np.full(n, n)], 1)
    nz = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])[:, 2].sum()
    if (nz > 0) != up:
        F = F[:, ::-1]
    return V, F


def torso_continuation(P: np.ndarray, length: float = LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, triangles) of the closed prism under a garment whose (outer) vertices are ``P``;
    faces point outward."""
    if not length > 0:
        raise ValueError(f"torso length must be positive, got {length}")
    c, r, zmin = section(P)
    n = len(r)
    phi = (np.arange(n) + 0.5) / n * 2 * np.pi - np.pi
    rr = np.maximum(r - INSET, 0.5 * r)
    ray = np.stack([np.cos(phi), np.sin(phi)], 1)
    xy = c + ray * rr[:, None]
    z_top = zmin + OVERLAP
    z_bottom = float(np.asarray(P)[:, 2].min()) - length
    # the top ring, one just under the garment's lowest point, then evenly down to the bottom
    zs = [z_top, zmin - 0.005] + [np.full(n, z) for z in np.linspace(zmin.min() - 0.02, z_bottom, RINGS)[1:]]
    zs = [np.minimum(z, prev - 1e-4) for prev, z in zip([np.full(n, np.inf)] + zs[:-1], zs)]
    rings = [np.column_stack([xy, z]) for z in zs]
    rings[0][:, :2] -= ray * np.minimum(TUCK, 0.25 * rr)[:, None]
    m = len(rings)
    W = np.stack(rings, 1).reshape(-1, 3)  # index u * m + v: angle u, ring v (top first)
    u = np.arange(n)[:, None]
    v = np.arange(m - 1)[None, :]
    a = u * m + v
    b = ((u + 1) % n) * m + v
    Fw = np.concatenate([np.stack([a, a + 1, b + 1], -1).reshape(-1, 3), np.stack([a, b + 1, b], -1).reshape(-1, 3)])
    # outward: the first face's normal against its radial direction
    t = W[Fw[0]]
    nrm = np.cross(t[1] - t[0], t[2] - t[0])
    if np.dot(nrm[:2], t.mean(0)[:2] - c) < 0:
        Fw = Fw[:, ::-1]
    top, Ft = _fan(rings[0], np.append(c, z_top.mean()), up=True)
    bot, Fb = _fan(rings[-1], np.append(c, z_bottom), up=False)
    V = np.vstack([W, top, bot])
    F = np.vstack([Fw, Ft + len(W), Fb + len(W) + len(top)])
    return V, F


def hem_rim(fitted) -> np.ndarray:
    """Indices of the rim of the cap that closes a fitted garment's hem in its outer cloth
    (:class:`synth.assets.fit.body.FittedShell`: faces of material slot 0 on vertices never pushed
    out, ``inside``): the hem loop, 0.5 mm in (``hem.CAP_INSET``). The cap is a fan, so its rim's
    vertices are in two of its faces and its centre in all; a jacket's undershirt (slot 1) and
    drawstrings, scarf ends, ties and collars hanging below the hem do not count."""
    if fitted.inside is None:
        raise ValueError("the garment has no hem cap to shape the torso from")
    F = np.asarray(fitted.F, np.int64)
    inside = np.asarray(fitted.inside, bool)
    cap = F[(np.asarray(fitted.M) == 0) & inside[F].all(1)]
    if not len(cap):
        raise ValueError("the garment has no hem cap in its outer cloth to shape the torso from")
    count = np.bincount(cap.ravel(), minlength=len(inside))
    rim = np.nonzero(count == 2)[0]
    if len(rim) < 8:
        raise ValueError("the garment's hem cap has fewer than 8 rim vertices")
    return rim


def hem_band(fitted) -> np.ndarray:
    """Indices of the vertices the torso follows (:func:`follow`): the hem's rim (:func:`hem_rim`)."""
    return hem_rim(fitted)


def follow(V: np.ndarray, rest: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """The torso's vertices ``V`` moved with the garment's hem rim (its rest and current positions):
    by their mean displacement. Below the bust nothing deforms; only a garment bound to the head
    (a hoodie) shifts its hem by a few mm with the jaw."""
    return np.asarray(V) + (np.asarray(moved, np.float64) - np.asarray(rest, np.float64)).mean(0)


def garment_torso_parts(fitted, body=None, offset: float = 0.0):
    """The parts of the body below and beside the garment: ((prism vertices, faces), (forearms'
    vertices, faces)), each part's faces indexing its own vertices. The prism is
    :func:`torso_continuation` of the hem's rim (:func:`hem_rim`); the forearms
    (:func:`synth.assets.fit.arms.forearms`, their wall ``offset`` outside the elbow's skin) need
    ``body`` = (vertices, triangles, regions) and are empty without it or without the bust's arms."""
    from synth.assets.fit.arms import forearms

    prism = torso_continuation(np.asarray(fitted.P, np.float64)[hem_rim(fitted)])
    if body is None:
        return prism, (np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    V, F, regions = body
    return prism, forearms(V, F, regions, offset)


def garment_torso(fitted, body=None, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`garment_torso_parts` in one mesh: the prism's vertices, then the forearms'."""
    (V, F), (Va, Fa) = garment_torso_parts(fitted, body, offset)
    return np.vstack([V, Va]), np.vstack([F, np.asarray(Fa, np.int64) + len(V)])
