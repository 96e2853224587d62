"""The body below the bust: a garment-covered torso that carries the silhouette out of the frame
(pure numpy; the rig is ``blender_scripts/assets/garment.py``).

The default bust ends 17-20 cm below the chin, and every garment ends on a hem just above that
cut (:mod:`synth.assets.fit.hem`) with a cap underneath. Framed to fit the head and its hair,
a third of the default views then showed the bust's lower end floating in the frame: a
tailor's dummy, not a person. Real portraits never show where the body ends.

:func:`torso_continuation` builds a closed prism under the garment's hem, in the garment's cloth:

* its horizontal section follows the garment near its hem: around the hem's centre, per angle
  (:data:`ANGLES` bins), the largest radius of the garment's vertices within :data:`BAND` above
  the garment's lowest point at that angle, minus :data:`INSET` (so that the garment's hem stays
  visible as a hem over it), smoothed around; across the arm stumps' openings (the garment's
  lowest point :data:`STUMP_RISE` above its lowest overall) straight between the angles beside;
* it starts :data:`OVERLAP` above the garment's lowest point at each angle (hidden inside the
  garment, so no gap opens at the hem), and runs straight down :data:`LENGTH` below the lowest
  point of the hem: out of every default view (``docs/realism.md``, "The body below the bust");
* its top and bottom are closed by fans on their own vertices (the smooth shading of the walls is
  not bent over the rims).

The prism is rigid; it follows the mean motion of the garment's hem band (:func:`follow`).
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
#: at angles where the garment's lowest point is this far (m) above its lowest point overall (the
#: arm stumps' openings, whose hem runs up over the shoulder), the section runs straight between
#: the neighbouring angles: the lowest vertices there can be the inner rim of the opening
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
        out[k] = t if np.isfinite(t) and t > 0 else 0.5 * (r[p] + r[q])
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


def torso_shell_vertices(fitted) -> np.ndarray:
    """Indices of a fitted garment's torso shell (:class:`synth.assets.fit.body.FittedShell`): the
    largest connected piece of its outer cloth (material slot 0, not a hem cap)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    n = len(fitted.P)
    F = np.asarray(fitted.F, np.int64)
    F = F[np.asarray(fitted.M) == 0]
    if fitted.inside is not None:
        F = F[~np.asarray(fitted.inside, bool)[F].any(1)]
    if not len(F):
        raise ValueError("the garment has no outer cloth to shape the torso from")
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]]])
    g = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    _, label = connected_components(g, directed=False)
    used = np.unique(F)
    return used[label[used] == np.bincount(label[used]).argmax()]


def hem_band(fitted, height: float = 0.02) -> np.ndarray:
    """Indices of the torso shell's vertices within ``height`` of its lowest point: the band the
    torso follows (:func:`follow`)."""
    shell = torso_shell_vertices(fitted)
    z = np.asarray(fitted.P, np.float64)[shell, 2]
    return shell[z < z.min() + height]


def follow(V: np.ndarray, rest: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """The torso's vertices ``V`` moved with the garment's hem band (its rest and current positions):
    by their mean displacement. Below the bust nothing deforms; only a garment bound to the head
    (a hoodie) shifts its hem by a few mm with the jaw."""
    return np.asarray(V) + (np.asarray(moved, np.float64) - np.asarray(rest, np.float64)).mean(0)


def garment_torso(fitted) -> tuple[np.ndarray, np.ndarray]:
    """:func:`torso_continuation` of a fitted garment, shaped by its torso shell
    (:func:`torso_shell_vertices`), so that drawstrings, scarf ends, ties and collars hanging
    below the hem do not shape the body."""
    return torso_continuation(np.asarray(fitted.P, np.float64)[torso_shell_vertices(fitted)])
