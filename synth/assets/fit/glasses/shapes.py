"""Mesh building blocks and polylines for the glasses (frame space or world, metres).

Lens outlines (superellipses with per-style edits), swept tubes of superellipse section with
rotation-minimising frames, ellipsoids (nose pads), mesh merging, Bezier curves, arc-length
resampling and smoothing of polylines, a rotation about X.
"""

from __future__ import annotations

import math

import numpy as np

from synth.assets.fit.glasses.spec import FrameSpec
from synth.geometry.normals import dot


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


def outward_normals_2d(pts):
    tang = np.roll(pts, -1, 0) - np.roll(pts, 1, 0)
    nrm = np.stack([tang[:, 1], -tang[:, 0]], 1)  # ccw outline -> right-hand normal points outward
    return nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)


def _rmf(curve: np.ndarray, up=(0.0, 0.0, 1.0)):
    """Rotation-minimising frames (double reflection) along an open polyline: (T, N, B)."""
    P = np.asarray(curve, np.float64)
    T = np.gradient(P, axis=0)
    T /= np.maximum(np.linalg.norm(T, axis=1, keepdims=True), 1e-12)
    up = np.asarray(up, np.float64)
    n0 = up - dot(up, T[0]) * T[0]
    if np.linalg.norm(n0) < 1e-6:
        n0 = np.cross(T[0], [1.0, 0.0, 0.0])
    N = np.zeros_like(P)
    N[0] = n0 / np.linalg.norm(n0)
    for i in range(len(P) - 1):
        v1 = P[i + 1] - P[i]
        c1 = dot(v1, v1)
        if c1 < 1e-20:
            N[i + 1] = N[i]
            continue
        rL = N[i] - (2 / c1) * dot(v1, N[i]) * v1
        tL = T[i] - (2 / c1) * dot(v1, T[i]) * v1
        v2 = T[i + 1] - tL
        c2 = dot(v2, v2)
        N[i + 1] = rL - (2 / c2) * dot(v2, rL) * v2 if c2 > 1e-20 else rL
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


def merge_meshes(parts):
    Vs, Fs, off = [], [], 0
    for V, F in parts:
        Vs.append(V)
        Fs.append(F + off)
        off += len(V)
    if not Vs:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return np.concatenate(Vs), np.concatenate(Fs)


def bezier(ctrl, n):
    t = np.linspace(0, 1, n)[:, None]
    P = np.asarray(ctrl, np.float64)
    while len(P) > 1:
        P = np.stack([(1 - t) * P[i] + t * P[i + 1] if P.ndim == 2 else (1 - t) * P[i] + t * P[i + 1]
                      for i in range(len(P) - 1)])
    return P[0]


def resample_polyline(P, n):
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    t = np.linspace(0, s[-1], n)
    return np.stack([np.interp(t, s, P[:, i]) for i in range(3)], 1)


def smooth_polyline(P, it=3, fix_first=2, fix_last=0):
    P = P.copy()
    for _ in range(it):
        Q = P.copy()
        Q[1:-1] = 0.25 * P[:-2] + 0.5 * P[1:-1] + 0.25 * P[2:]
        Q[:fix_first] = P[:fix_first]
        if fix_last:
            Q[-fix_last:] = P[-fix_last:]
        P = Q
    return P


def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
