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
  lowest point :data:`STUMP_RISE` above its lowest overall; also a coat's front opening or a
  back hem riding high) straight between the angles beside, at most as far out as the farther
  of the two;
* it starts :data:`OVERLAP` above the garment's lowest point at each angle (hidden inside the
  garment, so no gap opens at the hem), and runs straight down :data:`LENGTH` below the lowest
  point of the hem: out of every default view (``docs/realism.md``, "The body below the bust");
* its top and bottom are closed by fans on their own vertices (the smooth shading of the walls is
  not bent over the rims).

The prism is rigid; it follows the mean motion of the garment's hem band (:func:`follow`).

:func:`arms` hangs an upper arm from each of the garment's arm-stump openings, in the same cloth
(a sleeve): without them the body below the shoulders was only as wide as the chest, 1.5-2.1
face widths in frontal renders where people measure about 3 (bideltoid breadth against head
breadth; ``docs/realism.md``, "Arms"). Each arm is a closed tube, its radius :data:`ARM_RADIUS`
of the torso's width, its inner :data:`ARM_INSIDE` of the radius inside the torso's side. Its top
is a cap that is high on the inside and low on the outside (:data:`ARM_CAP_IN`,
:data:`ARM_CAP_OUT`): seen from the front, the shoulder goes on from the garment's shoulder down
and out over the deltoid instead of rising into a knob. The cap's surface at the torso's side lies
:data:`ARM_TUCK` under the garment's shoulder there (the sleeve's seam shows as a hem over it);
the arm tapers to :data:`ARM_TAPER` at :data:`ELBOW` below the cap and runs as far down as the
torso.
"""

from __future__ import annotations

from dataclasses import dataclass

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
#: the arm stumps' openings lie within this many degrees of the sides (x): a back hem that rides
#: higher than the front (a work shirt on some bodies) or a coat's front opening is not where an
#: arm hangs (:func:`arm_params`; the section runs straight across all of them)
STUMP_SECTOR = 45.0
#: passes of circular averaging of the section's radius and height
SMOOTHING = 3
#: an upper arm's radius as a fraction of the torso's width (side to side) at the arms
ARM_RADIUS = 0.17
#: the fraction of the arm's radius inside the torso's side (the arm rests against the chest)
ARM_INSIDE = 0.4
#: the arm's top cap, a half ellipsoid sheared across: its height in radii at the arm's inner
#: edge (against the torso) and at its outer edge, linear in between
ARM_CAP_IN = 1.6
ARM_CAP_OUT = 0.5
#: the cap lies this far (m) under the garment's shoulder at the torso's side
ARM_TUCK = 0.003
#: the radius at ELBOW (m) below the cap's base, as a fraction of the radius at the top
ARM_TAPER = 0.85
ELBOW = 0.3
#: the garment's shoulder over an arm lies at most this far (m) above the opening's lowest rim
#: (2-3 cm on the hard cases); higher cloth at the torso's side is a hood's, beside the head
SHOULDER_ABOVE_OPENING = 0.05
#: hair points inside an arm are moved this far (m) beyond its surface (:func:`keep_strands_out`)
ARM_HAIR_CLEARANCE = 0.002
#: segments around an arm; rings of its cap
ARM_SEGMENTS = 32
ARM_CAP_RINGS = 6


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


def _cap_height(u):
    """The arm cap's height in radii at ``u`` across the arm (-1: its inner edge, 1: its outer)."""
    return ARM_CAP_IN + (ARM_CAP_OUT - ARM_CAP_IN) * 0.5 * (np.asarray(u) + 1)


@dataclass(frozen=True)
class Arm:
    """One upper arm (see the module docstring): a vertical axis at ``axis`` (x, y), the cap above
    ``z_base`` (its height over the base at ``u`` across the arm: :func:`_cap_height` radii times
    ``sqrt(1 - (rho / radius)**2)``), the tube below it tapering to ``ARM_TAPER`` at ``ELBOW``
    below, down to ``z_bottom``; ``side`` -1 or 1 (its sign of x)."""

    axis: tuple[float, float]
    z_base: float
    radius: float
    z_bottom: float
    side: float

    def radius_at(self, z: np.ndarray) -> np.ndarray:
        """The tube's radius at heights ``z`` (at or below the cap's base)."""
        t = np.clip((self.z_base - np.asarray(z, np.float64)) / ELBOW, 0.0, 1.0)
        return self.radius * (1 - (1 - ARM_TAPER) * t)

    def cap_z(self, xy: np.ndarray) -> np.ndarray:
        """The cap's surface height over points ``xy`` (N, 2) within the arm's radius."""
        d = np.asarray(xy, np.float64) - self.axis
        rho = np.minimum(np.linalg.norm(d, axis=1) / self.radius, 1.0)
        u = np.clip(self.side * d[:, 0] / self.radius, -1.0, 1.0)
        return self.z_base + _cap_height(u) * self.radius * np.sqrt(1 - rho ** 2)

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, outward triangles): a closed tube, the cap's rings on :meth:`cap_z`."""
        from synth.assets.fit.meshops import sweep_tube

        t = np.linspace(0, 0.5 * np.pi, ARM_CAP_RINGS + 1)[1:]
        z = np.concatenate([self.z_base + np.cos(t), [self.z_base - 0.5 * ELBOW, self.z_base - ELBOW, self.z_bottom]])
        rad = np.concatenate([self.radius * np.sin(t), self.radius_at(z[ARM_CAP_RINGS:])])
        path = np.column_stack([np.broadcast_to(self.axis, (len(z), 2)), z])
        V, F = sweep_tube(path, rad, n_sides=ARM_SEGMENTS)
        V[-2, 2] = self.z_base + 1.0  # the top cap's centre: the pole of a unit half sphere, sheared below
        if np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() < 0:
            F = F[:, ::-1]  # outward
        cap = V[:, 2] > self.z_base + 1e-9
        u = np.clip(self.side * (V[cap, 0] - self.axis[0]) / self.radius, -1.0, 1.0)
        V[cap, 2] = self.z_base + (V[cap, 2] - self.z_base) * _cap_height(u) * self.radius
        return V, F

    def push_out(self, pts: np.ndarray, clearance: float = ARM_HAIR_CLEARANCE) -> tuple[np.ndarray, np.ndarray]:
        """(points, moved mask): points (N, 3) inside the arm moved out to ``clearance`` beyond
        its surface: up onto the cap or out from the axis, whichever is nearer (so that strands
        hanging through a shoulder drape over it and down its side)."""
        P = np.array(pts, np.float64, copy=True)
        d = P[:, :2] - self.axis
        rho = np.linalg.norm(d, axis=1)
        z = P[:, 2]
        tube_r = self.radius_at(np.minimum(z, self.z_base))
        cand = (rho < tube_r) & (z > self.z_bottom)
        top = np.full(len(P), -np.inf)
        in_cap = cand & (z > self.z_base)
        top[in_cap] = self.cap_z(P[in_cap, :2])
        inside = cand & ((z <= self.z_base) | (z < top))
        up = np.where(in_cap, top - z, np.inf)
        out = tube_r - rho
        lift = inside & (up <= out)
        P[lift, 2] = top[lift] + clearance
        push = inside & ~lift
        safe = np.where(rho > 1e-9, rho, 1.0)
        dirn = np.where((rho > 1e-9)[:, None], d / safe[:, None], np.array([self.side, 0.0]))
        P[push, :2] = np.asarray(self.axis) + dirn[push] * (tube_r[push] + clearance)[:, None]
        return P, inside


def arm_params(P: np.ndarray, length: float = LENGTH) -> list[Arm]:
    """The two :class:`Arm` of a garment whose (outer, torso shell) vertices are ``P`` (left,
    right): hanging from its arm-stump openings, one per side of the torso's section, down to the
    torso's bottom."""
    if not length > 0:
        raise ValueError(f"torso length must be positive, got {length}")
    P = np.asarray(P, np.float64)
    c, r, zmin = section(P)
    n = len(r)
    phi = (np.arange(n) + 0.5) / n * 2 * np.pi - np.pi
    S = c + r[:, None] * np.stack([np.cos(phi), np.sin(phi)], 1)
    z_low = P[:, 2].min()
    width = S[:, 0].max() - S[:, 0].min()
    rad = ARM_RADIUS * width
    stump = (zmin > z_low + STUMP_RISE) & (np.abs(np.cos(phi)) > np.cos(np.radians(STUMP_SECTOR)))
    out = []
    for side in (-1.0, 1.0):
        w = (side * (S[:, 0] - c[0])).max()  # the torso's half width on this side
        B = stump & (side * np.cos(phi) > 0)
        if not B.any():  # no opening found: the bins within 20 degrees of the side
            B = side * np.cos(phi) > np.cos(np.radians(20))
        # the garment's shoulder at the torso's side: its highest point there, at most
        # SHOULDER_ABOVE_OPENING over the opening's rim (not a hood's side at the head)
        reach = side * (P[:, 0] - c[0])
        rim = zmin[B].max()
        near = (reach > min(w, reach.max()) - 0.015) & (P[:, 2] <= rim + SHOULDER_ABOVE_OPENING)
        z_shoulder = P[near, 2].max() if near.any() else rim
        d = (1 - ARM_INSIDE) * rad  # from the arm's axis to the torso's side
        # the cap over the torso's side (u = -d / rad across the arm): ARM_TUCK under the shoulder
        u_side = -d / rad
        z_base = z_shoulder - ARM_TUCK - float(_cap_height(u_side)) * rad * np.sqrt(1 - u_side ** 2)
        out.append(Arm((float(c[0] + side * (w + d)), float(S[B, 1].mean())), float(z_base), float(rad),
                       float(z_low - length), side))
    return out


def arms(P: np.ndarray, length: float = LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, outward triangles) of the two upper arms (:func:`arm_params`), left then right."""
    out_V, out_F = [], []
    for arm in arm_params(P, length):
        V, F = arm.mesh()
        out_F.append(F + sum(len(v) for v in out_V))
        out_V.append(V)
    return np.vstack(out_V), np.vstack(out_F)


def keep_strands_out(arms_: list[Arm], pts: np.ndarray, clearance: float = ARM_HAIR_CLEARANCE) -> tuple[np.ndarray, int]:
    """(strands (N, P, 3), number of points moved): strand points inside the arms pushed out
    (:meth:`Arm.push_out`); roots (point 0) stay. Hair is groomed on the head and bust alone and
    hung through the arms' shoulders (long styles and braids: up to 8 % of strands, 4 cm deep)."""
    pts = np.asarray(pts, np.float64)
    flat = pts[:, 1:].reshape(-1, 3).copy()
    moved = np.zeros(len(flat), bool)
    for arm in arms_:
        lo = np.array([arm.axis[0] - arm.radius, arm.axis[1] - arm.radius, arm.z_bottom])
        hi = np.array([arm.axis[0] + arm.radius, arm.axis[1] + arm.radius, arm.z_base + ARM_CAP_IN * arm.radius])
        box = np.all((flat >= lo) & (flat <= hi), axis=1)
        if box.any():
            q, m = arm.push_out(flat[box], clearance)
            flat[box] = q
            idx = np.nonzero(box)[0]
            moved[idx[m]] = True
    out = pts.copy()
    out[:, 1:] = flat.reshape(pts.shape[0], pts.shape[1] - 1, 3)
    return out, int(moved.sum())


def torso_shell_vertices(fitted) -> np.ndarray:
    """Indices of a fitted garment's torso shell (:class:`synth.assets.fit.body.FittedShell`): of the
    connected pieces of its outer cloth (material slot 0, not a hem cap) with at least a fifth of
    the largest one's vertices, the one whose lowest tenth lies lowest (not a hood up, which
    on a +3 SD body is the largest piece)."""
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
    size = np.bincount(label[used])
    # of the large pieces (drawstrings and ties are small), the one that reaches lowest: a hood
    # up on a small body can be larger than the body's piece under it
    z = np.asarray(fitted.P, np.float64)[used, 2]
    low = np.full(len(size), np.inf)
    for k in np.nonzero(size >= 0.2 * size.max())[0]:
        low[k] = np.percentile(z[label[used] == k], 10)
    return used[label[used] == int(np.argmin(low))]


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


def garment_torso_parts(fitted) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """The two parts of :func:`garment_torso`: ((prism vertices, faces), (arms' vertices, faces)),
    each part's faces indexing its own vertices."""
    Q = np.asarray(fitted.P, np.float64)[torso_shell_vertices(fitted)]
    return torso_continuation(Q), arms(Q)


def garment_torso(fitted, with_arms: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """:func:`torso_continuation` of a fitted garment, shaped by its torso shell
    (:func:`torso_shell_vertices`), so that drawstrings, scarf ends, ties and collars hanging
    below the hem do not shape the body; ``with_arms``: and its :func:`arms` (after the prism's
    vertices). A render whose garment record has no ``torso_arms`` recorded the prism alone."""
    if not with_arms:
        return torso_continuation(np.asarray(fitted.P, np.float64)[torso_shell_vertices(fitted)])
    (V, F), (Va, Fa) = garment_torso_parts(fitted)
    return np.vstack([V, Va]), np.vstack([F, Fa + len(V)])
