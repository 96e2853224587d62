"""The pose solve of the glasses on a head (:func:`fit_glasses`) and its contact measures.

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
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from synth.assets.fit.glasses.contact import (HeadQuery, closest_on_faces, ear_hook_path, ear_rests, head_basis,
                                              nose_faces, region_indices, settle)
from synth.assets.fit.glasses.front import Front, build_front
from synth.assets.fit.glasses.shapes import (bezier, ellipsoid, merge_meshes, resample_polyline, rot_x,
                                             smooth_polyline, tube_along)
from synth.assets.fit.glasses.spec import FrameSpec
from synth.geometry.normals import dot
from synth.geometry.sdf import SignedDistance

MARGIN = 0.0002  # clearance left between any frame part and the skin (m)
#: the parts of the frame (one material each; the lenses are the "lens" part), in slot order
FRAME_PARTS = ("frame", "metal", "temple", "tip", "pad")


@dataclasses.dataclass
class GlassesFit:
    parts: dict  # material key -> (V (n,3) world, F (m,3))
    info: dict


def fit_glasses(vertices, triangles, regions, landmarks: dict, spec: FrameSpec, surface: SignedDistance | None = None,
                front: Front | None = None) -> GlassesFit:
    """Pose the frame on a head: see the module docstring. Deterministic."""
    V = np.asarray(vertices, np.float64)
    T = np.asarray(triangles, np.int64)
    front = front or build_front(spec)
    lm = np.asarray(landmarks["ibug68"], np.float64)
    ears_raw = ear_rests(V, T, regions)
    B = head_basis(ears_raw, lm)
    nose = lm[27:31]
    mid = nose.mean(0)
    hq = HeadQuery(V, T, B, float(mid @ B[:, 0]), surface)
    r_t = max(spec.temple_r)
    ears = np.stack([settle(hq, e, r_t + MARGIN) for e in ears_raw])
    yaw = math.degrees(math.atan2(B[1, 0], B[0, 0]))
    roll = math.degrees(math.atan2(B[2, 0], math.hypot(B[0, 0], B[1, 0])))
    pup = []
    for nm, sl in (("pupil_l", slice(42, 48)), ("pupil_r", slice(36, 42))):
        r = region_indices(regions, nm)
        pup.append(V[r].mean(0) if r is not None else lm[sl].mean(0))
    pup = np.asarray(pup)
    front_pts = np.concatenate([front.parts["frame"][0], front.parts["metal"][0], front.lens_V])
    coarse = front_pts[:: max(1, len(front_pts) // 2500)]

    def place(pts, t, pitch):
        return (pts @ (B @ rot_x(pitch)).T) + t

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
    nose_idx = nose_faces(V, T, regions, lm)
    nose_surf = SignedDistance(V, T[nose_idx], k=8)
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
        gap = float(nose_surf.query(bs).distance.min())
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
    Rw = B @ rot_x(pitch)
    parts = {k: (place(v, t, pitch), f) for k, (v, f) in front.parts.items()}
    parts["lens"] = (place(front.lens_V, t, pitch), front.lens_F)
    hinges = place(front.hinges, t, pitch)
    anchors = place(front.pad_anchors, t, pitch)
    # nose pads on the nose surface, joined to the rims by pad arms
    pad_parts, arm_parts = [], []
    for i, side in enumerate((1.0, -1.0)):
        a = anchors[i]
        guess = a + Rw @ np.array([-side * 0.004, 0.003, -0.001])
        cp, n, _ = closest_on_faces(hq.surf, guess[None], nose_idx)
        cp, n = cp[0], n[0]
        if n @ B[:, 1] > 0.3:  # folded / back-facing nose patch: face forward instead
            n = -B[:, 1]
        up = Rw[:, 2] - dot(Rw[:, 2], n) * n
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
        arm = resample_polyline(bezier(ctrl, 12), 10)
        arm_r = 0.0005 if spec.material == "metal" else 0.0011
        arm_parts.append(_clear_tube(hq, arm, arm_r, arm_r, 2.0, False, Rw[:, 2], fix_first=1, m=6))
    parts["pad"] = merge_meshes(pad_parts)
    key = "metal" if spec.material == "metal" else "frame"
    parts[key] = merge_meshes([parts[key], merge_meshes(arm_parts)])
    # temples: hinge -> ear rest -> hook behind the ear, pushed out to clearance
    temple_parts, tip_parts, temple_len, spreads = [], [], [], []
    for i, side in enumerate((1.0, -1.0)):
        H, E = hinges[i], ears[i]
        L = float(np.linalg.norm(E - H))
        ctrl = np.array([H, H + Rw[:, 1] * L * 0.35, E - (E - H) / L * L * 0.3 + Rw[:, 2] * 0.001, E])
        path = resample_polyline(bezier(ctrl, 60), 40)
        hook = ear_hook_path(V, T, regions, side, ears_raw[i])
        hook = resample_polyline(hook, max(6, int(np.linalg.norm(np.diff(hook, axis=0), axis=1).sum() / 0.002)))
        full = resample_polyline(np.concatenate([path, hook[1:]]), 64)
        cum = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(full, axis=0), axis=1))])
        n_tip = int(np.searchsorted(cum, L * 0.97))
        clear = np.full(len(full), r_t + MARGIN)
        clear[n_tip:] = spec.tip_r + MARGIN
        for _ in range(4):
            full[2:] = hq.push_out(full[2:], clear[2:] + 0.00015, True)
            full = smooth_polyline(full, 2, fix_first=2)
        full[2:] = hq.push_out(full[2:], clear[2:], True)
        spreads.append(math.degrees(math.atan2(side * dot(full[8] - H, Rw[:, 0]), dot(full[8] - H, Rw[:, 1]))))
        temple_len.append(float(np.linalg.norm(np.diff(full, axis=0), axis=1).sum()))
        th = spec.temple_r
        temple_parts.append(_clear_tube(hq, full[: n_tip + 1], th[0], th[1],
                                        2.0 if spec.material == "metal" else 4.0, True, Rw[:, 2], fix_first=1))
        tip_parts.append(_clear_tube(hq, full[max(0, n_tip - 1):], spec.tip_r, spec.tip_r, 2.0, True, Rw[:, 2],
                                     fix_first=0))
    parts["temple"] = merge_meshes(temple_parts)
    parts["tip"] = merge_meshes(tip_parts)
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


def measure(hq: HeadQuery, parts: dict, nose_surf: SignedDistance, ears) -> dict:
    """Contact facts: smallest clearance (negative = penetration), nose gap, ear gaps."""
    front_keys = [k for k in parts if k not in ("temple", "tip")]
    Pf = np.concatenate([parts[k][0] for k in front_keys])
    Pt = np.concatenate([parts[k][0] for k in ("temple", "tip")])
    sdf = hq.sd(Pf, False)[0]
    sdt = hq.sd(Pt, True)[0]
    nose_gap = float(nose_surf.query(Pf).distance.min())
    ear_gap = []
    for e in ears:
        ear_gap.append(float(np.linalg.norm(Pt - e, axis=1).min()))
    return {"min_clearance_m": float(min(sdf.min(), sdt.min())), "front_min_clearance_m": float(sdf.min()),
            "temple_min_clearance_m": float(sdt.min()), "nose_gap_m": float(nose_gap),
            "ear_rest_offset_m": float(max(ear_gap))}
