"""Folds and drape of a garment's torso shell: where its cloth stands off the skin (pure numpy).

A torso shell is the skin offset along its normals (:func:`synth.assets.fit.garment_parts.torso_shell`).
:class:`Folds` is that offset: the fabric's thickness plus a displacement that puts folds where a
worn garment has them, on the body it is built on (no cloth solve):

* **drape** (below the chest's high point): the cloth hangs from the chest instead of following
  the skin into the hollow under it and between the breasts. Per front vertex, the cloth's
  front lies where a sheet falling from every higher vertex (a slope of :data:`~synth.assets.fit.body.DRAPE_SLOPE`
  back per metre down, :data:`~synth.assets.fit.body.BRIDGE_SLOPE` sideways) leaves it; the gap to the skin, softly
  capped at the garment's ``bridge`` (``bridge * tanh(gap / bridge)``), faded where the skin
  turns to the side and averaged over the mesh, moves the shell forward (along -y), down to the
  hem's band (:data:`HEM_FLAT`); there the offset and the folds turn forward too
  (:data:`BRIDGE_TURN`). Vertical folds hang from there down to the waist.
* **waist**: horizontal compression folds over the last :data:`WAIST_BAND` above the hem.
* **armpits**: tension folds radiating from each armpit over the chest and back (the lowest
  point where the arm meets the torso), strongest 3-10 cm from it.
* **sleeves**: horizontal compression folds around the arm above the elbow.

Every fold is a non-negative offset (ridges stand out, valleys touch the base offset), so none
pushes the cloth into the skin; they fade out over :data:`NECK_FADE` under the neck's base (the
necklines and the collars lie on a plain shell) and in the crease where an arm rests on the
torso (:data:`CREASE_ROOM`: there the cloth has no room to fold). Each pattern's crests meander and vary in height (plane-wave noise drawn from the
``rng`` passed in, :class:`~synth.assets.fit.body.WaveNoise`). Per garment, :data:`DRAPES` gives
the fold height ``amp``, crest-to-crest ``wavelength`` and the largest ``bridge`` (a looser,
thicker garment: larger, softer folds).

The displacement is computed at the shell's build: the fit's push-out and binding carry it, so a
garment keeps its folds through expressions (:meth:`synth.assets.fit.body.FittedShell.follow`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.assets.fit.body import Body, WaveNoise
from synth.model.meshutil import smoothstep


@dataclass(frozen=True)
class Drape:
    """How a garment folds: ``amp`` (m) the height of a fold's crest over its valley,
    ``wavelength`` (m) crest to crest, ``bridge`` (m) the largest gap spanned below the chest."""

    amp: float
    wavelength: float
    bridge: float


#: per kind of garment (:data:`KIND`): thin knits cling (small, close folds), woven shirts fold a
#: little deeper, fleece hoodies and coats hang in large soft folds, tailored jackets are stiff
DRAPES = {
    "fitted": Drape(0.004, 0.045, 0.012),  # T-shirts, tank tops, scrubs, polos (jersey, pique)
    "knit": Drape(0.005, 0.055, 0.016),  # sweaters, turtlenecks
    "shirt": Drape(0.005, 0.05, 0.02),  # woven shirts
    "loose": Drape(0.010, 0.08, 0.03),  # hoodies
    "tailored": Drape(0.005, 0.09, 0.022),  # jackets
    "coat": Drape(0.008, 0.10, 0.03),
    "under": Drape(0.002, 0.04, 0.01),  # a shirt or T-shirt under a jacket or coat
}
#: garment id (or ``uniform:style``) -> kind of :data:`DRAPES`; every other garment: "fitted"
KIND = {"sweater": "knit", "turtleneck": "knit", "scarf_over_sweater": "knit", "shirt_collar": "shirt",
        "uniform:work_shirt": "shirt", "hoodie": "loose", "jacket_blazer": "tailored", "coat": "coat"}

#: the chest's high point is the mean height of the front vertices this close (m) to the furthest
#: forward
CHEST_TOLERANCE = 0.003
#: where the bridge's gap passes this (m), the offset and the folds go forward (-y), not along the
#: skin's normal
BRIDGE_TURN = 0.006
#: the folds grow from nothing at the neck's base to full height this far (m) under it
NECK_FADE = 0.06
#: height (m) of the band above the hem with horizontal (compression) folds
WAIST_BAND = 0.09
#: the hem's own band (m): the folds and the bridge fade to nothing over it (a hem is stitched flat,
#: and stays one smooth loop)
HEM_FLAT = 0.02
#: distances (m) from the armpit over which its tension folds rise and fade
ARMPIT_RISE, ARMPIT_REACH = (0.015, 0.04), (0.08, 0.15)
#: radial folds from an armpit: this many per half turn around it (crests about ``wavelength``
#: apart 9 cm from it)
ARMPIT_RAYS = 6
#: the sleeve's compression folds span this part of the upper arm (t, 0 armhole .. 1 elbow; a short
#: sleeve ends before it)
ELBOW_T = (0.6, 0.85)
#: folds shrink to nothing where the skin across a crease (an arm resting on the torso) is nearer
#: than the first distance (m), and have their full height from the second on
CREASE_ROOM = (0.012, 0.035)
#: share of the fold height given to unstructured wrinkles everywhere (below the neck fade)
WRINKLE_SHARE = 0.25


def kind_of(aid: str, style: str | None = None) -> str:
    """The kind of :data:`DRAPES` of garment ``aid`` (a uniform's ``style``)."""
    return KIND.get(f"{aid}:{style}", KIND.get(aid, "fitted"))


def crease_room(body: Body) -> np.ndarray:
    """(V,) distance (m) from each vertex to the nearest vertex of the other side of an arm's
    crease (an arm's to the torso's, the torso's to an arm's); inf without arms."""
    arms = body.arms
    out = np.full(len(body.V), np.inf)
    if arms is None:
        return out
    from scipy.spatial import cKDTree

    on_arm = arms.member >= 0.5
    for own in (on_arm, ~on_arm):
        if own.any() and (~own).any():
            out[own] = cKDTree(body.V[~own]).query(body.V[own])[0]
    return out


def _armpits(body: Body) -> np.ndarray:
    """(2, 3) the lowest point where each arm meets the torso (the armhole vertex furthest down
    the arm, its innermost on ties); empty without arms."""
    fr = body.arms
    if fr is None:
        return np.zeros((0, 3))
    out = []
    for s, sign in (("L", 1.0), ("R", -1.0)):
        on = np.nonzero((fr.side == sign) & (fr.t >= fr.armpit_t[s] - 0.03) & (fr.t <= fr.armpit_t[s]))[0]
        if len(on) == 0:
            on = np.nonzero(fr.side == sign)[0]
        # the innermost (smallest |x|), ties to the lowest index: no float tie decides alone
        k = on[np.lexsort((on, np.round(np.abs(body.V[on, 0]), 6)))[0]]
        out.append(body.V[k])
    return np.array(out)


class Folds:
    """The offset of a torso shell (a callable for :meth:`Body.shell`, with per-body-vertex
    ``fields``): ``base`` (m, the fabric thickness and clearance) plus ``extra(P, N)`` (a
    garment's own shaping: lapels, a turtleneck's collar) along the normals, plus the folds of
    ``drape`` and its bridge along -y. ``rng`` draws the crests' meanders and heights, the
    wrinkles (plane-wave noises) and the patterns' phases."""

    def __init__(self, body: Body, rng: np.random.Generator, base: float, drape: Drape, extra=None):
        self.base, self.drape, self.extra = float(base), drape, extra
        lam = drape.wavelength
        # crests that meander (vertical folds wander sideways, horizontal ones up and down)
        self.meander = WaveNoise(rng, 3.0 * lam, 8, stretch=(0.3, 0.3, 1.0))
        self.height = WaveNoise(rng, 2.0 * lam, 8)
        self.wrinkle = WaveNoise(rng, 0.6 * lam, 12, stretch=(1.0, 1.0, 0.4))
        self.phase = rng.uniform(0.0, 2.0 * np.pi, 4)
        V = body.V
        n = len(V)
        fr = body.frame
        self.center = fr.center.copy()
        self.z_neck = float(V[fr.ring, 2].min())
        arms = body.arms
        member = np.zeros(n) if arms is None else arms.member
        t = np.zeros(n) if arms is None else arms.t
        gap = body.bridge_gap if drape.bridge > 0 else np.zeros(n)
        gap = drape.bridge * np.tanh(gap / drape.bridge) if drape.bridge > 0 else gap
        # the chest's high point: the mean height of the front torso vertices within CHEST_TOLERANCE
        # of the furthest forward (no single vertex decides it)
        front = (member < 0.3) & (body.N[:, 1] < -0.5) & (V[:, 2] < self.z_neck - 0.05) & (body.hem > 0.05)
        if front.any():
            y = V[front, 1]
            self.z_chest = float(V[front, 2][y < y.min() + CHEST_TOLERANCE].mean())
        else:
            self.z_chest = self.z_neck - 0.15
        self.pits = _armpits(body)
        room = smoothstep(crease_room(body), *CREASE_ROOM)
        #: (V, 6) per body vertex: arm membership, place down the arm, hem distance, bridge gap,
        #: arm length (0 off the arms), room to fold (0 in a crease .. 1)
        alen = np.zeros(n) if arms is None else np.where(arms.side > 0, arms.length["L"],
                                                         np.where(arms.side < 0, arms.length["R"], 0.0))
        self.fields = np.stack([member, t, body.hem, gap, alen, room], 1)

    def folds(self, P: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, dict]:
        """(n,) the fold displacement (m, >= 0, along the normal) at base points ``P`` with their
        interpolated ``fields`` ``f``, and its components (each in [0, 1]) by name."""
        d = self.drape
        lam = d.wavelength
        member, t, hem, _, alen, room = f.T
        torso = 1.0 - np.clip(member, 0.0, 1.0)
        fade = smoothstep(self.z_neck - P[:, 2], 0.0, NECK_FADE) * smoothstep(hem, 0.0, HEM_FLAT)
        rel = P - self.center
        u = 0.16 * np.arctan2(rel[:, 0], -rel[:, 1])  # arc length (m) round a torso of ~16 cm radius
        m = self.meander(P)
        hgt = 0.6 + 0.4 * self.height(P)  # crest height varies 0.2 .. 1
        # vertical folds hanging from under the chest to the waist (ridges narrower than valleys)
        w_drape = smoothstep(self.z_chest - P[:, 2], -0.01, 0.08)
        w_waist = 1.0 - smoothstep(hem, HEM_FLAT, WAIST_BAND)
        vert = (0.5 + 0.5 * np.cos(2 * np.pi * (u + 0.25 * lam * m) / lam + self.phase[0])) ** 1.5
        horiz = (0.5 + 0.5 * np.cos(2 * np.pi * (P[:, 2] + 0.2 * lam * m) / (0.6 * lam) + self.phase[1])) ** 1.5
        # radial folds round each armpit
        pit = np.zeros(len(P))
        for k, A in enumerate(self.pits):
            r = np.linalg.norm(P - A, axis=1)
            w = smoothstep(r, *ARMPIT_RISE) * (1.0 - smoothstep(r, *ARMPIT_REACH))
            ang = np.arctan2(P[:, 2] - A[2], np.abs(P[:, 0] - A[0]) + 0.3 * np.abs(P[:, 1] - A[1]))
            ray = (0.5 + 0.5 * np.cos(ARMPIT_RAYS * 2.0 * ang + 0.6 * m + self.phase[2] + k)) ** 2
            pit = np.maximum(pit, w * ray)
        # rings round the sleeve above the elbow
        w_elbow = smoothstep(t, ELBOW_T[0], ELBOW_T[0] + 0.1) * (1.0 - smoothstep(t, ELBOW_T[1], ELBOW_T[1] + 0.1))
        ring = (0.5 + 0.5 * np.cos(2 * np.pi * (t * alen + 0.2 * lam * m) / (0.6 * lam) + self.phase[3])) ** 1.5
        parts = {
            "drape": torso * w_drape * (1.0 - w_waist) * vert,
            "waist": torso * w_waist * horiz,
            "armpit": torso * pit,
            "elbow": np.clip(member, 0.0, 1.0) * w_elbow * ring,
        }
        body = parts["drape"] + parts["waist"] + parts["armpit"] + parts["elbow"]
        wr = WRINKLE_SHARE * (0.5 + 0.5 * self.wrinkle(P))
        return room * fade * d.amp * (hgt * np.minimum(body, 1.0) + wr), parts

    def reach(self, elbow: bool = True) -> float:
        """The largest offset (m) off the skin on the upper arms (the hair's keep-out): base plus the
        rings above the elbow (``elbow``: a sleeve that reaches them) and the wrinkles."""
        return self.base + self.drape.amp * ((1.0 if elbow else 0.0) + WRINKLE_SHARE)

    def __call__(self, P: np.ndarray, N: np.ndarray, f: np.ndarray) -> np.ndarray:
        s = self.base + self.folds(P, f)[0]
        if self.extra is not None:
            s = s + self.extra(P, N)
        fade = smoothstep(self.z_neck - P[:, 2], 0.0, NECK_FADE) * smoothstep(f[:, 2], 0.0, HEM_FLAT)
        gap = fade * f[:, 3]
        # where the cloth spans a hollow it faces forward, not along the skin's normal there (the
        # underside of the chest faces down: offsets along it would cross)
        b = smoothstep(gap, 0.0, BRIDGE_TURN)[:, None]
        fwd = np.array([0.0, -1.0, 0.0])
        d = N * (1.0 - b) + fwd * b
        d /= np.linalg.norm(d, axis=1, keepdims=True).clip(1e-9)
        out = d * s[:, None]
        out[:, 1] -= gap
        return out
