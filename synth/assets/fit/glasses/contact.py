"""Where glasses touch the head: ear rests, the path behind the ear, the nose bridge, and the
head query (signed distance with the sign from parity rays) every contact test uses.
"""

from __future__ import annotations

import math

import numpy as np

from synth.geometry.closest import nearest_on_candidates
from synth.geometry.normals import normalize
from synth.geometry.raycast import RayGrid
from synth.geometry.sdf import SignedDistance

#: candidate triangles per closest-point query on the head (nearest centroids)
HEAD_CANDIDATES = 24


def head_surface(vertices, triangles) -> SignedDistance:
    """The head's signed distance as the glasses use it (pseudo-normal sign)."""
    return SignedDistance(vertices, triangles, sign="pseudo", k=HEAD_CANDIDATES)


def region_indices(data_regions, name):
    r = data_regions.get(name)
    return None if r is None else np.asarray(r, np.int64)


def ear_junction(V: np.ndarray, T: np.ndarray, regions, side: float) -> tuple[np.ndarray, np.ndarray]:
    """The vertices of one ear (``side`` +1: left, -1: right; the ``ear_l``/``ear_r`` region,
    else the ``ears`` region on that side) and those of them on its junction with the head
    (ear vertices sharing a triangle with non-ear vertices)."""
    idx = region_indices(regions, "ear_l" if side > 0 else "ear_r")
    if idx is None:
        allr = region_indices(regions, "ears")
        idx = allr[np.sign(V[allr, 0]) == side]
    ear = np.zeros(len(V), bool)
    ear[idx] = True
    mixed = ear[T].any(1) & ~ear[T].all(1)
    return idx, np.unique(T[mixed][ear[T[mixed]]])


def ear_rests(vertices, triangles, regions) -> np.ndarray:
    """(2, 3) top of the ear/head junction, left (+X) then right."""
    V = np.asarray(vertices, np.float64)
    T = np.asarray(triangles, np.int64)
    out = []
    for side in (1.0, -1.0):
        idx, jv = ear_junction(V, T, regions, side)
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
    idx, jv = ear_junction(V, T, regions, side)
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


def head_basis(ears, lm):
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

    def __init__(self, vertices, triangles, basis, midline_x: float, surface: SignedDistance | None = None):
        self.surf = surface or head_surface(vertices, triangles)
        self.B = basis
        self.mid = float(midline_x)
        self.gy = RayGrid(vertices, triangles, basis[:, 1])
        self.gx = RayGrid(vertices, triangles, basis[:, 0])

    def sd(self, P, lateral=None):
        P = np.asarray(P, np.float64).reshape(-1, 3)
        h = self.surf.query(P)
        cp, dist, sdn, n = h.point, h.distance, h.signed, h.normal
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


def settle(hq: "HeadQuery", p, clearance):
    """Drop a point onto the surface from above (Z), then push it out to the clearance."""
    p = np.asarray(p, np.float64)
    q = p + np.array([0.0, 0.0, clearance + 0.004])
    for _ in range(60):
        sd = hq.sd(q[None], True)[0][0]
        if sd < clearance + 1e-5:
            break
        q = q - np.array([0.0, 0.0, max(sd - clearance, 1e-5)])
    return hq.push_out(q[None], clearance, True)[0]


def nose_faces(V, triangles, regions, lm, radius: float = 0.014):
    """Faces of the nose bridge: within ``radius`` of ibug 27-29 (and in the nose region if any)."""
    T = np.asarray(triangles, np.int64)
    cen = V[T].mean(1)
    d = np.min(np.linalg.norm(cen[:, None, :] - lm[None, 27:30], axis=-1), axis=1)
    sel = d < radius
    nr = region_indices(regions, "nose")
    eyes = region_indices(regions, "eyes")
    if eyes is not None:
        m = np.zeros(len(V), bool)
        m[eyes] = True
        sel &= ~m[T].any(1)
    return np.nonzero(sel)[0]


def closest_on_faces(surf: SignedDistance, P, faces):
    """Closest points of ``P`` on the triangles ``faces`` of the head, the smooth normal there
    (barycentric blend of the angle-weighted vertex normals) and the distance."""
    faces = np.asarray(faces, np.int64)
    c = nearest_on_candidates(P, surf.V, surf.F, np.broadcast_to(faces, (len(P), len(faces))))
    ns = normalize((c.bary[..., None] * surf.vertex_normals[surf.F[c.face]]).sum(1))
    return c.point, ns, c.distance
