"""The bust's upper arms under a garment: sleeves, forearms, and hair kept off the sleeves (pure numpy).

The default head model carries the MakeHuman bust: the torso to the waist and both upper arms,
hanging, to the elbows (regions ``arm_l``, ``arm_r``; each elbow closed by a cap on the loop
``elbow_l`` / ``elbow_r``; docs/body-plan.md). A garment is the skin of the ``neck`` and
``shoulders`` regions, which now take in the arms, clipped under its neckline and above its hem
(:mod:`synth.assets.fit.garment`). What this module adds:

* :class:`ArmFrame`: per body vertex, how much it belongs to an arm (the arm regions' indicator,
  smoothed on the mesh: :data:`MEMBER_SMOOTHING` passes) and how far down its upper arm it lies
  (``t``: 0 at the armhole's centre, 1 at the elbow loop's, along the line between them);
* :func:`sleeve_field`: the field a garment's shell is also clipped at (>= 0 where the cloth is):
  ``long`` sleeves cover the whole upper arm (no field), ``short`` ones end on the plane across
  the arm at ``t`` = :data:`SHORT_SLEEVE_T` (a T-shirt's: mid upper arm), ``none`` (a tank top)
  leaves the arms (membership under 0.5) bare;
* :func:`forearm`: a closed tube that goes on from an elbow loop :data:`FOREARM_LENGTH` straight
  down, :data:`FOREARM_BEND_DEG` forward (relaxed arms: the forearm hangs, the hands in front of
  the thighs), and tapered: in the sleeve's cloth under a long
  sleeve, in the skin's under a short one or none. The bust ends at the elbows; the forearms carry
  the arms out of the frame as the torso's prism carries the body (:mod:`synth.assets.fit.torso`);
* :class:`ArmKeepOut`: hair is groomed on the body before the garment, clear of the skin; once
  the garment exists its strand points closer to an upper arm's skin than the sleeve's cloth
  (plus :data:`HAIR_CLEARANCE`) are pushed out along the arm's normal (signed distance to the
  arms' triangles, normals from the whole mesh).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.geometry.normals import normalize

#: the arm regions and elbow loops a model needs for sleeves (the default model's bust)
ARM_REGIONS = {"L": ("arm_l", "elbow_l"), "R": ("arm_r", "elbow_r")}
#: passes of neighbour averaging of the arm regions' indicator (the membership field)
MEMBER_SMOOTHING = 3
#: a short sleeve ends this far down the upper arm (t: armhole centre 0, elbow 1)
SHORT_SLEEVE_T = 0.45
#: ... never higher than this far (t) under the highest t of the armhole's own vertices (the
#: armpit's), so that the sleeve's end runs round the arm, not into the torso
SLEEVE_BELOW_ARMPIT = 0.08
#: the membership field's scale (m per unit of membership): a tank top's arm hole lies where the
#: membership is 0.5; the factor puts the field in about the metres of the other fields
MEMBER_FIELD_M = 0.04
#: the forearm: its length (m) from the elbow loop, its angle forward of the vertical (degrees), its
#: radius at the end as a share of the elbow's, its rings, its segments round
FOREARM_LENGTH = 0.3
FOREARM_BEND_DEG = 15.0
FOREARM_TAPER = 0.75
FOREARM_RINGS = 6
FOREARM_SEGMENTS = 40
#: the forearm's top ring lies this far (m) up the arm from the elbow loop and this share of the
#: radius in (inside the arm or the sleeve: no gap at the elbow)
FOREARM_OVERLAP = 0.01
FOREARM_TUCK = 0.15
#: under a sleeve the forearm's wall lies this far (m) inside the sleeve's cloth at the elbow
FOREARM_INSET = 0.001
#: hair points are kept this far (m) beyond the sleeve's cloth (or the bare arm's skin)
HAIR_CLEARANCE = 0.002
#: points deeper than this (m) inside an arm are not the arm's (the torso beside it, a far side)
HAIR_MAX_DEPTH = 0.07
#: a point the push would put into the skin across (the crease between arm and torso) is pushed
#: half as far, up to this many times, else left where it was
CREASE_HALVINGS = 3


def has_arms(regions: dict) -> bool:
    """Whether a model's regions hold the bust's arms and elbow loops (the default model's)."""
    return all(r in regions and len(regions[r]) for names in ARM_REGIONS.values() for r in names)


@dataclass
class ArmFrame:
    """Per-vertex arm fields of a body (see the module docstring); ``side``: 1 on the left arm's
    region, -1 on the right's, 0 elsewhere; ``shoulder``, ``elbow``: the armhole's and the elbow
    loop's centres (side -> (3,))."""

    member: np.ndarray  # (V,) in [0, 1]
    t: np.ndarray  # (V,) along the vertex's arm (0 off the arms)
    side: np.ndarray  # (V,)
    length: dict  # side -> |elbow - shoulder| (m)
    shoulder: dict
    elbow: dict
    armpit_t: dict  # side -> the highest t of the armhole's vertices


def arm_frame(V: np.ndarray, F: np.ndarray, regions: dict) -> ArmFrame | None:
    """The :class:`ArmFrame` of vertices ``V`` (the mesh ``F``, the model's ``regions``); None for a
    model without the bust's arms."""
    if not has_arms(regions):
        return None
    from synth.assets.fit.hem import neighbour_mean_matrix

    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    side = np.zeros(n)
    for s, sign in (("L", 1.0), ("R", -1.0)):
        side[np.asarray(regions[ARM_REGIONS[s][0]], np.int64)] = sign
    arm = side != 0
    M = neighbour_mean_matrix(F, n)
    member = arm.astype(np.float64)
    for _ in range(MEMBER_SMOOTHING):
        member = M @ member
    # the armhole: arm vertices with a neighbour off the arms
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    E = np.concatenate([E, E[:, ::-1]])
    hole = np.zeros(n, bool)
    hole[E[arm[E[:, 0]] & ~arm[E[:, 1]], 0]] = True
    t = np.zeros(n)
    length, shoulder, elbow, pit = {}, {}, {}, {}
    for s, sign in (("L", 1.0), ("R", -1.0)):
        on = side == sign
        S = V[hole & on].mean(0)
        Ev = V[np.asarray(regions[ARM_REGIONS[s][1]], np.int64)].mean(0)
        d = Ev - S
        L2 = float(d @ d)
        t[on] = (V[on] - S) @ d / L2
        length[s], shoulder[s], elbow[s] = float(np.sqrt(L2)), S, Ev
        pit[s] = float(t[hole & on].max())
    return ArmFrame(member, t, side, length, shoulder, elbow, pit)


def sleeve_end(frame: ArmFrame, t_end: float) -> float:
    """The sleeve's end ``t_end`` kept :data:`SLEEVE_BELOW_ARMPIT` under both armpits."""
    return max(float(t_end), max(frame.armpit_t.values()) + SLEEVE_BELOW_ARMPIT)


def sleeve_field(frame: ArmFrame | None, kind: str, t_end: float = SHORT_SLEEVE_T) -> np.ndarray | None:
    """(V,) field, >= 0 where a garment with sleeves of ``kind`` ('long', 'short', 'none') may be;
    None when nothing is clipped (long sleeves, or a model without arms)."""
    if frame is None or kind == "long":
        return None
    if kind == "short":
        te = sleeve_end(frame, t_end)
        L = np.where(frame.side > 0, frame.length["L"], frame.length["R"])
        return np.where(frame.side != 0, (te - frame.t) * L, 1.0)
    if kind == "none":
        return (0.5 - frame.member) * MEMBER_FIELD_M
    raise ValueError(f"unknown sleeve kind {kind!r}")


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = normalize(np.asarray(axis, np.float64))
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


def _resample_ring(Q: np.ndarray, n: int) -> np.ndarray:
    """The closed polyline ``Q`` at ``n`` points evenly spaced along it (from Q[0])."""
    ext = np.vstack([Q, Q[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ext, axis=0), axis=1))])
    u = np.arange(n) * (s[-1] / n)
    return np.stack([np.interp(u, s, ext[:, k]) for k in range(3)], 1)


def forearm(ring: np.ndarray, shoulder: np.ndarray, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, outward triangles) of a closed forearm tube on the elbow loop ``ring`` (its body
    vertices in order) of the arm hanging from ``shoulder`` (the armhole's centre); ``offset``: how far
    (m) its wall at the elbow lies outside the skin's loop (a sleeve's cloth; 0: the skin's)."""
    from synth.assets.fit.meshops import grid_faces

    Q = _resample_ring(np.asarray(ring, np.float64), FOREARM_SEGMENTS)
    c = Q.mean(0)
    d = normalize(c - np.asarray(shoulder, np.float64))  # down the upper arm
    r = Q - c
    r -= np.outer(r @ d, d)  # radial, across the arm
    rad = np.linalg.norm(r, axis=1)
    u = r / np.maximum(rad, 1e-9)[:, None]
    wall = Q + u * offset  # the ring at the elbow, on the skin or the sleeve
    # the bend at the elbow: the forearm hangs straight down, FOREARM_BEND_DEG forward (-y); its
    # section turns with it (the rotation taking the upper arm's direction to the forearm's)
    b = np.radians(FOREARM_BEND_DEG)
    d2 = np.array([0.0, -np.sin(b), -np.cos(b)])
    axis = np.cross(d, d2)
    ang = float(np.arctan2(np.linalg.norm(axis), d @ d2))
    R = _rotation(axis, ang) if np.linalg.norm(axis) > 1e-12 else np.eye(3)
    rings = [c - d * FOREARM_OVERLAP + (wall - c) * (1.0 - FOREARM_TUCK), wall]
    for k in range(1, FOREARM_RINGS + 1):
        f = k / FOREARM_RINGS
        scale = 1.0 - (1.0 - FOREARM_TAPER) * f
        rings.append(c + d2 * (FOREARM_LENGTH * f) + ((wall - c) @ R.T) * scale)
    G = np.stack(rings, 1)  # (segments, rings, 3)
    Vt = G.reshape(-1, 3)
    Ft = grid_faces(G.shape[0], G.shape[1], closed_u=True)
    # close both ends by fans on their centres
    nr = G.shape[1]
    top_c, bot_c = len(Vt), len(Vt) + 1
    Vt = np.vstack([Vt, rings[0].mean(0), rings[-1].mean(0)])
    i = np.arange(G.shape[0])
    j = (i + 1) % G.shape[0]
    Ftop = np.stack([i * nr, j * nr, np.full(len(i), top_c)], 1)
    Fbot = np.stack([i * nr + nr - 1, j * nr + nr - 1, np.full(len(i), bot_c)], 1)
    F = np.vstack([Ft, Ftop, Fbot])
    # outward: the sum of the signed volumes about the tube's centre is positive
    ctr = Vt.mean(0)
    A, B, C = Vt[F[:, 0]] - ctr, Vt[F[:, 1]] - ctr, Vt[F[:, 2]] - ctr
    vol = np.einsum("ij,ij->i", A, np.cross(B, C))
    # orient every face of each part like its part's majority (grid and fans are built consistently)
    F[: len(Ft)] = F[: len(Ft)] if vol[: len(Ft)].sum() > 0 else F[: len(Ft), ::-1]
    F[len(Ft):len(Ft) + len(i)] = F[len(Ft):len(Ft) + len(i)] if vol[len(Ft):len(Ft) + len(i)].sum() > 0 \
        else F[len(Ft):len(Ft) + len(i), ::-1]
    F[len(Ft) + len(i):] = F[len(Ft) + len(i):] if vol[len(Ft) + len(i):].sum() > 0 else F[len(Ft) + len(i):, ::-1]
    return Vt, F


def forearms(V: np.ndarray, F: np.ndarray, regions: dict, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, outward triangles) of both forearms (:func:`forearm`, left then right) of the body
    ``V`` (mesh ``F``, ``regions``); empty for a model without the bust's arms."""
    frame = arm_frame(V, F, regions)
    if frame is None:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    out_V, out_F = [], []
    for s in ("L", "R"):
        Vf, Ff = forearm(np.asarray(V, np.float64)[np.asarray(regions[ARM_REGIONS[s][1]], np.int64)],
                         frame.shoulder[s], offset)
        out_F.append(Ff + sum(len(v) for v in out_V))
        out_V.append(Vf)
    return np.vstack(out_V), np.vstack(out_F)


def arm_triangles(F: np.ndarray, regions: dict) -> np.ndarray:
    """Indices of the triangles of ``F`` with every corner on an arm (the elbow caps included)."""
    n = int(np.asarray(F).max()) + 1
    arm = np.zeros(n, bool)
    for names in ARM_REGIONS.values():
        arm[np.asarray(regions[names[0]], np.int64)] = True
    return np.nonzero(arm[np.asarray(F, np.int64)].all(1))[0]


class ArmKeepOut:
    """Keep strand points ``clearance`` off the upper arms' skin (see the module docstring): the
    signed distance to the skin (every triangle of the ``skin`` region; the sign from the
    angle-weighted pseudo-normals, exact on the closed skin), and the points whose closest skin
    point lies on an arm (its triangles: :func:`arm_triangles`), closer than ``clearance`` and less
    than :data:`HAIR_MAX_DEPTH` inside, are moved to that point plus ``clearance`` along the normal
    there (three passes, for concave spots). A point nearer the torso than the arm is left alone:
    at the armhole the arm's patch ends, and the skin beside it is the torso's."""

    def __init__(self, V: np.ndarray, F: np.ndarray, regions: dict, clearance: float):
        self.F = np.asarray(F, np.int64)
        n = int(self.F.max()) + 1
        skin = np.zeros(n, bool)
        skin[np.asarray(regions["skin"], np.int64)] = True
        self.faces = np.nonzero(skin[self.F].all(1))[0]
        self.on_arm = np.zeros(len(self.F), bool)
        self.on_arm[arm_triangles(self.F, regions)] = True
        self.rows = np.unique(self.F[self.on_arm])
        self.clearance = float(clearance)
        self._build(np.asarray(V, np.float64))

    def _build(self, V):
        from synth.geometry.sdf import SignedDistance

        self._V = V.copy()
        self._sdf = SignedDistance(V, self.F, faces=self.faces, sign="pseudo", k=16)
        pad = self.clearance + 0.01
        self._lo, self._hi = V[self.rows].min(0) - pad, V[self.rows].max(0) + pad

    def follow(self, V: np.ndarray) -> None:
        """The body's vertices changed (an expression): rebuilt if they moved (the default model's
        arms and torso do not: the bust is bound to the root joint; the face does, so the whole
        skin is compared)."""
        V = np.asarray(V, np.float64)
        if not np.array_equal(V, self._V):
            self._build(V)

    def distance(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(signed distance to the skin, whether the closest skin point is on an arm) of points (N, 3)."""
        h = self._sdf.query(np.asarray(pts, np.float64).reshape(-1, 3))
        return h.signed, self.on_arm[h.face]

    def push(self, pts: np.ndarray, iterations: int = 3) -> tuple[np.ndarray, int]:
        """(strands (N, P, 3), number of points moved): ``pts`` with their points (not the roots)
        kept ``clearance`` off the arms."""
        pts = np.asarray(pts, np.float64)
        flat = pts[:, 1:].reshape(-1, 3).copy()
        moved = np.zeros(len(flat), bool)
        box = np.nonzero(np.all((flat >= self._lo) & (flat <= self._hi), axis=1))[0]
        for _ in range(iterations):
            if not len(box):
                break
            h = self._sdf.query(flat[box])
            bad = (h.signed < self.clearance - 1e-7) & (h.signed > -HAIR_MAX_DEPTH) & self.on_arm[h.face]
            if not bad.any():
                break
            i = box[bad]
            step = np.full(len(i), self.clearance)
            q = h.point[bad] + h.normal[bad] * step[:, None]
            # in the crease between arm and torso the clearance may not fit: a point pushed into the
            # skin across is pushed half as far (three times), else left where it was
            for _ in range(CREASE_HALVINGS):
                g = self._sdf(q)
                into = g < 0.0
                if not into.any():
                    break
                step[into] *= 0.5
                q[into] = h.point[bad][into] + h.normal[bad][into] * step[into, None]
            ok = self._sdf(q) >= 0.0
            i, q = i[ok], q[ok]
            flat[i] = q
            moved[i] = True
            box = i[step[ok] >= self.clearance]  # points that found room only half way stay put
        out = pts.copy()
        out[:, 1:] = flat.reshape(pts.shape[0], pts.shape[1] - 1, 3)
        return out, int(moved.sum())
