"""Eye-glasses: parametric frame geometry and a contact solver, in plain numpy (no bpy).

Everything here is pure numpy/scipy so that it can be tested without Blender; the rig
(``blender_scripts.assets.glasses``) only turns the result into Blender meshes.

Geometry (metres, world axes: Z up, the face looks toward -Y, +X is the subject's left).
The frame is designed in a *frame space* whose axes are the world's (X left, Y back toward
the head, Z up), with the origin at the middle of the bridge at lens-centre height and the
lens fronts near y = 0:

* lens outline: a superellipse ``|u/a|^n + |z/b|^n = 1`` (``u`` outward from the lens
  centre, toward the temple) with per-style edits (aviator tear-drop, cat-eye wing lift);
  lenses carry a spherical front curve (base ~6) and a few degrees of face-form wrap;
* rims: tubes swept around the outline (boxy superellipse section for acetate, round for
  metal); half-rim = upper part only, browline = thick upper bar + thin metal loop,
  rimless = none (the lens edge is the frame);
* bridge (arched tube; aviators add a straight top bar), end pieces, hinges, nose pads on
  pad arms, temples (tubes) ending in ear hooks with temple tips.

Pose and contact (``fit_glasses``):

1. ear rests: the top of each ear's junction with the head (ear vertices sharing a
   triangle with non-ear vertices, the highest few); the temple centre line is placed
   there and pushed out of the surface to exactly ``radius + margin`` clearance;
2. a head-aligned basis from the two ear rests (yaw, roll) and the nose midline
   (ibug 27-30);
3. the front (rims, bridge, lenses, end pieces) is placed at the lens-centre height
   (pupils slightly above the lens centre), pitched by the pantoscopic tilt plus the slope
   of the hinge-to-ear line, and slid back toward the face until the first contact
   (conservative advancement on the signed distance: every step is no longer than the
   current clearance, so it never tunnels). A few heights are tried and the one that leaves
   the smallest nose gap wins;
4. nose pads are put on the nose surface (closest point + pseudo-normal) and joined to the
   rim by pad arms, so the frame always rests on the nose bridge;
5. temples run from the hinges to the ear rests (their length and spread follow the head)
   and hook down behind the ears; every temple sample is pushed out to clearance and
   smoothed (a few rounds).

Penetration uses a robust signed distance for the *open* head mesh: closest point on the
surface, signed by the angle-weighted pseudo-normal of the closest feature (face, edge or
vertex; Baerentzen & Aanaes 2005), which is exact for closed meshes and well behaved near
an open one.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from synth.assets.fit.closest import closest_on_triangles

MARGIN = 0.0002  # clearance left between any frame part and the skin (m)

# --------------------------------------------------------------------------------------
# signed distance to an open triangle mesh


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


class Surface:
    """Signed-distance queries against a triangle mesh (open meshes allowed)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, k: int = 24):
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(triangles, np.int64)
        self.k = int(k)
        V, F = self.V, self.F
        a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
        n = np.cross(b - a, c - a)
        ln = np.linalg.norm(n, axis=1, keepdims=True)
        self.face_normals = n / np.maximum(ln, 1e-30)
        # angle-weighted vertex pseudo-normals
        vn = np.zeros_like(V)
        for i in range(3):
            p0, p1, p2 = V[F[:, i]], V[F[:, (i + 1) % 3]], V[F[:, (i + 2) % 3]]
            u, w = p1 - p0, p2 - p0
            cosang = _dot(u, w) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-30)
            ang = np.arccos(np.clip(cosang, -1.0, 1.0))
            np.add.at(vn, F[:, i], self.face_normals * ang[:, None])
        self.vertex_normals = vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)
        # edge pseudo-normals: edge opposite local vertex j of face f
        keys = np.stack([np.sort(np.stack([F[:, (j + 1) % 3], F[:, (j + 2) % 3]], 1), 1) for j in range(3)], 1)
        flat = keys.reshape(-1, 2)
        uniq, inv = np.unique(flat, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        en = np.zeros((len(uniq), 3))
        np.add.at(en, inv, np.repeat(self.face_normals, 3, axis=0))
        en /= np.maximum(np.linalg.norm(en, axis=1, keepdims=True), 1e-30)
        self.edge_of_face = inv.reshape(-1, 3)
        self.edge_normals = en
        # candidate faces come from the k nearest face centroids (a face's centroid is within
        # its circumradius of every point of it; k = 16 covers the mesh's size variation)
        self.tree = cKDTree((a + b + c) / 3.0)

    def query(self, points: np.ndarray, chunk: int = 4096):
        """Closest points, unsigned and signed distances, pseudo-normals, closest faces."""
        P = np.asarray(points, np.float64).reshape(-1, 3)
        outs = [self._query(P[i:i + chunk]) for i in range(0, len(P), chunk)] or [self._query(P)]
        return tuple(np.concatenate([o[i] for o in outs]) for i in range(5))

    def _query(self, P):
        k = min(self.k, len(self.F))
        _, cand = self.tree.query(P, k=k)
        cand = np.asarray(cand).reshape(len(P), -1)
        tri = self.F[cand]
        q, bary = closest_on_triangles(P[:, None, :], self.V[tri[..., 0]], self.V[tri[..., 1]],
                                             self.V[tri[..., 2]])
        d2 = ((q - P[:, None, :]) ** 2).sum(-1)
        best = np.argmin(d2, axis=1)
        r = np.arange(len(P))
        face = cand[r, best]
        cp = q[r, best]
        bc = bary[r, best]
        dist = np.sqrt(d2[r, best])
        nz = bc > 1e-12
        cnt = nz.sum(1)
        normal = self.face_normals[face].copy()
        # edge: the zero coordinate's local index names the opposite edge
        e = cnt == 2
        if e.any():
            j = np.argmin(np.where(nz[e], 1, 0), axis=1)
            normal[e] = self.edge_normals[self.edge_of_face[face[e], j]]
        v = cnt == 1
        if v.any():
            j = np.argmax(bc[v], axis=1)
            normal[v] = self.vertex_normals[self.F[face[v], j]]
        side = np.sign(_dot(P - cp, normal))
        side = np.where(side == 0, 1.0, side)
        return cp, dist, dist * side, normal, face

    def signed_distance(self, points):
        return self.query(points)[2]

    def push_out(self, points, clearance, iterations: int = 6):
        """Move points along the surface normal until their signed distance is >= clearance."""
        P = np.array(points, np.float64).reshape(-1, 3)
        clearance = np.broadcast_to(np.asarray(clearance, np.float64), (len(P),))
        for _ in range(iterations):
            cp, dist, sd, n, _ = self.query(P)
            short = sd < clearance - 1e-7
            if not short.any():
                break
            # direction: away from the closest point (outside) or along the pseudo-normal (inside)
            d = np.where((sd > 1e-6)[:, None], (P - cp) / np.maximum(dist, 1e-12)[:, None], n)
            P[short] = cp[short] + d[short] * clearance[short, None]
        return P


class RayGrid:
    """Rays along one axis against a triangle mesh, through a 2D grid of the projected triangles.

    ``hits(P)`` gives, per point, the signed ray parameters ``t`` (along ``axis``) of every
    crossing of the line through the point (NaN padded). Parity of the crossings on one side
    decides inside/outside robustly even where the surface folds over itself (a fold adds two
    crossings) or is open elsewhere.
    """

    def __init__(self, vertices, triangles, axis, cell: float = 0.002):
        V = np.asarray(vertices, np.float64)
        F = np.asarray(triangles, np.int64)
        d = np.asarray(axis, np.float64)
        d = d / np.linalg.norm(d)
        e1 = np.cross(d, [0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.cross(d, [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(d, e1)
        self.d, self.E = d, np.stack([e1, e2])
        p2 = V @ self.E.T
        self.tri2 = p2[F]  # (T, 3, 2)
        self.depth = (V @ d)[F]  # (T, 3)
        self.cell = cell
        lo = self.tri2.min(1)
        hi = self.tri2.max(1)
        self.origin = lo.min(0) - cell
        i0 = np.floor((lo - self.origin) / cell).astype(np.int64)
        i1 = np.floor((hi - self.origin) / cell).astype(np.int64)
        self.shape = (int(i1[:, 0].max()) + 2, int(i1[:, 1].max()) + 2)
        ni, nj = i1[:, 0] - i0[:, 0] + 1, i1[:, 1] - i0[:, 1] + 1
        cnt = ni * nj
        tid = np.repeat(np.arange(len(F)), cnt)
        loc = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ci = i0[tid, 0] + loc % ni[tid]
        cj = i0[tid, 1] + loc // ni[tid]
        cid = ci * self.shape[1] + cj
        order = np.argsort(cid, kind="stable")
        cid, tid = cid[order], tid[order]
        counts = np.bincount(cid, minlength=self.shape[0] * self.shape[1])
        mx = max(1, int(counts.max()))
        start = np.cumsum(counts) - counts
        pos = np.arange(len(cid)) - start[cid]
        table = np.full((self.shape[0] * self.shape[1], mx), -1, np.int64)
        table[cid, pos] = tid
        self.table = table
        self.counts = counts

    def hits(self, P):
        P = np.asarray(P, np.float64).reshape(-1, 3)
        q = P @ self.E.T
        ij = np.floor((q - self.origin) / self.cell).astype(np.int64)
        ok = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < self.shape[0]) & (ij[:, 1] < self.shape[1])
        cid = np.where(ok, ij[:, 0] * self.shape[1] + ij[:, 1], 0)
        cnt = np.where(ok, self.counts[cid], 0)
        out = np.full((len(P), max(1, int(cnt.max(initial=0)))), np.nan)
        order = np.argsort(cnt, kind="stable")
        pd = P @ self.d
        for g in range(0, len(P), 256):  # groups of similar candidate counts: little padding
            idx = order[g:g + 256]
            w = int(cnt[idx].max(initial=0))
            if w == 0:
                continue
            cand = self.table[cid[idx], :w]
            cand = np.where(ok[idx, None], cand, -1)
            tri = self.tri2[np.maximum(cand, 0)]
            a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
            x = q[idx, None, :]
            v0, v1, v2 = b - a, c - a, x - a
            den = v0[..., 0] * v1[..., 1] - v1[..., 0] * v0[..., 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                bb = (v2[..., 0] * v1[..., 1] - v1[..., 0] * v2[..., 1]) / den
                cc = (v0[..., 0] * v2[..., 1] - v2[..., 0] * v0[..., 1]) / den
                aa = 1.0 - bb - cc
            valid = (cand >= 0) & (den != 0)
            # half-open edge rule so a ray through a shared edge counts once (up to round-off)
            inside = valid & (aa >= 0) & (bb >= 0) & (cc > 0) | valid & (aa > 0) & (bb > 0) & (cc == 0)
            dep = self.depth[np.maximum(cand, 0)]
            t = aa * dep[..., 0] + bb * dep[..., 1] + cc * dep[..., 2] - pd[idx, None]
            out[idx, :w] = np.where(inside, t, np.nan)
        return out

    def inside(self, P, direction: float = 1.0):
        """Odd number of crossings on the ``direction`` side of each point (+1: along axis)."""
        t = self.hits(P)
        n = np.sum(np.nan_to_num(t * direction, nan=-1.0) > 0, axis=1)
        return n % 2 == 1

    def first_hit(self, P, direction: float = 1.0):
        t = self.hits(P) * direction
        t = np.where(t > 0, t, np.inf)
        return t.min(1) if t.shape[1] else np.full(len(t), np.inf)


# --------------------------------------------------------------------------------------
# frame description


STYLES = ("rectangular", "round", "oval", "aviator", "cat_eye", "browline", "rimless", "half_rim")

COLOURS = {  # linear sRGB base colours
    "black": (0.012, 0.012, 0.013), "tortoise": (0.16, 0.06, 0.018), "brown": (0.09, 0.04, 0.018),
    "clear": (0.8, 0.8, 0.8), "silver": (0.85, 0.86, 0.87), "gold": (0.9, 0.62, 0.25),
    "navy": (0.01, 0.02, 0.08), "red": (0.45, 0.02, 0.02), "white": (0.8, 0.8, 0.78),
    "titanium": (0.55, 0.53, 0.5),
}
METALLIC_COLOURS = {"silver", "gold", "titanium"}


@dataclasses.dataclass
class FrameSpec:
    style: str
    lens_w: float  # box width of one lens (m)
    lens_h: float  # box height
    rim_w: float  # rim face width (in the lens plane)
    rim_d: float  # rim depth (along the optical axis)
    bridge: float  # distance between lenses (DBL)
    rim_mode: str  # full | half | none | browline
    material: str  # acetate | metal
    colour: str
    temple_colour: str
    tint: float
    superellipse: float
    wing_lift: float = 0.0
    double_bridge: bool = False
    pantoscopic_deg: float = 8.0
    wrap_deg: float = 4.0
    lens_thickness: float = 0.002
    temple_r: tuple = (0.0012, 0.0022)  # half sizes (horizontal, vertical) of the temple section
    tip_r: float = 0.0016

    def record(self) -> dict:
        d = dataclasses.asdict(self)
        return {k: (round(v, 6) if isinstance(v, float) else (list(v) if isinstance(v, tuple) else v))
                for k, v in d.items()}


def _pick(rng, choices):
    return choices[int(rng.integers(len(choices)))]


def frame_spec(style: str, params: dict, rng: np.random.Generator) -> FrameSpec:
    """Complete the plan's parameters with rig-drawn ones (bridge, missing sizes, ...)."""
    if style not in STYLES:
        raise ValueError(f"unknown glasses style {style!r}; expected one of {STYLES}")
    p = dict(params or {})
    u = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731 - always drawn, so draws stay aligned
    draws = {"w": u(0.046, 0.054), "h": u(0.03, 0.038), "rim": u(0.002, 0.005), "bridge": u(0.016, 0.021),
             "pct": u(6.0, 10.0), "wrap": u(2.0, 6.0), "mat": u(0.0, 1.0), "col": int(rng.integers(1 << 30))}
    w = float(p.get("lens_width_m", p.get("lens_diameter_m", draws["w"])))
    h = float(p.get("lens_height_m", p.get("lens_diameter_m", 0.0))) or None
    colour = str(p.get("frame_colour", ["black", "tortoise", "brown", "silver", "gold"][draws["col"] % 5]))
    material = str(p.get("frame_material", "metal" if colour in METALLIC_COLOURS else "acetate"))
    if style in ("aviator", "rimless"):
        material = "metal"
    rim_w = float(p.get("rim_thickness_m", draws["rim"]))
    n_exp, rim_mode, wing, dbl = 2.0, "full", 0.0, False
    if style == "rectangular":
        n_exp, h = 4.5, h or 0.68 * w
    elif style == "round":
        n_exp, h = 2.0, h or w
    elif style == "oval":
        n_exp, h = 2.3, h or 0.68 * w
    elif style == "aviator":
        n_exp, h, dbl = 2.4, h or 0.86 * w, bool(p.get("double_bridge", True))
        rim_w = min(rim_w, 0.0025)
    elif style == "cat_eye":
        n_exp, h, wing = 2.8, h or 0.66 * w, float(p.get("wing_lift", 0.5))
    elif style == "browline":
        n_exp, h, rim_mode = 3.2, h or 0.7 * w, "browline"
    elif style == "rimless":
        n_exp, h, rim_mode = 3.0, h or 0.62 * w, "none"
    elif style == "half_rim":
        n_exp, h, rim_mode = 3.5, h or 0.66 * w, "half"
    metal = material == "metal"
    if metal and style != "browline":
        rim_w = float(np.clip(0.45 * rim_w, 0.0012, 0.0022))
    rim_d = rim_w if metal else float(np.clip(1.3 * rim_w, 0.003, 0.006))
    temple_colour = str(p.get("temple_colour", colour))
    return FrameSpec(style=style, lens_w=w, lens_h=float(h), rim_w=rim_w, rim_d=rim_d, bridge=draws["bridge"],
                     rim_mode=rim_mode, material=material, colour=colour, temple_colour=temple_colour,
                     tint=float(p.get("lens_tint", 0.0)), superellipse=n_exp, wing_lift=wing, double_bridge=dbl,
                     pantoscopic_deg=draws["pct"], wrap_deg=draws["wrap"],
                     lens_thickness=0.0022 if style == "rimless" else 0.0018,
                     temple_r=(0.0007, 0.0007) if metal else (0.0011, 0.0021),
                     tip_r=0.0014 if metal else 0.0016)


# --------------------------------------------------------------------------------------
# mesh building blocks


def outline_2d(spec: FrameSpec, n: int = 96) -> np.ndarray:
    """(n, 2) lens outline (u outward toward the temple, z up) centred on the lens box,
    counter-clockwise seen from the front of the left lens."""
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    a, b, e = spec.lens_w / 2, spec.lens_h / 2, spec.superellipse
    c, s = np.cos(t), np.sin(t)
    u = a * np.sign(c) * np.abs(c) ** (2.0 / e)
    z = b * np.sign(s) * np.abs(s) ** (2.0 / e)
    if spec.style == "aviator":  # tear drop: the lower inner part droops toward the nose
        inner = np.clip((a - u) / (2 * a), 0, 1)
        z = np.where(z < 0, z * (1.0 + 0.45 * inner), z * 0.9)
        u = np.where(z < 0, u + 0.12 * a * (z / b) * (1 - inner), u)
    if spec.style == "cat_eye":  # outer top corner lifted into a wing
        outer = np.clip((u / a - 0.1) / 0.9, 0, 1) ** 2
        z = np.where(z > 0, z + spec.wing_lift * 0.35 * b * outer * (0.5 + 0.5 * z / b), z)
        u = np.where(z > 0, u + spec.wing_lift * 0.08 * a * outer, u)
        z = np.where(z < 0, z * (1.0 - 0.15 * (u / a + 1) / 2), z)
    pts = np.stack([u, z], 1)
    lo, hi = pts.min(0), pts.max(0)
    pts -= (lo + hi) / 2  # centre the box
    return pts


def _outward_normals_2d(pts):
    tang = np.roll(pts, -1, 0) - np.roll(pts, 1, 0)
    nrm = np.stack([tang[:, 1], -tang[:, 0]], 1)  # ccw outline -> right-hand normal points outward
    return nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)


def _rmf(curve: np.ndarray, up=(0.0, 0.0, 1.0)):
    """Rotation-minimising frames (double reflection) along an open polyline: (T, N, B)."""
    P = np.asarray(curve, np.float64)
    T = np.gradient(P, axis=0)
    T /= np.maximum(np.linalg.norm(T, axis=1, keepdims=True), 1e-12)
    up = np.asarray(up, np.float64)
    n0 = up - _dot(up, T[0]) * T[0]
    if np.linalg.norm(n0) < 1e-6:
        n0 = np.cross(T[0], [1.0, 0.0, 0.0])
    N = np.zeros_like(P)
    N[0] = n0 / np.linalg.norm(n0)
    for i in range(len(P) - 1):
        v1 = P[i + 1] - P[i]
        c1 = _dot(v1, v1)
        if c1 < 1e-20:
            N[i + 1] = N[i]
            continue
        rL = N[i] - (2 / c1) * _dot(v1, N[i]) * v1
        tL = T[i] - (2 / c1) * _dot(v1, T[i]) * v1
        v2 = T[i + 1] - tL
        c2 = _dot(v2, v2)
        N[i + 1] = rL - (2 / c2) * _dot(v2, rL) * v2 if c2 > 1e-20 else rL
        N[i + 1] /= np.linalg.norm(N[i + 1])
    B = np.cross(T, N)
    return T, N, B


def sweep(centre, ax1, ax2, h1, h2, exponent: float = 2.0, m: int = 10, closed: bool = False, caps: bool = True):
    """Tube of superellipse section (half sizes h1 along ax1, h2 along ax2) along ``centre``.
    Returns (V, F) triangles."""
    centre = np.asarray(centre, np.float64)
    n = len(centre)
    h1 = np.broadcast_to(np.asarray(h1, np.float64), (n,))
    h2 = np.broadcast_to(np.asarray(h2, np.float64), (n,))
    t = np.linspace(0, 2 * np.pi, m, endpoint=False)
    c, s = np.cos(t), np.sin(t)
    cu = np.sign(c) * np.abs(c) ** (2.0 / exponent)
    su = np.sign(s) * np.abs(s) ** (2.0 / exponent)
    V = (centre[:, None, :] + (h1[:, None] * cu[None, :])[..., None] * ax1[:, None, :]
         + (h2[:, None] * su[None, :])[..., None] * ax2[:, None, :]).reshape(-1, 3)
    rings = n if closed else n - 1
    i = np.arange(rings)[:, None]
    j = np.arange(m)[None, :]
    a = i * m + j
    b = i * m + (j + 1) % m
    cc = ((i + 1) % n) * m + (j + 1) % m
    d = ((i + 1) % n) * m + j
    F = np.concatenate([np.stack([a, b, cc], -1).reshape(-1, 3), np.stack([a, cc, d], -1).reshape(-1, 3)])
    if caps and not closed:
        V = np.concatenate([V, centre[[0, -1]]])
        c0, c1 = n * m, n * m + 1
        jj = np.arange(m)
        F = np.concatenate([F, np.stack([np.full(m, c0), (jj + 1) % m, jj], 1),
                            np.stack([np.full(m, c1), (n - 1) * m + jj, (n - 1) * m + (jj + 1) % m], 1)])
    return V, F.astype(np.int64)


def tube_along(curve, h1, h2, exponent=2.0, m=10, up=(0.0, 0.0, 1.0)):
    """Open tube along a polyline with rotation-minimising frames (h2 along the frame 'up')."""
    T, N, B = _rmf(curve, up)
    return sweep(curve, B, N, h1, h2, exponent, m)


def ellipsoid(centre, axes, radii, nu: int = 12, nv: int = 8):
    """Ellipsoid mesh; axes (3, 3) rows are unit directions."""
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, np.pi, nv + 1)[1:-1]
    uu, vv = np.meshgrid(u, v)
    loc = np.stack([np.cos(uu) * np.sin(vv), np.sin(uu) * np.sin(vv), np.cos(vv)], -1).reshape(-1, 3)
    loc = np.concatenate([loc, [[0, 0, 1], [0, 0, -1]]]) * np.asarray(radii)
    V = np.asarray(centre) + loc @ np.asarray(axes)
    F = []
    for r in range(nv - 2):
        for c in range(nu):
            a, b = r * nu + c, r * nu + (c + 1) % nu
            F += [[a, b + nu, b], [a, a + nu, b + nu]]
    top, bot = len(V) - 2, len(V) - 1
    last = (nv - 2) * nu
    for c in range(nu):
        F.append([top, c, (c + 1) % nu])
        F.append([bot, last + (c + 1) % nu, last + c])
    return V, np.asarray(F, np.int64)


def _merge(parts):
    Vs, Fs, off = [], [], 0
    for V, F in parts:
        Vs.append(V)
        Fs.append(F + off)
        off += len(V)
    if not Vs:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return np.concatenate(Vs), np.concatenate(Fs)


# --------------------------------------------------------------------------------------
# the front in frame space


@dataclasses.dataclass
class Front:
    parts: dict  # material key -> (V, F) in frame space
    lens_V: np.ndarray
    lens_F: np.ndarray
    hinges: np.ndarray  # (2, 3) left, right
    pad_anchors: np.ndarray  # (2, 3)
    lens_centres: np.ndarray  # (2, 3)
    bridge_samples: np.ndarray  # points of the bridge / inner rims (nose-contact candidates)


def _lens_surface_y(spec, u, z, u_in):
    """Depth (frame y, + toward the face) of the lens front at (u, z) of one lens."""
    R = 0.088  # ~ base 6 front curve
    r2 = u ** 2 + z ** 2
    sag = R - np.sqrt(np.maximum(R * R - r2, 0.0))
    return sag + math.sin(math.radians(spec.wrap_deg)) * (u - u_in)


def build_front(spec: FrameSpec, n: int = 96) -> Front:
    o2 = outline_2d(spec, n)
    nrm2 = _outward_normals_2d(o2)
    u_in = o2[:, 0].min()
    cx = spec.bridge / 2 - u_in  # lens-box centre offset from the middle
    lens_y = lambda u, z: _lens_surface_y(spec, u, z, u_in)  # noqa: E731
    th = spec.lens_thickness
    frame_parts, metal_parts, lens_parts = [], [], []
    hinges, anchors, centres, bridge_pts = [], [], [], []
    metal = spec.material == "metal"
    m_sec = 8 if metal else 10
    ex_sec = 2.0 if metal else 4.0
    for side in (1.0, -1.0):  # +1 left lens (x > 0), -1 right lens
        def to3(u, z, y):
            return np.stack([side * (cx + u), y, z], -1)

        # lens: front cap from concentric rings, back cap, edge wall
        K = 6
        ring_s = np.linspace(1.0, 0.0, K + 1)[:-1]
        front, back = [], []
        for s in ring_s:
            u, z = o2[:, 0] * s, o2[:, 1] * s
            y = lens_y(u, z)
            front.append(to3(u, z, y))
            back.append(to3(u, z, y + th))
        front.append(to3(np.zeros(1), np.zeros(1), lens_y(np.zeros(1), np.zeros(1))))
        back.append(to3(np.zeros(1), np.zeros(1), lens_y(np.zeros(1), np.zeros(1)) + th))
        fv, bv = np.concatenate(front), np.concatenate(back)
        F = []
        for k in range(K - 1):
            for j in range(n):
                a, b = k * n + j, k * n + (j + 1) % n
                F += [[a, b, b + n], [a, b + n, a + n]]
        cidx = K * n
        for j in range(n):
            F.append([(K - 1) * n + j, (K - 1) * n + (j + 1) % n, cidx])
        F = np.asarray(F, np.int64)
        if side < 0:
            F = F[:, ::-1]
        nv = len(fv)
        wall = []
        for j in range(n):
            a, b = j, (j + 1) % n
            wall += [[b, a, a + nv], [b, a + nv, b + nv]]
        wall = np.asarray(wall, np.int64)
        if side < 0:
            wall = wall[:, ::-1]
        lens_parts.append((np.concatenate([fv, bv]), np.concatenate([F[:, ::-1], F + nv, wall])))
        centres.append(to3(np.zeros(1), np.zeros(1), np.zeros(1))[0])

        # rim: centre line offset outward from the lens edge (the lens sits in a groove)
        edge_y = lens_y(o2[:, 0], o2[:, 1]) + th / 2
        off = spec.rim_w / 2 - 0.35 * min(spec.rim_w, 0.002)
        rim_c = to3(o2[:, 0] + nrm2[:, 0] * off, o2[:, 1] + nrm2[:, 1] * off, edge_y)
        ax1 = np.stack([side * nrm2[:, 0], np.zeros(n), nrm2[:, 1]], 1)
        ax2 = np.tile([0.0, 1.0, 0.0], (n, 1))
        top = o2[:, 1] > -0.05 * spec.lens_h
        if spec.rim_mode == "full":
            frame_parts.append(sweep(rim_c, ax1, ax2, spec.rim_w / 2, spec.rim_d / 2, ex_sec, m_sec, closed=True))
        elif spec.rim_mode in ("half", "browline"):
            idx = np.nonzero(top)[0]
            # contiguous run of the top part (the outline starts on the outer side)
            idx = np.roll(np.arange(n), -int(np.argmax(~top)))
            idx = idx[top[idx]]
            w = spec.rim_w * (1.5 if spec.rim_mode == "browline" else 1.0)
            d = max(spec.rim_d, 0.004) if spec.rim_mode == "browline" else spec.rim_d
            frame_parts.append(sweep(rim_c[idx], ax1[idx], ax2[idx], w / 2, d / 2, 4.0, 10))
            if spec.rim_mode == "browline":  # thin metal loop holding the lens
                metal_parts.append(sweep(rim_c, ax1, ax2, 0.0007, 0.0007, 2.0, 6, closed=True))
        # hinge / end piece at the upper outer edge of the outline
        j_out = int(np.argmax(o2[:, 0] + 0.6 * o2[:, 1]))
        pe = rim_c[j_out] + side * np.array([1.0, 0.0, 0.0]) * (spec.rim_w / 2)
        if spec.rim_mode == "none":
            pe = to3(o2[j_out, 0], o2[j_out, 1], lens_y(o2[j_out, 0], o2[j_out, 1]) + th / 2)
        hinge = pe + np.array([side * 0.0015, 0.007, 0.0])
        endc = np.linspace(pe, hinge, 6)
        endc[:, 0] += side * 0.0012 * np.sin(np.linspace(0, np.pi, 6))
        eh = max(0.0012, min(spec.rim_w, 0.003))
        (metal_parts if metal else frame_parts).append(tube_along(endc, 0.0012, eh, ex_sec, m_sec))
        metal_parts.append(sweep(np.array([hinge + [0, 0, -0.0022], hinge + [0, 0, 0.0022]]),
                                 np.array([[1.0, 0, 0]] * 2), np.array([[0, 1.0, 0]] * 2), 0.0011, 0.0011, 2.0, 8))
        hinges.append(hinge)
        # pad anchor: inner, lower part of the rim
        j_pad = int(np.argmin(o2[:, 0] - 0.35 * o2[:, 1] * 0 + 0.8 * np.abs(o2[:, 1] + 0.15 * spec.lens_h)))
        anchors.append(rim_c[j_pad] + np.array([0, th / 2 + 0.0005, 0]))
        inner = o2[:, 0] < (u_in + 0.3 * spec.lens_w)
        bridge_pts.append(rim_c[inner])

    # bridge(s): arched tube between the inner rims at ~ a quarter of the lens height up
    zb = 0.22 * spec.lens_h / 2 + 0.1 * spec.lens_h / 2
    jb = int(np.argmin(np.abs(o2[:, 1] - zb) + 10 * (o2[:, 0] - u_in)))
    pL = np.array([cx + o2[jb, 0] - spec.rim_w * 0.3, lens_y(o2[jb, 0], o2[jb, 1]) + th / 2, o2[jb, 1]])
    pR = pL * [-1, 1, 1]
    s = np.linspace(0, 1, 17)
    arch = 0.0035 if not metal else 0.0025
    bc = (1 - s)[:, None] * pR + s[:, None] * pL
    bc[:, 2] += arch * np.sin(np.pi * s)
    bc[:, 1] -= 0.001 * np.sin(np.pi * s)
    if spec.rim_mode == "none":
        bc[:, 1] += 0.0
    bw = (0.0009, 0.0009) if metal else (max(spec.rim_w, 0.003) * 0.5, spec.rim_d / 2)
    (metal_parts if metal else frame_parts).append(tube_along(bc, bw[1], bw[0], ex_sec, m_sec, up=(0, -1, 0)))
    bridge_pts.append(bc)
    if spec.double_bridge:
        jt = int(np.argmin(np.abs(o2[:, 0] - (u_in + 0.2 * spec.lens_w)) - 10 * o2[:, 1] * (o2[:, 1] > 0)))
        qL = np.array([cx + o2[jt, 0], lens_y(o2[jt, 0], o2[jt, 1]) + th / 2, o2[jt, 1] - 0.001])
        tb = (1 - s)[:, None] * (qL * [-1, 1, 1]) + s[:, None] * qL
        tb[:, 1] -= 0.0015 * np.sin(np.pi * s)
        metal_parts.append(tube_along(tb, 0.0008, 0.0008, 2.0, 8, up=(0, -1, 0)))
    parts = {"frame": _merge(frame_parts), "metal": _merge(metal_parts)}
    lV, lF = _merge(lens_parts)
    return Front(parts=parts, lens_V=lV, lens_F=lF, hinges=np.asarray(hinges), pad_anchors=np.asarray(anchors),
                 lens_centres=np.asarray(centres), bridge_samples=np.concatenate(bridge_pts))


# --------------------------------------------------------------------------------------
# head features


def _region(data_regions, name):
    r = data_regions.get(name)
    return None if r is None else np.asarray(r, np.int64)


def ear_rests(vertices, triangles, regions) -> np.ndarray:
    """(2, 3) top of the ear/head junction, left (+X) then right."""
    V = np.asarray(vertices, np.float64)
    T = np.asarray(triangles, np.int64)
    out = []
    for side, name in ((1.0, "ear_l"), (-1.0, "ear_r")):
        idx = _region(regions, name)
        if idx is None:
            allr = _region(regions, "ears")
            idx = allr[np.sign(V[allr, 0]) == side]
        ear = np.zeros(len(V), bool)
        ear[idx] = True
        mixed = ear[T].any(1) & ~ear[T].all(1)
        jv = np.unique(T[mixed][ear[T[mixed]]])
        if len(jv) < 3:
            jv = idx
        p = V[jv]
        top = p[np.argsort(-p[:, 2])[:5]]
        out.append(top.mean(0))
    return np.asarray(out)


def ear_hook_path(vertices, triangles, regions, side: float, rest: np.ndarray, length: float = 0.028):
    """Points behind the ear (the retro-auricular junction) going down from the ear rest."""
    V = np.asarray(vertices, np.float64)
    T = np.asarray(triangles, np.int64)
    name = "ear_l" if side > 0 else "ear_r"
    idx = _region(regions, name)
    if idx is None:
        allr = _region(regions, "ears")
        idx = allr[np.sign(V[allr, 0]) == side]
    ear = np.zeros(len(V), bool)
    ear[idx] = True
    mixed = ear[T].any(1) & ~ear[T].all(1)
    jv = np.unique(T[mixed][ear[T[mixed]]])
    p = V[jv]
    centre = V[idx].mean(0)
    ang = np.arctan2(p[:, 2] - centre[2], p[:, 1] - centre[1])  # 0: behind (+y), pi/2: top
    a0 = math.atan2(rest[2] - centre[2], rest[1] - centre[1])
    sel = (ang < a0 + 0.05) & (ang > a0 - 2.2)
    q = p[sel]
    order = np.argsort(-np.arctan2(q[:, 2] - centre[2], q[:, 1] - centre[1]))
    q = q[order]
    if len(q) < 2:
        q = np.array([rest + [0, 0.01, -0.008], rest + [0, 0.016, -0.02]])
    pts = [rest]
    acc = 0.0
    for x in q:
        d = np.linalg.norm(x - pts[-1])
        if d < 0.003:
            continue
        pts.append(x)
        acc += d
        if acc > length:
            break
    return np.asarray(pts)


def _resample(P, n):
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    t = np.linspace(0, s[-1], n)
    return np.stack([np.interp(t, s, P[:, i]) for i in range(3)], 1)


def _smooth(P, it=3, fix_first=2, fix_last=0):
    P = P.copy()
    for _ in range(it):
        Q = P.copy()
        Q[1:-1] = 0.25 * P[:-2] + 0.5 * P[1:-1] + 0.25 * P[2:]
        Q[:fix_first] = P[:fix_first]
        if fix_last:
            Q[-fix_last:] = P[-fix_last:]
        P = Q
    return P


def _rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


# --------------------------------------------------------------------------------------
# the solver


@dataclasses.dataclass
class GlassesFit:
    parts: dict  # material key -> (V (n,3) world, F (m,3))
    info: dict


def _head_basis(ears, lm):
    ex = ears[0] - ears[1]
    ex /= np.linalg.norm(ex)
    ez = np.array([0.0, 0.0, 1.0])
    ey = np.cross(ez, ex)
    ey /= np.linalg.norm(ey)
    ez = np.cross(ex, ey)
    return np.stack([ex, ey, ez], 1)  # columns: frame axes in world


class HeadQuery:
    """Signed distance to the head with the sign from ray parity (robust to folds and holes):
    front parts look forward (-Y of the head basis), temples look outward (+-X)."""

    def __init__(self, vertices, triangles, basis, midline_x: float, surface: Surface | None = None):
        self.surf = surface or Surface(vertices, triangles)
        self.B = basis
        self.mid = float(midline_x)
        self.gy = RayGrid(vertices, triangles, basis[:, 1])
        self.gx = RayGrid(vertices, triangles, basis[:, 0])

    def sd(self, P, lateral=None):
        P = np.asarray(P, np.float64).reshape(-1, 3)
        cp, dist, sdn, n, _ = self.surf.query(P)
        # parity rays only where the answer is in doubt: near the surface or on its inner side
        # by the pseudo-normal (far points on the outer side are outside)
        doubt = (sdn < 0) | (dist < 0.004)
        ins = np.zeros(len(P), bool)
        if doubt.any():
            lat = None if lateral is None else np.broadcast_to(np.asarray(lateral, bool), (len(P),))[doubt]
            ins[doubt] = self.inside(P[doubt], lat)
        return np.where(ins, -dist, dist), cp, dist, n, ins

    def inside(self, P, lateral=None):
        P = np.asarray(P, np.float64).reshape(-1, 3)
        if lateral is None:
            lateral = np.zeros(len(P), bool)
        lateral = np.broadcast_to(np.asarray(lateral, bool), (len(P),))
        ins = np.zeros(len(P), bool)
        if (~lateral).any():
            ins[~lateral] = self.gy.inside(P[~lateral], -1.0)
        if lateral.any():
            Q = P[lateral]
            side = np.where(Q @ self.B[:, 0] >= self.mid, 1.0, -1.0)
            r = np.zeros(len(Q), bool)
            for sgn in (1.0, -1.0):
                m = side == sgn
                if m.any():
                    r[m] = self.gx.inside(Q[m], sgn)
            ins[lateral] = r
        return ins

    def push_out(self, P, clearance, lateral, iterations: int = 8):
        """Move points out of the head and to ``clearance`` from it (escape along the parity
        ray when inside, along the closest-point direction when merely too close)."""
        P = np.array(P, np.float64).reshape(-1, 3)
        clearance = np.broadcast_to(np.asarray(clearance, np.float64), (len(P),)).copy()
        lat = np.broadcast_to(np.asarray(lateral, bool), (len(P),))
        for _ in range(iterations):
            sd, cp, dist, n, ins = self.sd(P, lat)
            if ins.any():
                Q = P[ins]
                out = np.zeros_like(Q)
                lq = lat[ins]
                if (~lq).any():
                    t = self.gy.hits(Q[~lq])
                    t = np.where(t < 0, t, np.nan)
                    out[~lq] = self.B[:, 1] * (np.nanmin(t, 1) - 1e-4)[:, None]
                if lq.any():
                    QQ = Q[lq]
                    side = np.where(QQ @ self.B[:, 0] >= self.mid, 1.0, -1.0)
                    t = self.gx.hits(QQ) * side[:, None]
                    t = np.where(t > 0, t, np.nan)
                    out[lq] = self.B[:, 0] * (side * (np.nanmax(t, 1) + 1e-4))[:, None]
                P[ins] = Q + np.nan_to_num(out)
                continue
            short = sd < clearance - 1e-7
            if not short.any():
                break
            dirn = (P - cp) / np.maximum(dist, 1e-12)[:, None]
            P[short] = cp[short] + dirn[short] * clearance[short, None]
        return P


def fit_glasses(vertices, triangles, regions, landmarks: dict, spec: FrameSpec, surface: Surface | None = None,
                front: Front | None = None) -> GlassesFit:
    """Pose the frame on a head: see the module docstring. Deterministic."""
    V = np.asarray(vertices, np.float64)
    T = np.asarray(triangles, np.int64)
    front = front or build_front(spec)
    lm = np.asarray(landmarks["ibug68"], np.float64)
    ears_raw = ear_rests(V, T, regions)
    B = _head_basis(ears_raw, lm)
    nose = lm[27:31]
    mid = nose.mean(0)
    hq = HeadQuery(V, T, B, float(mid @ B[:, 0]), surface)
    r_t = max(spec.temple_r)
    ears = np.stack([_settle(hq, e, r_t + MARGIN) for e in ears_raw])
    yaw = math.degrees(math.atan2(B[1, 0], B[0, 0]))
    roll = math.degrees(math.atan2(B[2, 0], math.hypot(B[0, 0], B[1, 0])))
    pup = []
    for nm, sl in (("pupil_l", slice(42, 48)), ("pupil_r", slice(36, 42))):
        r = _region(regions, nm)
        pup.append(V[r].mean(0) if r is not None else lm[sl].mean(0))
    pup = np.asarray(pup)
    front_pts = np.concatenate([front.parts["frame"][0], front.parts["metal"][0], front.lens_V])
    coarse = front_pts[:: max(1, len(front_pts) // 2500)]

    def place(pts, t, pitch):
        return (pts @ (B @ _rot_x(pitch)).T) + t

    mid_h = B.T @ mid
    y_start = (B.T @ lm[27])[1] - 0.05

    def tvec(y, z):
        return B @ np.array([mid_h[0], y, z])

    def contact(z, pitch):
        """Slide the front back (+Y of the head basis) from well in front of the face to the
        first contact, then settle to MARGIN clearance with the exact signed distance."""
        X = place(coarse, tvec(y_start, z), pitch)
        hit = hq.gy.first_hit(X, 1.0)
        s = float(hit.min())
        if not np.isfinite(s):
            s = 0.05
        near = coarse[hit < s + 0.004]
        y = y_start + s - MARGIN
        for _ in range(6):
            sd = hq.sd(place(near, tvec(y, z), pitch))[0].min()
            if abs(sd - MARGIN) < 2e-5:
                break
            y += (sd - MARGIN) * (0.5 if sd > MARGIN else 1.0)
        return y

    pupil_h = (B.T @ pup.mean(0))[2]
    z_nom = pupil_h - 0.12 * spec.lens_h
    ear_h = B.T @ ears.mean(0)
    nose_idx = _nose_faces(V, T, regions, lm)
    nose_surf = Surface(V, T[nose_idx], k=8)
    best = None
    for dz in (0.0, -0.003, 0.002, -0.006):
        pitch = math.radians(spec.pantoscopic_deg)
        for _ in range(3):
            y = contact(z_nom + dz, pitch)
            hinge_h = B.T @ (place(front.hinges, tvec(y, z_nom + dz), pitch).mean(0))
            slope = math.atan2(hinge_h[2] - ear_h[2], ear_h[1] - hinge_h[1])
            new_pitch = math.radians(spec.pantoscopic_deg) + float(np.clip(slope, -0.15, 0.2))
            done = abs(new_pitch - pitch) < 2e-3
            pitch = new_pitch
            if done:
                break
        y = contact(z_nom + dz, pitch)
        bs = place(front.bridge_samples, tvec(y, z_nom + dz), pitch)
        gap = float(nose_surf.query(bs)[1].min())
        cost = gap + 0.25 * abs(dz)
        if best is None or cost < best[0] - 1e-9:
            best = (cost, dz, pitch, y, gap)
    _, dz, pitch, y, bridge_gap = best
    t = tvec(y, z_nom + dz)
    for _ in range(4):  # full-resolution guard: back off by any remaining shortfall
        short = MARGIN - hq.sd(place(front_pts, t, pitch))[0].min()
        if short <= 1e-6:
            break
        t = t - B[:, 1] * (short + 1e-5)
    Rw = B @ _rot_x(pitch)
    parts = {k: (place(v, t, pitch), f) for k, (v, f) in front.parts.items()}
    parts["lens"] = (place(front.lens_V, t, pitch), front.lens_F)
    hinges = place(front.hinges, t, pitch)
    anchors = place(front.pad_anchors, t, pitch)
    # nose pads on the nose surface, joined to the rims by pad arms
    pad_parts, arm_parts = [], []
    for i, side in enumerate((1.0, -1.0)):
        a = anchors[i]
        guess = a + Rw @ np.array([-side * 0.004, 0.003, -0.001])
        cp, n, _ = _closest_on_faces(hq.surf, guess[None], nose_idx)
        cp, n = cp[0], n[0]
        if n @ B[:, 1] > 0.3:  # folded / back-facing nose patch: face forward instead
            n = -B[:, 1]
        up = Rw[:, 2] - _dot(Rw[:, 2], n) * n
        up /= np.linalg.norm(up)
        ax = np.stack([up, np.cross(n, up), n])
        radii = np.array([0.0055, 0.0033, 0.0009])
        centre = cp + n * (radii[2] + MARGIN)
        pv, pf = ellipsoid(centre, ax, radii)
        for _ in range(6):  # the pad is rigid: move it as a whole until every point clears
            sd = hq.sd(pv)[0]
            if sd.min() >= MARGIN - 1e-6:
                break
            step = n * (MARGIN - sd.min() + 2e-5) if sd.min() > -0.0005 else -B[:, 1] * (MARGIN - sd.min() + 2e-5)
            pv, centre = pv + step, centre + step
        pad_parts.append((pv, pf))
        back = centre + n * radii[2]
        ctrl = np.array([a, a + 0.45 * (back - a) + Rw[:, 1] * -0.0012 + n * 0.0015, back])
        arm = _resample(_bezier(ctrl, 12), 10)
        arm_r = 0.0005 if spec.material == "metal" else 0.0011
        arm_parts.append(_clear_tube(hq, arm, arm_r, arm_r, 2.0, False, Rw[:, 2], fix_first=1, m=6))
    parts["pad"] = _merge(pad_parts)
    key = "metal" if spec.material == "metal" else "frame"
    parts[key] = _merge([parts[key], _merge(arm_parts)])
    # temples: hinge -> ear rest -> hook behind the ear, pushed out to clearance
    temple_parts, tip_parts, temple_len, spreads = [], [], [], []
    for i, side in enumerate((1.0, -1.0)):
        H, E = hinges[i], ears[i]
        L = float(np.linalg.norm(E - H))
        ctrl = np.array([H, H + Rw[:, 1] * L * 0.35, E - (E - H) / L * L * 0.3 + Rw[:, 2] * 0.001, E])
        path = _resample(_bezier(ctrl, 60), 40)
        hook = ear_hook_path(V, T, regions, side, ears_raw[i])
        hook = _resample(hook, max(6, int(np.linalg.norm(np.diff(hook, axis=0), axis=1).sum() / 0.002)))
        full = _resample(np.concatenate([path, hook[1:]]), 64)
        cum = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(full, axis=0), axis=1))])
        n_tip = int(np.searchsorted(cum, L * 0.97))
        clear = np.full(len(full), r_t + MARGIN)
        clear[n_tip:] = spec.tip_r + MARGIN
        for _ in range(4):
            full[2:] = hq.push_out(full[2:], clear[2:] + 0.00015, True)
            full = _smooth(full, 2, fix_first=2)
        full[2:] = hq.push_out(full[2:], clear[2:], True)
        spreads.append(math.degrees(math.atan2(side * _dot(full[8] - H, Rw[:, 0]), _dot(full[8] - H, Rw[:, 1]))))
        temple_len.append(float(np.linalg.norm(np.diff(full, axis=0), axis=1).sum()))
        th = spec.temple_r
        temple_parts.append(_clear_tube(hq, full[: n_tip + 1], th[0], th[1],
                                        2.0 if spec.material == "metal" else 4.0, True, Rw[:, 2], fix_first=1))
        tip_parts.append(_clear_tube(hq, full[max(0, n_tip - 1):], spec.tip_r, spec.tip_r, 2.0, True, Rw[:, 2],
                                     fix_first=0))
    parts["temple"] = _merge(temple_parts)
    parts["tip"] = _merge(tip_parts)
    m = measure(hq, parts, nose_surf, ears)
    info = {
        "style": spec.style, "spec": spec.record(),
        "pose": {"translation_m": [round(float(x), 6) for x in t], "pitch_deg": round(math.degrees(pitch), 3),
                 "yaw_deg": round(yaw, 3), "roll_deg": round(roll, 3), "height_offset_m": dz},
        "temple_length_m": [round(x, 5) for x in temple_len],
        "temple_spread_deg": [round(x, 3) for x in spreads],
        "bridge_gap_m": round(float(bridge_gap), 6),
        **{k: round(v, 6) for k, v in m.items()},
        "ear_rests": ears.round(6).tolist(),
    }
    return GlassesFit(parts=parts, info=info)


def _clear_tube(hq: "HeadQuery", centre, h1, h2, exponent, lateral: bool, up, fix_first: int = 1,
                m: int = 8, rounds: int = 12):
    """Sweep a tube and move its centre line until every tube vertex clears the head by MARGIN
    (measured on the tube's own vertices, the same way the checks measure it)."""
    C = np.array(centre, np.float64)
    for _ in range(rounds):
        V, F = tube_along(C, h1, h2, exponent, m, up=up)
        ring = V[: len(C) * m]
        sd, cp, dist, n, ins = hq.sd(ring, lateral)
        sd = sd.reshape(len(C), m)
        worst = np.argmin(sd, 1)
        need = MARGIN + 2e-5 - sd[np.arange(len(C)), worst]
        bad = need > 0
        bad[:fix_first] = False
        if not bad.any():
            break
        wi = np.arange(len(C)) * m + worst
        if lateral:
            side = np.where(C @ hq.B[:, 0] >= hq.mid, 1.0, -1.0)
            esc = np.where(ins.reshape(len(C), m)[np.arange(len(C)), worst][:, None], hq.B[:, 0] * side[:, None],
                           n[wi])
        else:
            esc = np.where(ins.reshape(len(C), m)[np.arange(len(C)), worst][:, None], -hq.B[:, 1], n[wi])
        wins = ins.reshape(len(C), m)[np.arange(len(C)), worst]
        fix = bad & wins
        if fix.any():  # inside: the exit along the parity ray, not the closest distance
            Q = ring[wi[fix]]
            if lateral:
                sd_side = np.where(Q @ hq.B[:, 0] >= hq.mid, 1.0, -1.0)
                t = hq.gx.hits(Q) * sd_side[:, None]
            else:
                t = -hq.gy.hits(Q)
            t = np.where(t > 0, t, np.nan)
            ex = np.nan_to_num(np.nanmax(t, 1), nan=0.0) if t.size else np.zeros(len(Q))
            need[fix] = ex + MARGIN + 2e-5
        C[bad] += esc[bad] * need[bad, None]
    return tube_along(C, h1, h2, exponent, m, up=up)


def lateral_mask(hq: HeadQuery, P, hinges_y: float):
    """Points behind the front (temples and tips): their inside test looks sideways."""
    return (np.asarray(P) @ hq.B[:, 1]) > hinges_y + 0.004


def measure(hq: HeadQuery, parts: dict, nose_surf: Surface, ears) -> dict:
    """Contact facts: smallest clearance (negative = penetration), nose gap, ear gaps."""
    front_keys = [k for k in parts if k not in ("temple", "tip")]
    Pf = np.concatenate([parts[k][0] for k in front_keys])
    Pt = np.concatenate([parts[k][0] for k in ("temple", "tip")])
    sdf = hq.sd(Pf, False)[0]
    sdt = hq.sd(Pt, True)[0]
    nose_gap = float(nose_surf.query(Pf)[1].min())
    ear_gap = []
    for e in ears:
        ear_gap.append(float(np.linalg.norm(Pt - e, axis=1).min()))
    return {"min_clearance_m": float(min(sdf.min(), sdt.min())), "front_min_clearance_m": float(sdf.min()),
            "temple_min_clearance_m": float(sdt.min()), "nose_gap_m": float(nose_gap),
            "ear_rest_offset_m": float(max(ear_gap))}


def _bezier(ctrl, n):
    t = np.linspace(0, 1, n)[:, None]
    P = np.asarray(ctrl, np.float64)
    while len(P) > 1:
        P = np.stack([(1 - t) * P[i] + t * P[i + 1] if P.ndim == 2 else (1 - t) * P[i] + t * P[i + 1]
                      for i in range(len(P) - 1)])
    return P[0]


def _settle(hq: "HeadQuery", p, clearance):
    """Drop a point onto the surface from above (Z), then push it out to the clearance."""
    p = np.asarray(p, np.float64)
    q = p + np.array([0.0, 0.0, clearance + 0.004])
    for _ in range(60):
        sd = hq.sd(q[None], True)[0][0]
        if sd < clearance + 1e-5:
            break
        q = q - np.array([0.0, 0.0, max(sd - clearance, 1e-5)])
    return hq.push_out(q[None], clearance, True)[0]


def _nose_faces(V, triangles, regions, lm, radius: float = 0.014):
    """Faces of the nose bridge: within ``radius`` of ibug 27-29 (and in the nose region if any)."""
    T = np.asarray(triangles, np.int64)
    cen = V[T].mean(1)
    d = np.min(np.linalg.norm(cen[:, None, :] - lm[None, 27:30], axis=-1), axis=1)
    sel = d < radius
    nr = _region(regions, "nose")
    eyes = _region(regions, "eyes")
    if eyes is not None:
        m = np.zeros(len(V), bool)
        m[eyes] = True
        sel &= ~m[T].any(1)
    return np.nonzero(sel)[0]


def _closest_on_faces(surf: Surface, P, faces):
    tri = surf.F[faces]
    q, bary = closest_on_triangles(P[:, None, :], surf.V[tri[:, 0]][None], surf.V[tri[:, 1]][None],
                                         surf.V[tri[:, 2]][None])
    d2 = ((q - P[:, None]) ** 2).sum(-1)
    b = np.argmin(d2, 1)
    r = np.arange(len(P))
    cp = q[r, b]
    n = surf.face_normals[faces[b]]
    # smooth normal: barycentric blend of vertex normals
    bc = bary[r, b]
    vn = surf.vertex_normals[tri[b]]
    ns = (bc[..., None] * vn).sum(1)
    ns /= np.linalg.norm(ns, axis=1, keepdims=True)
    return cp, ns, np.sqrt(d2[r, b])


def _gap_to_faces(surf: Surface, P, faces):
    """Smallest unsigned distance from points to a face subset (chunked)."""
    best = np.inf
    for i in range(0, len(P), 256):
        _, _, d = _closest_on_faces(surf, P[i:i + 256], faces)
        best = min(best, float(d.min()))
    return best
