"""The body a shell is fitted to (garments, headwear), and the fit itself; pure numpy.

A shell rig (``synth.assets.fit.garment``, ``synth.assets.fit.headwear``) describes its mesh as
:class:`Parts` built from a :class:`Body` and returns a :class:`Shell`: the parts, the body
triangles it is bound to, its materials as :class:`Cloth` descriptions and its record.
:func:`fit_shell` then cuts trimmable parts where they ended up deep inside another body part
(a chin sunk into the chest at -3 SD; :mod:`synth.assets.fit.trim`), pushes every other vertex out to
``clearance`` (:func:`synth.assets.fit.attach.push_out`) and binds the result to the body
(:class:`synth.assets.fit.attach.Binding`); :meth:`FittedShell.follow` re-applies that
binding to new body vertices (an expression change) and pushes out again. The Blender rigs
only turn a :class:`FittedShell` into a mesh object and materials.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from synth.assets.fit.attach import Binding, body_query, push_out
from synth.assets.fit.hem import neighbour_mean_matrix
from synth.assets.fit.masks import jaw_line, region_mask
from synth.assets.fit.meshops import (clip_by_field, level_points, oriented_boundary_loops, resample_loop, subdivide,
                                      subdivide_where)
from synth.assets.fit.trim import Rim, add_rims, place_rims, push_out_edges, trim_part
from synth.geometry.normals import normalize, vertex_normals
from synth.model.meshutil import smoothstep


class WaveNoise:
    """Smooth deterministic 3D noise in [-1, 1]: a sum of random plane waves (from ``rng``).

    ``stretch`` scales the axes of the wave vectors (e.g. (1, 1, 0.3): folds that run
    vertically). Used for geometric wrinkles and slack."""

    def __init__(self, rng: np.random.Generator, wavelength: float, n_waves: int = 12, stretch=(1.0, 1.0, 1.0)):
        d = normalize(rng.normal(size=(n_waves, 3)) * np.asarray(stretch, np.float64))
        k = 2 * np.pi / (wavelength * rng.uniform(0.7, 1.4, n_waves))
        self.k = d * k[:, None]
        self.phase = rng.uniform(0, 2 * np.pi, n_waves)
        self.amp = rng.uniform(0.5, 1.0, n_waves)
        self.amp /= self.amp.sum()

    def __call__(self, P: np.ndarray) -> np.ndarray:
        return np.sin(np.asarray(P) @ self.k.T + self.phase) @ self.amp


class NeckFrame:
    """Where the neck meets the shoulders, for any identity (pure numpy).

    ``ring``: shoulder vertices adjacent to neck vertices (the neck base); ``center``: its
    centroid; angles ``theta = atan2(x - cx, -(y - cy))`` (0 in front, +-pi behind, +pi/2
    at the subject's left). ``z_ring(theta)``: height of the neck base around the neck;
    ``z_cap(theta)``: highest a collar may rise (1.2 cm under the jaw line, masks.jaw_line,
    in front of the ears; unlimited behind)."""

    def __init__(self, V: np.ndarray, F: np.ndarray, regions: dict, ibug68: np.ndarray):
        n = len(V)
        neck = region_mask(regions, ["neck"], n)
        sh = region_mask(regions, ["shoulders"], n)
        E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        E = np.concatenate([E, E[:, ::-1]])
        ring = np.unique(E[neck[E[:, 0]] & sh[E[:, 1]], 1])
        self.ring = ring
        self.center = V[ring].mean(0)
        th = self.theta(V[ring])
        o = np.argsort(th)
        self._th = np.concatenate([th[o] - 2 * np.pi, th[o], th[o] + 2 * np.pi])
        self._z = np.tile(V[ring][o, 2], 3)
        jaw = jaw_line(ibug68)
        jt = self.theta(jaw)
        o = np.argsort(jt)
        self._jt, self._jz = jt[o], jaw[o, 2] - 0.012
        self.chin = np.asarray(ibug68[8], np.float64)
        self.radius = float(np.median(np.linalg.norm((V[ring] - self.center)[:, :2], axis=1)))

    def theta(self, P: np.ndarray) -> np.ndarray:
        d = np.asarray(P, np.float64) - self.center
        return np.arctan2(d[..., 0], -d[..., 1])

    def rxy(self, P: np.ndarray) -> np.ndarray:
        d = np.asarray(P, np.float64) - self.center
        return np.hypot(d[..., 0], d[..., 1])

    def z_ring(self, th) -> np.ndarray:
        # smooth the base height a little (the ring is a vertex zig-zag)
        th = np.asarray(th, np.float64)
        acc = sum(np.interp(th + d, self._th, self._z) for d in (-0.15, 0.0, 0.15))
        return acc / 3.0

    def z_cap(self, th) -> np.ndarray:
        th = np.asarray(th, np.float64)
        inside = (th >= self._jt[0]) & (th <= self._jt[-1])
        return np.where(inside, np.interp(th, self._jt, self._jz), np.inf)

    def outward(self, P: np.ndarray) -> np.ndarray:
        d = np.asarray(P, np.float64) - self.center
        d[..., 2] = 0.0
        return normalize(d)


class Body:
    """Body arrays for one build: skin query, source triangles, neck frame, normals."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, regions: dict, ibug68: np.ndarray):
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(triangles, np.int64)
        self.regions = regions
        n = len(self.V)
        skin = region_mask(regions, ["skin"], n)
        self.skin_tris = np.nonzero(skin[self.F].all(1))[0]
        self.query = body_query(self.V, self.F, self.skin_tris)
        self.N = vertex_normals(self.V, self.F[self.skin_tris], fallback=(0.0, 0.0, 1.0))
        ns = region_mask(regions, ["neck", "shoulders"], n) & skin
        self.torso_tris = np.nonzero(ns[self.F].all(1))[0]
        hd = region_mask(regions, ["neck", "scalp", "ears", "face"], n) & skin
        self.head_tris = np.nonzero(hd[self.F].all(1))[0]
        self.frame = NeckFrame(self.V, self.F, regions, ibug68)
        self.lm = np.asarray(ibug68, np.float64)
        self._hem = None
        self._arms = False
        self._bridge = None
        self._torso_query = None

    @classmethod
    def of(cls, head) -> "Body":
        """The body of a head context (anything with ``vertices``, ``data.triangles``,
        ``data.regions`` and ``landmarks["ibug68"]``: the rigs' HeadContext)."""
        return cls(head.vertices, head.data.triangles, head.data.regions, head.landmarks["ibug68"])

    @property
    def hem(self) -> np.ndarray:
        """Per-vertex hem field (>= 0 above the hem; :mod:`synth.assets.fit.hem`), computed once."""
        if self._hem is None:
            from synth.assets.fit.hem import hem_field

            self._hem = hem_field(self.V, self.F)
        return self._hem

    @property
    def arms(self):
        """The bust's upper arms (:class:`synth.assets.fit.arms.ArmFrame`; None for a model without
        them), computed once."""
        if self._arms is False:
            from synth.assets.fit.arms import arm_frame

            self._arms = arm_frame(self.V, self.F, self.regions)
        return self._arms

    @property
    def torso_query(self):
        """Signed distance to the neck and shoulders' skin only (``torso_tris``: no chin or jaw
        near a collar), built once."""
        if self._torso_query is None:
            self._torso_query = body_query(self.V, self.F, self.torso_tris)
        return self._torso_query

    @property
    def bridge_gap(self) -> np.ndarray:
        """(V,) how far a sheet hanging from the chest stands in front of the skin
        (:func:`bridge_gap`), computed once."""
        if self._bridge is None:
            self._bridge = bridge_gap(self)
        return self._bridge

    @property
    def arm_faces(self) -> np.ndarray | None:
        """(T,) bool: the triangles of the bust's upper arms (None for a model without them)."""
        if self.arms is None:
            return None
        from synth.assets.fit.arms import arm_triangles

        out = np.zeros(len(self.F), bool)
        out[arm_triangles(self.F, self.regions)] = True
        return out

    def shell(self, tris: np.ndarray, field: np.ndarray, offset_fn, subdiv: int = 1, weights: bool = False,
              refine=None):
        """Clip ``tris`` at ``field >= 0``, subdivide, offset by ``offset_fn(base points, normals)``
        (a distance along the normals, or (n, 3) displacements; an ``offset_fn`` with ``fields``,
        (V, k) per body vertex, gets them interpolated as a third argument:
        :class:`synth.assets.fit.folds.Folds`).
        Returns (P, faces, cut mask), and the (M, V) combination matrix of the body vertices
        giving each point's base position when ``weights``. ``refine``: subdivide only the faces
        for whose base centroids (n, 3) it returns True (and their neighbours as the mesh needs:
        :func:`synth.assets.fit.meshops.subdivide_where`); None: every face."""
        W, faces, cut = clip_by_field(self.F[tris], field, len(self.V))
        if len(faces) == 0:
            P = np.zeros((0, 3))
            return (P, faces, cut, W) if weights else (P, faces, cut)
        for _ in range(subdiv):
            if refine is None:
                W, faces, cut = subdivide(W, faces, cut)
            else:
                base = np.asarray(W @ self.V)
                W, faces, cut = subdivide_where(W, faces, cut, np.asarray(refine(base[faces].mean(1)), bool))
        base = np.asarray(W @ self.V)
        nrm = normalize(np.asarray(W @ self.N))
        fields = getattr(offset_fn, "fields", None)
        off = np.asarray(offset_fn(base, nrm) if fields is None else offset_fn(base, nrm, np.asarray(W @ fields)))
        P = base + (off if off.ndim == 2 else nrm * off[:, None])
        return (P, faces, cut, W) if weights else (P, faces, cut)

    def neck_loop(self, z_fn, n: int = 48, angle0: float = 0.0) -> np.ndarray:
        """Loop on the neck/shoulder surface where ``z == z_fn(theta)``, resampled at ``n``
        equal angles around the neck (index 0 at theta = angle0 - pi)."""
        f = z_fn(self.frame.theta(self.V)) - self.V[:, 2]
        pts = level_points(self.V, self.F[self.torso_tris], f)
        return resample_loop(pts, self.frame.center, n, angle0)


class Parts:
    """Accumulates mesh parts: (positions, faces, material slot, trimmable, inside, smooth edge,
    rim)."""

    def __init__(self):
        self.P, self.F, self.M, self.T, self.R, self.S, self.rim = [], [], [], [], [], [], []

    def add(self, P, F, slot: int = 0, trim: bool = False, inside: bool = False, smooth_edge=False, rim=None):
        """``trim``: vertices deep in another body part are trimmed; ``inside``: the part lies
        inside the body on purpose (a hem cap) and is never pushed out; ``smooth_edge`` (bool or
        per vertex): the boundary loops through these vertices only are kept smooth through the
        fit (a torso shell's necklines: every vertex but the hem's); ``rim``: ``(radius,
        flatten, slot)`` of a tube laid on those loops once they are fitted
        (:func:`synth.assets.fit.trim.add_rims`), or None."""
        if len(F) == 0:
            return
        self.rim.append(rim)
        self.P.append(np.asarray(P, np.float64))
        self.F.append(np.asarray(F, np.int64))
        self.M.append(np.full(len(F), slot, np.int32))
        self.T.append(np.full(len(P), trim))
        self.R.append(np.full(len(P), inside))
        self.S.append(np.array(np.broadcast_to(np.asarray(smooth_edge, bool), (len(P),))))

    def merged(self):
        """(P, F, slot per face, trimmable / inside / smooth edge per vertex)."""
        off = np.cumsum([0] + [len(p) for p in self.P])
        P = np.concatenate(self.P)
        F = np.concatenate([f + o for f, o in zip(self.F, off[:-1])])
        return (P, F, np.concatenate(self.M), np.concatenate(self.T), np.concatenate(self.R),
                np.concatenate(self.S))


@dataclass(frozen=True)
class Cloth:
    """One material of a shell, for the Blender side (``cloth_material``): slot = list position."""

    name: str
    colour: object  # a colour name or an (h, s, v) triple
    fabric: str
    knit_scale: float
    seed: float


@dataclass
class Shell:
    """A shell before the fit: its parts, the body triangles it is bound to, its materials."""

    cls: str  # asset class (garment, headwear)
    name: str  # object name
    parts: Parts
    anchor_tris: np.ndarray
    cloths: list[Cloth]
    info: dict = field(default_factory=dict)


#: :meth:`FittedShell.follow` recomputes the garment's vertices within this distance (m) of a body
#: vertex that moved since the fit (a jaw opening moves the chin by 2-3 cm); the others keep theirs
FOLLOW_REACH = 0.05


@dataclass
class FittedShell:
    """A shell trimmed, pushed out and bound: the mesh and what ``follow`` needs."""

    cls: str
    name: str
    P: np.ndarray  # (V, 3) world positions
    F: np.ndarray  # (T, 3) triangles
    M: np.ndarray  # (T,) material slot per triangle
    cloths: list[Cloth]
    binding: Binding
    body_tris: np.ndarray
    clearance: float
    info: dict
    inside: np.ndarray | None = None  # (V,) vertices never pushed out (hem caps)
    edge_loops: list = field(default_factory=list)  # boundary loops kept smooth (necklines)
    rims: list[Rim] = field(default_factory=list)  # tubes laid on necklines
    body_rest: np.ndarray | None = None  # (B, 3) the body's vertices at the fit

    def moving(self, vertices: np.ndarray) -> np.ndarray | None:
        """(V,) the vertices :meth:`follow` recomputes on new body ``vertices``: those bound to a
        triangle with a vertex that moved since the fit, or within :data:`FOLLOW_REACH` of such a
        vertex, and every vertex of a neckline loop that has one and of its rim; None: all (no rest
        body known)."""
        V = np.asarray(vertices, np.float64)
        if self.body_rest is None or V.shape != self.body_rest.shape:
            return None
        moved = np.any(V != self.body_rest, axis=1)
        active = np.zeros(len(self.P), bool)
        if not moved.any():
            return active
        from scipy.spatial import cKDTree

        active = moved[self.binding.F].any(1)
        d, _ = cKDTree(V[moved]).query(self.P, distance_upper_bound=FOLLOW_REACH)
        active |= np.isfinite(d)
        for lo in self.edge_loops:
            if active[lo].any():
                active[lo] = True
        for r in self.rims:  # a rim is laid anew on its neckline
            if active[r.loop].any():
                active[r.start:r.stop] = True
        return active

    def follow(self, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """Positions on new body vertices: the binding re-applied, then pushed out again (the
        necklines from their build shape plus the body's motion averaged along them:
        :func:`synth.assets.fit.trim.push_out_edges`), and the rims laid anew on the necklines
        (:func:`synth.assets.fit.trim.place_rims`). Vertices far from every body vertex that moved
        (:meth:`moving`: the body below the neck does not move with an expression) keep their fitted
        positions."""
        active = self.moving(vertices)
        if active is not None and not active.any():
            return np.array(self.P, np.float64, copy=True)
        query = body_query(vertices, triangles, self.body_tris)
        skip = np.zeros(len(self.P), bool) if self.inside is None else self.inside.copy()
        for r in self.rims:
            skip[r.start:r.stop] = True  # placed from their neckline below
        if active is None:
            P = push_out_edges(self.binding.apply(vertices), query, self.clearance, skip, self.edge_loops,
                               rest=self.P)
            return place_rims(P, self.rims, query, self.clearance)
        P = np.array(self.P, np.float64, copy=True)
        P[active] = self.binding.apply(vertices, active)
        loops = [lo for lo in self.edge_loops if active[lo[0]]]
        P = push_out_edges(P, query, self.clearance, skip | ~active, loops, rest=self.P)
        return place_rims(P, [r for r in self.rims if active[r.loop[0]]], query, self.clearance)


def fit_shell(body: Body, shell: Shell, clearance: float) -> FittedShell:
    """Trim the trimmable parts where they run deep inside the skin (:func:`trim_part`), push
    out (keeping the smooth-edge parts' boundary loops smooth: :func:`push_out_edges`), lay the
    rims on the fitted necklines (:func:`add_rims`), bind."""
    parts, trimmed = Parts(), 0
    src = shell.parts
    for P, F, M, T, R, S, rim in zip(src.P, src.F, src.M, src.T, src.R, src.S, src.rim):
        if T.any():
            P, F, S, n = trim_part(body.query, P, F, S, body.arm_faces)
            trimmed += n
        parts.add(P, F, int(M[0]), bool(T.any()), bool(R.any()), S, rim)
    P, F, M, _, R, S = parts.merged()
    loops = [lo for lo in oriented_boundary_loops(F) if S[lo].all()]
    P = push_out_edges(P, body.query, clearance, R, loops)
    owner = np.repeat(np.arange(len(parts.P)), [len(p) for p in parts.P])
    specs = [(lo, parts.rim[owner[lo[0]]]) for lo in loops if parts.rim[owner[lo[0]]] is not None]
    P, F, M, rims = add_rims(P, F, M, specs, body.query, clearance)
    R = np.concatenate([R, np.zeros(len(P) - len(R), bool)])
    binding = Binding(body.V, body.F, shell.anchor_tris, P)
    info = dict(shell.info, vertices=int(len(P)), faces=int(len(F)), trimmed_vertices=int(trimmed))
    return FittedShell(shell.cls, shell.name, P, F, M, shell.cloths, binding, body.skin_tris, clearance, info,
                       R if R.any() else None, loops, rims, body.V.copy())


#: the sheet hanging from the chest moves back this much (m) per metre down
DRAPE_SLOPE = 0.3
#: ... and this much per metre sideways (the cloth spans the hollow between the breasts)
BRIDGE_SLOPE = 0.8
#: averaging passes of the bridge gap over the body's mesh
BRIDGE_SMOOTHING = 12


def bridge_gap(body: Body) -> np.ndarray:
    """(V,) how far (m, >= 0, uncapped) a sheet hanging from the chest stands in front of each
    front torso vertex (0 elsewhere): see :mod:`synth.assets.fit.folds`."""
    V, N = body.V, body.N
    n = len(V)
    on = np.zeros(n, bool)
    on[np.unique(body.F[body.torso_tris])] = True
    arms = body.arms
    if arms is not None:
        on &= arms.member < 0.3
    z_neck = float(V[body.frame.ring, 2].min())
    on &= (N[:, 1] < -0.2) & (V[:, 2] < z_neck - 0.03)
    idx = np.nonzero(on)[0]
    gap = np.zeros(n)
    if len(idx) == 0:
        return gap
    P = V[idx]
    y_cloth = np.empty(len(idx))
    for s in range(0, len(idx), 512):
        p = P[s:s + 512, None, :]
        dz = P[None, :, 2] - p[..., 2]
        cand = P[None, :, 1] + DRAPE_SLOPE * dz + BRIDGE_SLOPE * np.abs(P[None, :, 0] - p[..., 0])
        cand = np.where(dz >= 0.0, cand, np.inf)
        y_cloth[s:s + 512] = cand.min(1)
    # fading out where the skin turns sideways (no step at the edge of the front)
    gap[idx] = np.maximum(P[:, 1] - y_cloth, 0.0) * smoothstep(-N[idx, 1], 0.2, 0.7)
    M = neighbour_mean_matrix(body.F[body.torso_tris], n)
    for _ in range(BRIDGE_SMOOTHING):
        gap = M @ gap
    return gap
