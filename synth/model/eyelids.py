"""The eyelid rig: lids that close onto the eyeball and follow vertical gaze, per identity.

A linear model cannot close the lids of every identity with one blink blendshape (the opening
and the eyeball change with the identity), so the lids are moved by a small non-linear step
between shape blending and skinning (``synth.model.head.HeadModel`` and ``prior.fit.head``
call :func:`apply_eyelids` with their own array library). In the head frame, about each
eye's centre (its joint), a lid vertex has a lateral coordinate ``x``, a distance ``rho``
from the horizontal axis through the centre and an elevation ``alpha`` about that axis:

1. **Gaze follow.** Lid vertices turn about the axis by ``gain * pitch * w * taper``: ``pitch``
   the eye joint's gaze pitch, ``gain`` :data:`FOLLOW_UPPER` / :data:`FOLLOW_LOWER`, ``w`` the
   vertex's falloff from the lid margin, ``taper`` 0 at the canthi (held by the canthal
   tendons) and 1 mid-lid.
2. **Blink.** With ``b`` = eyeBlink clipped to [0, 1], an upper-lid vertex turns down by
   ``b * w * (alpha_upper(x) - alpha_lower(x))``: the upper margin's elevation minus the
   lower margin's at the vertex's ``x`` (both after step 1). At ``b`` = 1 the upper margin
   lands on the lower one whatever the identity, gaze or other expression.
3. **Resting on the eyeball.** Turning about an axis through the centre keeps distances to
   the centre; then every vertex near a margin moves radially, with falloff ``w_r``, by what
   its margin point needs to lie :data:`MARGIN_OFFSET_M` off the eyeball's surface (the
   identity's sclera sphere plus the corneal bulge about the gaze, pitched but not turned
   sideways: a lid that moved with the gaze yaw, which nothing else shows, would let landmark fits
   trade gaze for blink), and no rig vertex stays closer to that surface than :data:`MARGIN_OFFSET_M`.
   Toward the medial canthus (the lids' lacrimal part, within :data:`CANTHAL_HOLD_M`) a margin
   may stand off that surface by up to :data:`LACRIMAL_GAP_M` at the canthus, tapering to 0:
   the medial canthal tendon holds the canthus in front of the caruncle and the tear lake, off
   the globe, so the canthus stays where shape blending puts it (pushed out if it would lie
   inside the eyeball, pulled in only past the bound). Resting it on the sphere pulled it about
   1 mm toward the eye's centre, sideways and back (docs/realism.md, "The medial canthus held off
   the eyeball"). The move is a clamp of the margin's distance, so the step is idempotent: the
   template, rested once at build time, is what zero codes evaluate to.
   The pitched cornea bends the margins (and ibug 36-47 on them) non-linearly with the pitch
   and blink, which landmarks see only weakly: ``prior.fit.landmarks_fit`` gives the solver
   the exact curvature of that block (docs/fitting.md, "Optimisation").

The per-vertex data (which margin points a vertex refers to, weights) are fixed at build time
(:func:`build_eyelid_rig`, stored under ``extra["eyelids"]`` of the model file); models
without them (imported FLAME / ICT models) are evaluated without the step.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from synth.geometry import exact
from synth.model.meshutil import smoothstep

#: upper / lower lid rotation per unit of gaze pitch (see docs/default-model.md, "Eyelids")
FOLLOW_UPPER = 0.8
FOLLOW_LOWER = 0.3
#: falloff distances (metres, from the margin along the lid) of the lid motion and of the radial fit
FALLOFF_UPPER_M = 0.010
FALLOFF_LOWER_M = 0.007
FALLOFF_RADIAL_M = 0.003
#: a margin rests this far off the eyeball's surface (the tear film and lid margin thickness)
MARGIN_OFFSET_M = 1.0e-4
#: the lacrimal part: along the fissure this far (metres) from the medial canthus a margin may stand
#: off the eyeball, by up to LACRIMAL_GAP_M at the canthus (smoothstep taper to 0 at CANTHAL_HOLD_M).
#: On the default template the canthus stands 1.5 mm off (planned identities: median 1.6 mm,
#: at most 3 mm); a caruncle is a few millimetres across.
CANTHAL_HOLD_M = 0.004
LACRIMAL_GAP_M = 0.003

NUMPY_OPS = SimpleNamespace(atan2=np.arctan2, asin=np.arcsin, acos=np.arccos, sqrt=np.sqrt, sin=np.sin,
                            cos=np.cos, clip=np.clip, maximum=np.maximum, stack=np.stack, const=lambda a: a)


#: the same functions from :mod:`synth.geometry.exact`: the evaluated head's lids are the same bits
#: on every machine (numpy's SIMD transcendental loops are not)
EXACT_OPS = SimpleNamespace(atan2=exact.atan2, asin=exact.asin, acos=exact.acos, sqrt=np.sqrt, sin=exact.sin,
                            cos=exact.cos, clip=np.clip, maximum=np.maximum, stack=np.stack, const=lambda a: a)


def _cosine_falloff(d: np.ndarray, D: float) -> np.ndarray:
    return np.where(d < D, 0.5 * (1.0 + np.cos(np.pi * np.clip(d, 0.0, D) / D)), 0.0)


def _lerp_table(xs: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i0, i1, t) such that xs[i0] * (1 - t) + xs[i1] * t = x clipped to [xs[0], xs[-1]] (xs ascending)."""
    xc = np.clip(x, xs[0], xs[-1])
    i0 = np.clip(np.searchsorted(xs, xc, side="right") - 1, 0, len(xs) - 2)
    t = np.clip((xc - xs[i0]) / np.maximum(xs[i0 + 1] - xs[i0], 1e-12), 0.0, 1.0)
    return i0, i0 + 1, t


def _polar(P: np.ndarray):
    """(x, rho, alpha) of points relative to an eye centre (forward is -Y, up +Z)."""
    return P[..., 0], np.hypot(P[..., 1], P[..., 2]), np.arctan2(P[..., 2], -P[..., 1])


def build_eyelid_rig(template: np.ndarray, regions: dict, joint_rest: np.ndarray, joint_names: list[str],
                     expression_names: list[str], limbus_deg: float, cornea_bulge: float) -> dict:
    """The rig's per-vertex data (JSON-able) for ``extra["eyelids"]``, from the template.

    Rig vertices are the skin vertices (``skin`` region, not the hidden sockets) within the
    falloff distance of a lid margin (measured along the lid as ``rho * |alpha - alpha_margin(x)|``
    plus the lateral distance past a canthus)."""
    T = np.asarray(template, np.float64)
    skin = np.zeros(len(T), bool)
    skin[np.asarray(regions["skin"], np.int64)] = True
    skin[np.asarray(regions.get("eye_socket", []), np.int64)] = False
    eyes = []
    for side, blink in (("l", "eyeBlinkLeft"), ("r", "eyeBlinkRight")):
        c = np.asarray(joint_rest[joint_names.index(f"eye_{side}")], np.float64)
        up = np.asarray(regions[f"eyelid_{side}_upper"], np.int64)
        lo = np.asarray(regions[f"eyelid_{side}_lower"], np.int64)
        up, lo = up[np.argsort(T[up, 0])], lo[np.argsort(T[lo, 0])]
        x, rho, alpha = _polar(T - c)
        x0, x1 = x[up[0]], x[up[-1]]
        cand = np.nonzero(skin & (-(T[:, 1] - c[1]) > 0) & (x > x0 - FALLOFF_UPPER_M) & (x < x1 + FALLOFF_UPPER_M)
                          & (np.linalg.norm(T - c, axis=1) < rho[up].max() + FALLOFF_UPPER_M))[0]
        cand = np.union1d(cand, np.r_[up, lo])
        ui = _lerp_table(x[up], x[cand])
        li = _lerp_table(x[lo], x[cand])
        a_up = alpha[up][ui[0]] * (1 - ui[2]) + alpha[up][ui[1]] * ui[2]
        a_lo = alpha[lo][li[0]] * (1 - li[2]) + alpha[lo][li[1]] * li[2]
        past = np.maximum(np.maximum(x0 - x[cand], x[cand] - x1), 0.0)
        is_up = alpha[cand] >= 0.5 * (a_up + a_lo)
        is_up[np.isin(cand, up)] = True
        is_up[np.isin(cand, lo) & ~np.isin(cand, up)] = False
        d = np.hypot(rho[cand] * np.where(is_up, np.maximum(alpha[cand] - a_up, 0.0),
                                          np.maximum(a_lo - alpha[cand], 0.0)), past)
        w = np.where(is_up, _cosine_falloff(d, FALLOFF_UPPER_M), _cosine_falloff(d, FALLOFF_LOWER_M))
        keep = w > 0
        cand, w, is_up, d = cand[keep], w[keep], is_up[keep], d[keep]
        s = np.clip((x[cand] - x0) / (x1 - x0), 0.0, 1.0)
        taper = np.sin(np.pi * s) ** 0.5
        medial = np.clip(((x1 - x[cand]) if c[0] < 0 else (x[cand] - x0)) / CANTHAL_HOLD_M, 0.0, 1.0)
        lacrimal = LACRIMAL_GAP_M * (1.0 - smoothstep(medial))  # the nose side's end
        pos = {int(v): k for k, v in enumerate(cand)}
        ui = _lerp_table(x[up], x[cand])
        li = _lerp_table(x[lo], x[cand])
        sclera = np.asarray(regions[f"sclera_{side}"], np.int64)
        eyes.append({
            "joint": f"eye_{side}", "blink": blink if blink in expression_names else None,
            "vertices": cand.tolist(), "upper": is_up.tolist(),
            "weight": w.round(6).tolist(), "radial_weight": _cosine_falloff(d, FALLOFF_RADIAL_M).round(6).tolist(),
            "follow": (np.where(is_up, FOLLOW_UPPER, FOLLOW_LOWER) * w * taper).round(6).tolist(),
            "lacrimal_gap": lacrimal.round(7).tolist(),
            # rig-local indices of the margin points each vertex refers to, and the blend
            "upper_ref": np.c_[[pos[int(v)] for v in up[ui[0]]], [pos[int(v)] for v in up[ui[1]]]].tolist(),
            "upper_t": ui[2].round(6).tolist(),
            "lower_ref": np.c_[[pos[int(v)] for v in lo[li[0]]], [pos[int(v)] for v in lo[li[1]]]].tolist(),
            "lower_t": li[2].round(6).tolist(),
            "sclera_vertex": int(sclera[0]),
        })
    return {"version": 2, "limbus_rad": float(np.deg2rad(limbus_deg)), "cornea_bulge": float(cornea_bulge),
            "margin_offset_m": MARGIN_OFFSET_M, "eyes": eyes}


@dataclass
class EyeRig:
    joint: int
    blink: int  # expression index, -1 if none
    vertices: np.ndarray
    upper: np.ndarray  # (n,) bool
    weight: np.ndarray
    radial_weight: np.ndarray
    follow: np.ndarray
    upper_ref: np.ndarray  # (n, 2) rig-local
    upper_t: np.ndarray
    lower_ref: np.ndarray
    lower_t: np.ndarray
    sclera_vertex: int
    lacrimal_gap: np.ndarray  # (n,) metres a margin may stand off the eyeball (0 in version-1 rigs)


@dataclass
class EyelidRig:
    eyes: list[EyeRig]
    limbus_rad: float
    cornea_bulge: float
    offset: float

    @classmethod
    def from_data(cls, data) -> "EyelidRig | None":
        """The rig stored in a model (``None`` if it has none)."""
        e = (data.extra or {}).get("eyelids")
        if not e:
            return None
        names, jn = list(data.expression_names), list(data.joint_names)
        eyes = [EyeRig(jn.index(r["joint"]), names.index(r["blink"]) if r["blink"] in names else -1,
                       np.asarray(r["vertices"], np.int64), np.asarray(r["upper"], bool),
                       *(np.asarray(r[k], np.float64) for k in ("weight", "radial_weight", "follow")),
                       np.asarray(r["upper_ref"], np.int64), np.asarray(r["upper_t"], np.float64),
                       np.asarray(r["lower_ref"], np.int64), np.asarray(r["lower_t"], np.float64),
                       int(r["sclera_vertex"]),
                       np.asarray(r.get("lacrimal_gap", np.zeros(len(r["vertices"]))), np.float64)) for r in e["eyes"]]
        return cls(eyes, float(e["limbus_rad"]), float(e["cornea_bulge"]), float(e["margin_offset_m"]))

    def support(self) -> np.ndarray:
        """Every vertex the rig reads (its vertices and the sclera vertices that give the radius)."""
        return np.unique(np.concatenate([np.r_[e.vertices, e.sclera_vertex] for e in self.eyes]))


def _ref(a, idx, t):
    """Blend of rig-local values a[..., idx[:, 0]] and a[..., idx[:, 1]] by t."""
    return a[..., idx[:, 0]] * (1 - t) + a[..., idx[:, 1]] * t


def _surface_radius(rig: EyelidRig, dirs, fwd, R, ops):
    """Radius of the eyeball surface (sphere R plus the corneal bulge about ``fwd``) along unit ``dirs``."""
    cos_t = ops.clip((dirs * fwd[:, None, :]).sum(-1), -1.0, 1.0)
    q = ops.clip(1.0 - (ops.acos(cos_t) / rig.limbus_rad) ** 2, 0.0, 1.0)
    return R[:, None] * (1.0 + rig.cornea_bulge * q * q)


def apply_eyelids(rig: EyelidRig, shaped, joints, psi, eye_rot, ops=NUMPY_OPS):
    """Lid positions after the rig (module docstring). ``shaped`` (B, V, 3) blended vertices,
    ``joints`` (B, J, 3) rest joint positions, ``psi`` (B, Ke) expression codes, ``eye_rot``:
    joint index -> (B, 3, 3) local rotation of that eye joint. ``ops`` names the array functions
    (:data:`NUMPY_OPS`; torch's in ``prior.fit.head``). Returns {joint index: (vertex indices,
    (B, n, 3) new positions)}; ``shaped`` is not modified."""
    out = {}
    k = ops.const
    for e in rig.eyes:
        c = joints[:, e.joint][:, None, :]
        P = shaped[:, e.vertices] - c
        px, u, z = P[..., 0], -P[..., 1], P[..., 2]
        r = ops.sqrt(px * px + u * u + z * z)
        lat = ops.asin(ops.clip(px / r, -1.0, 1.0))  # angle off the vertical plane through the centre
        pitch = ops.asin(ops.clip(-eye_rot[e.joint][:, 2, 1], -1.0, 1.0))  # of the gaze, the turned -Y
        alpha = ops.atan2(z, u) + pitch[:, None] * k(e.follow)
        if e.blink >= 0:
            b = psi[:, e.blink][:, None] * k(e.weight * e.upper)
            alpha = alpha - b * (_ref(alpha, e.upper_ref, k(e.upper_t)) - _ref(alpha, e.lower_ref, k(e.lower_t)))
            lat = lat - b * (_ref(lat, e.upper_ref, k(e.upper_t)) - _ref(lat, e.lower_ref, k(e.lower_t)))
        cl = ops.cos(lat)
        dirs = ops.stack([ops.sin(lat), -cl * ops.cos(alpha), cl * ops.sin(alpha)], -1)
        radius = ops.sqrt(((shaped[:, e.sclera_vertex] - joints[:, e.joint]) ** 2).sum(-1))
        # the cornea about the gaze pitched but not turned sideways: lids that depended on the
        # gaze yaw (unseen otherwise) would let landmark fits (prior.fit) trade gaze for blink
        fwd = ops.stack([0.0 * pitch, -ops.cos(pitch), ops.sin(pitch)], -1)
        floor = _surface_radius(rig, dirs, fwd, radius, ops) + rig.offset
        up = k(e.upper.astype(np.float64))
        # a margin point's move: onto the surface, or in the lacrimal part into [floor, floor + gap]
        to = floor - r
        to = ops.maximum(to, -ops.clip(-(to + k(e.lacrimal_gap)), 0.0, None))
        need = up * _ref(to, e.upper_ref, k(e.upper_t)) + (1 - up) * _ref(to, e.lower_ref, k(e.lower_t))
        r2 = ops.maximum(r + k(e.radial_weight) * need, floor)
        out[e.joint] = (e.vertices, c + dirs * r2[..., None])
    return out


def rest_lids(rig_json: dict, template: np.ndarray, joint_rest: np.ndarray, joint_names: list[str],
              expression_names: list[str]) -> np.ndarray:
    """The template with its lids resting on the eyeballs (the rig at zero codes), so that the
    template stays what zero codes evaluate to."""
    from types import SimpleNamespace as NS

    data = NS(extra={"eyelids": rig_json}, expression_names=expression_names, joint_names=joint_names)
    rig = EyelidRig.from_data(data)
    shaped = np.asarray(template, np.float64)[None].copy()
    eye_rot = {e.joint: np.eye(3)[None] for e in rig.eyes}
    for idx, p in apply_eyelids(rig, shaped, np.asarray(joint_rest, np.float64)[None],
                                np.zeros((1, len(expression_names))), eye_rot).values():
        shaped[:, idx] = p
    return shaped[0]
