"""Collars that lie on their garment: a shirt's band and leaf, a turtleneck's folded roll (pure numpy).

Both are sheets laid on the skin like the torso shell is: every row of a collar is found by
walking down the body's surface from the collar's fold line (:func:`walk_down`, each step
snapped back onto the skin) and standing off it by the shell's own offset there
(the shell's own height over the skin there, with its folds and drape) plus a small gap, so the
collar rests on the garment wherever the garment goes.

* **Shirt collar** (:func:`shirt_collar`): the band stands round the neck (the neck's skin
  between two heights, clipped like the shell), the leaf folds over its top
  (:data:`FOLD_RADIUS`) and falls down over the band and on to the shirt's shoulders, chest and
  back, :data:`LEAF_GAP` over the band and over the shell; at the front its points run longer and
  turn out to the sides. A thin tube (:data:`EDGE_RADIUS`) gives the leaf's edge its thickness.
* **Turtleneck roll** (:func:`rolled_collar`): the collar's top folded down over its outside:
  a sheet from the collar's rim down ``depth``, :data:`ROLL_GAP` plus the fabric's thickness out
  from the collar, swelling in the middle (:data:`ROLL_SWELL`), with knit ribs across it
  (:data:`RIB_PITCH`, :data:`RIB_DEPTH`), soft creases where it bunches (``rng``) and a rounded
  lower edge; a knit that is not wool has no ribs.
"""

from __future__ import annotations

import numpy as np

from synth.assets.fit.attach import push_out
from synth.assets.fit.body import Body, Parts, WaveNoise
from synth.assets.fit.meshops import grid_faces, sweep_tube
from synth.geometry.normals import normalize
from synth.geometry.sdf import SignedDistance
from synth.model.meshutil import smoothstep

#: the leaf lies this far (m) over the band and over the shirt's shell
LEAF_GAP = 0.0012
#: radius (m) of the leaf's fold over the band's top
FOLD_RADIUS = 0.002
#: radius (m) of the tube along the leaf's free edge (its thickness)
EDGE_RADIUS = 0.0009
#: rows of a leaf down from its fold, and samples round the neck
LEAF_ROWS, LEAF_AROUND = 9, 96
#: a turtleneck's roll: gap (m) to the collar under it, swell (m) of its middle, knit ribs'
#: pitch and depth (m), creases' depth (m) and their wavelength round the neck (m)
ROLL_GAP, ROLL_SWELL = 0.0015, 0.003
RIB_PITCH, RIB_DEPTH = 0.005, 0.0007
CREASE_DEPTH, CREASE_WAVELENGTH = 0.0035, 0.06
#: rows of a roll and samples round the neck (4 per rib)
ROLL_ROWS, ROLL_AROUND = 8, 304


def walk_down(body: Body, start: np.ndarray, arcs: np.ndarray, side: np.ndarray | None = None,
              out: float = 0.4) -> tuple[np.ndarray, np.ndarray]:
    """Points on the skin ``arcs`` (R,) metres down from each of ``start`` (n, 3) (negative: up),
    walking along the neck and shoulders' skin (the tangent part of down plus ``out`` times away
    from the neck, plus ``side`` (n,) times round it), snapping each step back on to it. Returns (n, R, 3) points and
    (n, R, 3) skin normals."""
    fr = body.frame
    h = body.torso_query.query(start)
    p, nrm = h.point, h.normal
    P = np.empty((len(start), len(arcs), 3))
    N = np.empty_like(P)
    prev = 0.0
    order = np.argsort(arcs, kind="stable")
    for k in order:  # from the highest row down; negative arcs are walked from the start upward
        a = float(arcs[k])
        if a < 0:
            q, qn = h.point, h.normal
            step = a
        else:
            q, qn = p, nrm
            step = a - prev
        d = np.array([0.0, 0.0, -1.0]) + out * fr.outward(q)
        if side is not None:
            d = d + side[:, None] * np.cross([0.0, 0.0, 1.0], fr.outward(q))
        d = normalize(d - (d * qn).sum(1, keepdims=True) * qn)
        hq = body.torso_query.query(q + step * d)
        P[:, k], N[:, k] = hq.point, hq.normal
        if a >= 0:
            p, nrm, prev = hq.point, hq.normal, a
    return P, N


def _band(body: Body, z_lo, z_hi, gap: float):
    fr = body.frame
    th = fr.theta(body.V)
    z = body.V[:, 2]
    return np.minimum(np.minimum(z - z_lo(th), z_hi(th) - z), np.abs(th) - gap)


def shirt_collar(body: Body, parts: Parts, slot: int, base_off: float, open_front: bool, shell_mesh=None,
                 band_h: float = 0.03, leaf: float = 0.045) -> dict:
    """A shirt's collar on ``body``: the band (``band_h`` high) standing round the neck and the
    leaf (``leaf`` long at the back, half as long again at the points) folded down over it on to
    the shirt's shell ``shell_mesh`` (points, faces: with its folds; None: a plain ``base_off``). ``open_front``:
    the top button open (the collar's ends further apart). Returns the leaf's rows (n, R, 3), the
    arc of each row down from the fold and the band's height, for the tests."""
    fr = body.frame
    gap = 0.22 if open_front else 0.07

    def z_lo(t):
        return np.minimum(fr.z_ring(t) + 0.004 + 0.008 * (1 - np.cos(t)), fr.z_cap(t) - band_h)

    def z_hi(t):
        return np.minimum(z_lo(t) + band_h, fr.z_cap(t))

    band_off = base_off + 0.002
    P, F, _ = body.shell(body.torso_tris, _band(body, z_lo, z_hi, gap), lambda p, nrm: np.full(len(p), band_off))
    parts.add(P, F, slot, trim=True)
    # the leaf: from the band's top, round the back, from +gap to -gap
    top = body.neck_loop(z_hi, LEAF_AROUND, angle0=np.pi)
    tt = fr.theta(top)
    keep = np.abs(tt) >= gap
    top = top[keep][np.argsort(np.mod(tt[keep], 2 * np.pi), kind="stable")]
    th = fr.theta(top)
    front = np.maximum(np.cos(th), 0.0)
    length = leaf * (1.0 + 0.5 * front ** 4)
    s = np.linspace(0.0, 1.0, LEAF_ROWS)
    rows_P = np.empty((len(top), LEAF_ROWS, 3))
    rows_N = np.empty_like(rows_P)
    # every column walks its own length: walk the longest and interpolate along it
    fine = np.concatenate([[-FOLD_RADIUS], np.linspace(0.0, float(length.max()), 4 * LEAF_ROWS)])
    Pw, Nw = walk_down(body, top, fine, side=np.sign(th) * 0.6 * front ** 2, out=0.3)
    want = np.concatenate([np.full((len(top), 1), -FOLD_RADIUS), length[:, None] * s[None, 1:]], 1)
    for i in range(len(top)):
        for c in range(3):
            rows_P[i, :, c] = np.interp(want[i], fine, Pw[i, :, c])
            rows_N[i, :, c] = np.interp(want[i], fine, Nw[i, :, c])
    rows_N = normalize(rows_N)
    # 1 where the skin under a point is the band's (above its lower edge), 0 past it
    skin_th = fr.theta(rows_P.reshape(-1, 3))
    over_band = smoothstep(rows_P.reshape(-1, 3)[:, 2] - z_lo(skin_th), -0.002, 0.002).reshape(len(top), -1)
    # over the band: the band's offset plus the gap; past it: the gap over the shirt's shell itself
    # (with its folds and drape), from the shell's closest point along its normal
    G = rows_P + rows_N * (band_off + LEAF_GAP)
    G[:, 0] = rows_P[:, 0] + rows_N[:, 0] * (band_off + FOLD_RADIUS)
    if shell_mesh is not None and len(shell_mesh[1]):
        hs = SignedDistance(shell_mesh[0], shell_mesh[1], sign="vertex").query(G.reshape(-1, 3))
        on_shell = (hs.point + hs.normal * LEAF_GAP).reshape(G.shape)
        w = ((1.0 - over_band) * (hs.distance < 0.008).reshape(over_band.shape))[..., None]
        w[:, 0] = 0.0
        G = w * on_shell + (1.0 - w) * G
    # the fold's top row straight above the band's edge
    G[:, 0] += np.array([0.0, 0.0, 1.0]) * FOLD_RADIUS * 0.5
    Pl = push_out(G.reshape(-1, 3), body.query, base_off + 0.0015)
    parts.add(Pl, grid_faces(G.shape[0], G.shape[1]), slot)
    Vt, Ft = sweep_tube(G[:, -1], EDGE_RADIUS, 6, closed=False)
    parts.add(push_out(Vt, body.query, base_off + 0.0015), Ft, slot)
    return {"rows": G, "arcs": want, "over_band": over_band}


def rolled_collar(body: Body, parts: Parts, slot: int, z_top, collar_off: float, thick: float, depth: float,
                  rng: np.random.Generator, ribbed: bool = True) -> dict:
    """A turtleneck's top folded down over its collar (whose top is ``z_top(theta)``, standing
    ``collar_off`` off the skin): ``depth`` (m) down its outside, ``thick`` the fabric's
    thickness. Returns the roll's grid (n, R, 3) and its offsets off the skin, for the tests."""
    fr = body.frame
    top = body.neck_loop(lambda t: z_top(t) - 0.002, ROLL_AROUND, angle0=np.pi)
    creases = WaveNoise(rng, CREASE_WAVELENGTH, 8, stretch=(1.0, 1.0, 0.5))
    edge = WaveNoise(rng, 2.0 * CREASE_WAVELENGTH, 6)
    d = depth * (1.0 + 0.12 * edge(top))  # the lower edge wavers by about a tenth
    s = np.linspace(0.0, 1.0, ROLL_ROWS)
    fine = np.linspace(0.0, float(d.max()), 3 * ROLL_ROWS)
    Pw, Nw = walk_down(body, top, fine, out=0.0)
    want = d[:, None] * s[None, :]
    P = np.empty((len(top), ROLL_ROWS, 3))
    N = np.empty_like(P)
    for i in range(len(top)):
        for c in range(3):
            P[i, :, c] = np.interp(want[i], fine, Pw[i, :, c])
            N[i, :, c] = np.interp(want[i], fine, Nw[i, :, c])
    N = normalize(N)
    mid = P[:, ROLL_ROWS // 2] + N[:, ROLL_ROWS // 2] * (collar_off + thick + ROLL_GAP)
    u = np.cumsum(np.r_[0.0, np.linalg.norm(np.diff(mid, axis=0), axis=1)])  # arc round the roll
    rib = RIB_DEPTH * (0.5 + 0.5 * np.cos(2 * np.pi * u / RIB_PITCH)) if ribbed else np.zeros(len(top))
    swell = ROLL_SWELL * np.sin(np.pi * np.clip(s * 1.15, 0.0, 1.0))
    off = (collar_off + thick + ROLL_GAP + swell[None, :] + rib[:, None]
           + CREASE_DEPTH * (0.5 + 0.5 * creases(P.reshape(-1, 3))).reshape(P.shape[:2]) * s[None, :])
    off[:, 0] = collar_off + 0.5 * thick + ROLL_GAP  # the fold itself, over the collar's rim
    G = P + N * off[..., None]
    G[:, 0] += np.array([0.0, 0.0, 1.0]) * (thick + 0.002)
    Fg = grid_faces(G.shape[0], G.shape[1], closed_u=True)
    parts.add(G.reshape(-1, 3), Fg, slot, trim=True)
    Vt, Ft = sweep_tube(G[:, -1], 0.5 * thick + 0.0008, 8, closed=True)
    parts.add(Vt, Ft, slot)
    return {"rows": G, "offset": off}
