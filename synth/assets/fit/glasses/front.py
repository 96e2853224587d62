"""The front of the glasses in frame space: lenses, rims, end pieces, hinges, bridge(s).

Frame space has the world's axes (X left, Y back toward the head, Z up), the origin at the
middle of the bridge at lens-centre height and the lens fronts near y = 0. Lenses carry a
spherical front curve (base ~6) and a few degrees of face-form wrap; rims are tubes swept
around the outline (boxy section for acetate, round for metal); half-rim = upper part only,
browline = thick upper bar + thin metal loop, rimless = none.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from synth.assets.fit.glasses.shapes import merge_meshes, outline_2d, outward_normals_2d, sweep, tube_along
from synth.assets.fit.glasses.spec import FrameSpec


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
    nrm2 = outward_normals_2d(o2)
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

        # lens: front cap from concentric rings, back cap, edge wall; a closed solid wound
        # outward (Cycles takes the geometric normal's side for entering vs leaving the glass:
        # caps wound inward refract as if leaving it, with total reflection beyond ~42 degrees)
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
        lens_parts.append((np.concatenate([fv, bv]), np.concatenate([F, (F + nv)[:, ::-1], wall])))
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
    parts = {"frame": merge_meshes(frame_parts), "metal": merge_meshes(metal_parts)}
    lV, lF = merge_meshes(lens_parts)
    return Front(parts=parts, lens_V=lV, lens_F=lF, hinges=np.asarray(hinges), pad_anchors=np.asarray(anchors),
                 lens_centres=np.asarray(centres), bridge_samples=np.concatenate(bridge_pts))
