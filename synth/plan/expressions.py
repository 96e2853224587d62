"""Expressions: a mixture of neutral, named presets and random sparse combinations of the
model's expression components, plus jaw and eye rotations within anatomical limits.

Presets are written with ARKit blendshape names (the embedded default and ICT-FaceKit
models use them). They are resolved against the model's ``expression_names``; names the
model lacks are skipped, and a preset none of whose parts exist is unavailable. The
special part ``_jaw`` (0..1) is a jaw opening realised as ``jawOpen`` or as a jaw-joint
rotation (``expression.jaw_via``).

Every number of expression (i, e) comes from ``seeds.uniforms(seed, EXPRESSION, i, e)``;
the uniforms are laid out in fixed slots (see ``_SLOTS``), vectorised over expressions.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass

import numpy as np

from synth import seeds
from synth.conventions import gaze_axis_angle, jaw_axis_angle
from synth.geometry import exact

_L, _R = "Left", "Right"


def _sym(**parts: float) -> dict[str, float]:
    """Expand 'X_' keys to XLeft and XRight."""
    out: dict[str, float] = {}
    for k, v in parts.items():
        if k.endswith("_") and k != "_jaw":
            out[k[:-1] + _L] = v
            out[k[:-1] + _R] = v
        else:
            out[k] = v
    return out


#: Named presets (ARKit names, weights before the intensity scale). Left = the subject's left.
PRESETS: dict[str, dict[str, float]] = {
    "smile": _sym(mouthSmile_=0.8, cheekSquint_=0.35),
    "smile_open": _sym(mouthSmile_=0.9, cheekSquint_=0.4, mouthUpperUp_=0.3, _jaw=0.35),
    "jaw_open": {"_jaw": 1.0},
    "surprise": _sym(browInnerUp=0.8, browOuterUp_=0.8, eyeWide_=0.7, _jaw=0.45),
    "brows_raised": _sym(browInnerUp=0.9, browOuterUp_=0.9),
    "frown": _sym(browDown_=0.8, mouthFrown_=0.7),
    "sad": _sym(browInnerUp=0.7, mouthFrown_=0.6, mouthShrugLower=0.3),
    "angry": _sym(browDown_=0.9, eyeSquint_=0.5, noseSneer_=0.4, mouthPress_=0.5),
    "disgust": _sym(noseSneer_=0.8, mouthUpperUp_=0.6, browDown_=0.3),
    "pucker": {"mouthPucker": 1.0},
    "funnel": {"mouthFunnel": 0.9, "_jaw": 0.15},
    "blink": _sym(eyeBlink_=1.0),
    "squint": _sym(eyeSquint_=0.8, cheekSquint_=0.5),
    "cheek_puff": {"cheekPuff": 1.0, "mouthClose": 0.2},
    "lips_pressed": _sym(mouthPress_=0.8, mouthRollLower=0.4, mouthRollUpper=0.4),
    "grimace": _sym(mouthStretch_=0.8, mouthUpperUp_=0.5, mouthLowerDown_=0.5),
    "scream": _sym(browInnerUp=0.6, browOuterUp_=0.5, eyeWide_=0.6, mouthStretch_=0.5, _jaw=0.9),
    "jaw_forward": {"jawForward": 0.8},
    # asymmetric
    "sneer_left": {"noseSneerLeft": 0.9, "mouthUpperUpLeft": 0.5},
    "sneer_right": {"noseSneerRight": 0.9, "mouthUpperUpRight": 0.5},
    "wink_left": {"eyeBlinkLeft": 1.0, "cheekSquintLeft": 0.4, "mouthSmileLeft": 0.3},
    "wink_right": {"eyeBlinkRight": 1.0, "cheekSquintRight": 0.4, "mouthSmileRight": 0.3},
    "smirk_left": {"mouthSmileLeft": 0.8, "mouthDimpleLeft": 0.4},
    "smirk_right": {"mouthSmileRight": 0.8, "mouthDimpleRight": 0.4},
    "brow_raise_left": {"browOuterUpLeft": 0.9, "browInnerUp": 0.3},
    "brow_raise_right": {"browOuterUpRight": 0.9, "browInnerUp": 0.3},
    "mouth_left": {"mouthLeft": 0.8},
    "mouth_right": {"mouthRight": 0.8},
    "jaw_left": {"jawLeft": 0.8},
    "jaw_right": {"jawRight": 0.8},
}

#: Pairs that should not both be active in a random combination (the weaker one is dropped).
CONFLICTS: tuple[tuple[str, str], ...] = tuple(
    (a + s, b + s) for s in (_L, _R) for a, b in (
        ("mouthSmile", "mouthFrown"), ("browDown", "browOuterUp"), ("eyeBlink", "eyeWide"),
        ("eyeSquint", "eyeWide"), ("mouthPress", "mouthStretch"), ("mouthDimple", "mouthFrown"))
) + (("mouthLeft", "mouthRight"), ("jawLeft", "jawRight"), ("mouthPucker", "mouthSmileLeft"),
     ("mouthPucker", "mouthSmileRight"), ("mouthFunnel", "mouthPucker"), ("cheekPuff", "mouthFunnel"),
     ("browDownLeft", "browInnerUp"), ("browDownRight", "browInnerUp"), ("mouthClose", "jawOpen"))

KINDS = ("neutral", "preset", "random")

# uniform slots per expression (then 2 * Ke for the random ranking and amplitudes)
_SLOTS = ("kind", "preset", "intensity", "n_active", "symmetric", "jaw_p", "jaw", "jaw_lateral",
          "gaze_yaw", "gaze_pitch", "vergence", "spare")


@dataclass
class ExpressionModel:
    """The presets and rules resolved against one model's expression names."""

    names: list[str]
    preset_names: list[str]  # available presets, in PRESETS order
    preset_matrix: np.ndarray  # (n_presets, Ke)
    preset_jaw: np.ndarray  # (n_presets,) jaw opening 0..1
    skipped_presets: list[str]
    eligible: np.ndarray  # (Ke,) bool: may appear in random combinations
    mirror: np.ndarray  # (Ke,) index of the left/right partner, or -1
    conflicts: list[tuple[int, int]]
    jaw_index: int  # index of jawOpen used for jaw openings, or -1 (joint)


def resolve(names: list[str], cfg) -> ExpressionModel:
    """Resolve presets, exclusions, mirror pairs and conflicts for a model (``cfg``: ExpressionConfig)."""
    idx = {n: i for i, n in enumerate(names)}
    Ke = len(names)
    jaw_index = idx.get("jawOpen", -1) if cfg.jaw_via in ("auto", "blendshape") else -1
    wanted = list(cfg.presets) or list(PRESETS)
    rows, jaws, keep, skipped = [], [], [], []
    for name in PRESETS:
        if name not in wanted:
            continue
        parts = PRESETS[name]
        row = np.zeros(Ke)
        hit = False
        for k, v in parts.items():
            if k in idx:
                row[idx[k]] = v
                hit = True
        jaw = parts.get("_jaw", 0.0)
        if jaw and cfg.jaw_via == "blendshape" and jaw_index < 0:
            jaw = 0.0
        if jaw and jaw_index >= 0:
            row[jaw_index] = max(row[jaw_index], jaw)
            hit = True
            jaw = 0.0  # carried by the blendshape
        if hit or jaw > 0:
            rows.append(row)
            jaws.append(jaw)
            keep.append(name)
        else:
            skipped.append(name)
    eligible = np.array([not any(fnmatch.fnmatchcase(n, pat) for pat in cfg.exclude) for n in names], bool)
    if cfg.jaw_via == "joint" and "jawOpen" in idx:
        eligible[idx["jawOpen"]] = False  # the joint opens the jaw; the blendshape would open it twice
    mirror = np.full(Ke, -1, np.int64)
    for n, i in idx.items():
        for a, b in ((_L, _R), (_R, _L)):
            if n.endswith(a) and n[: -len(a)] + b in idx:
                mirror[i] = idx[n[: -len(a)] + b]
    conflicts = [(idx[a], idx[b]) for a, b in CONFLICTS if a in idx and b in idx]
    return ExpressionModel(list(names), keep, np.array(rows).reshape(len(rows), Ke),
                           np.array(jaws, np.float64), skipped, eligible, mirror, conflicts, jaw_index)


@dataclass
class Expressions:
    codes: np.ndarray  # (P, Ke) expression coefficients
    kind: np.ndarray  # (P,) index into KINDS
    preset: np.ndarray  # (P,) index into ExpressionModel.preset_names, -1 if none
    jaw_open_deg: np.ndarray  # (P,) jaw-joint opening
    jaw_lateral_deg: np.ndarray
    gaze_yaw_deg: np.ndarray
    gaze_pitch_deg: np.ndarray
    vergence_deg: np.ndarray

    def joint_rotations(self) -> dict[str, np.ndarray]:
        """Axis-angle (P, 3) per joint: jaw, eye_l (at +X), eye_r; vergence turns each eye inward."""
        return {
            "jaw": jaw_axis_angle(self.jaw_open_deg, self.jaw_lateral_deg),
            "eye_l": gaze_axis_angle(self.gaze_yaw_deg - self.vergence_deg, self.gaze_pitch_deg),
            "eye_r": gaze_axis_angle(self.gaze_yaw_deg + self.vergence_deg, self.gaze_pitch_deg),
        }


def _lerp(u: np.ndarray, rng: tuple[float, float]) -> np.ndarray:
    return rng[0] + u * (rng[1] - rng[0])


def _gaze(u: np.ndarray, limits: tuple[float, float], sd: float, distribution: str) -> np.ndarray:
    """Gaze angles (degrees) from uniforms ``u`` in (0, 1): uniform over ``limits``, or a normal centred on
    the primary position (0) with standard deviation ``sd`` truncated to ``limits`` (inverse CDF, so each
    angle depends on its own uniform only; the limits need not contain 0)."""
    lo, hi = float(limits[0]), float(limits[1])
    if distribution == "uniform" or hi <= lo:
        return _lerp(u, (lo, hi))
    return np.clip(truncated_normal_ppf(u, lo / sd, hi / sd) * sd, lo, hi)


def truncated_normal_ppf(u: np.ndarray, a: float, b: float) -> np.ndarray:
    """Inverse CDF of the standard normal truncated to [a, b], at ``u`` in [0, 1]: computed with
    :func:`synth.geometry.exact.truncated_normal_ppf`, so the gaze angles are the same bits on every
    machine (scipy's values come from the C library's exp/log, which differ with the CPU's FMA
    support and with the scipy version). Within 2e-14 of ``scipy.stats.truncnorm.ppf``
    (tests/plan/test_truncated_normal.py)."""
    return exact.truncated_normal_ppf(u, a, b)


def sample_expressions(seed: int, identity: np.ndarray, expression: np.ndarray, em: ExpressionModel,
                       cfg) -> Expressions:
    """Expressions for (identity[p], expression[p]); ``cfg`` is an ExpressionConfig."""
    identity = np.asarray(identity, np.int64).reshape(-1)
    expression = np.asarray(expression, np.int64).reshape(-1)
    P, Ke = identity.size, len(em.names)
    u = seeds.uniforms(seed, seeds.Stream.EXPRESSION, identity, expression, None, n=len(_SLOTS) + 2 * Ke)
    s = {name: u[:, i] for i, name in enumerate(_SLOTS)}
    rank_u, amp_u = u[:, len(_SLOTS):len(_SLOTS) + Ke], u[:, len(_SLOTS) + Ke:]

    n_elig = int(em.eligible.sum())
    w = np.array([cfg.neutral_weight, cfg.preset_weight if em.preset_names else 0.0,
                  cfg.random_weight if n_elig else 0.0])
    if w.sum() <= 0:
        w = np.array([1.0, 0.0, 0.0])
    kind = np.searchsorted(np.cumsum(w) / w.sum(), s["kind"], side="right").clip(0, 2)

    codes = np.zeros((P, Ke))
    jaw = np.zeros(P)  # jaw opening 0..1 realised by the joint
    preset = np.full(P, -1, np.int64)
    # presets
    isp = kind == 1
    if isp.any():
        n = len(em.preset_names)
        pi = np.minimum((s["preset"][isp] * n).astype(np.int64), n - 1)
        inten = _lerp(s["intensity"][isp], cfg.preset_intensity)
        preset[isp] = pi
        codes[isp] = em.preset_matrix[pi] * inten[:, None]
        jaw[isp] = em.preset_jaw[pi] * inten
    # random sparse combinations
    isr = kind == 2
    if isr.any():
        opens = s["jaw_p"][isr] < cfg.random_jaw_probability
        amount = np.where(opens, s["jaw"][isr], 0.0)
        r = _random_codes(rank_u[isr], amp_u[isr], s["n_active"][isr], s["symmetric"][isr],
                          amount if em.jaw_index >= 0 else None, em, cfg)
        if em.jaw_index < 0:
            jaw[isr] = amount
        codes[isr] = r
    codes = np.clip(codes, cfg.code_range[0], cfg.code_range[1])
    lo, hi = cfg.jaw_open_deg
    jaw_deg = np.clip(jaw * hi, lo, hi) * (jaw > 0)
    jaw_lat = np.where(jaw > 0, _lerp(s["jaw_lateral"], cfg.jaw_lateral_deg) * jaw, 0.0)
    return Expressions(codes=codes, kind=kind, preset=preset, jaw_open_deg=jaw_deg, jaw_lateral_deg=jaw_lat,
                       gaze_yaw_deg=_gaze(s["gaze_yaw"], cfg.gaze_yaw_deg, cfg.gaze_sd_deg[0], cfg.gaze_distribution),
                       gaze_pitch_deg=_gaze(s["gaze_pitch"], cfg.gaze_pitch_deg, cfg.gaze_sd_deg[1],
                                            cfg.gaze_distribution),
                       vergence_deg=_lerp(s["vergence"], cfg.vergence_deg))


def _random_codes(rank_u, amp_u, n_u, sym_u, jaw, em: ExpressionModel, cfg) -> np.ndarray:
    """Sparse random combinations with plausibility bounds (vectorised over rows); ``jaw``
    (rows,) is a jaw opening carried by jawOpen, or None."""
    R, Ke = rank_u.shape
    elig = em.eligible
    n_elig = int(elig.sum())
    k_lo = min(cfg.random_active[0], n_elig)
    k_hi = min(cfg.random_active[1], n_elig)
    k = k_lo + np.minimum((n_u * (k_hi - k_lo + 1)).astype(np.int64), k_hi - k_lo)
    ranks = np.where(elig[None], rank_u, 2.0).argsort(axis=1).argsort(axis=1)  # random order of eligible
    active = ranks < k[:, None]
    codes = np.where(active, _lerp(amp_u, cfg.random_amplitude), 0.0)
    # mirror left/right partners in symmetric combinations (real expressions mostly are)
    sym = sym_u < cfg.random_symmetry
    has = em.mirror >= 0
    if has.any() and sym.any():
        src = codes[sym]
        mirrored = np.zeros_like(src)
        mirrored[:, has] = src[:, em.mirror[has]]
        codes[sym] = np.maximum(src, np.where(elig[None], mirrored, 0.0))
    if jaw is not None:
        codes[:, em.jaw_index] = np.maximum(codes[:, em.jaw_index], jaw)
    for a, b in em.conflicts:  # drop the weaker of two antagonists
        both = (codes[:, a] > 0) & (codes[:, b] > 0)
        weaker_a = both & (codes[:, a] < codes[:, b])
        codes[weaker_a, a] = 0.0
        codes[both & ~weaker_a, b] = 0.0
    total = codes.sum(axis=1)
    scale = np.where(total > cfg.max_total_activation, cfg.max_total_activation / np.maximum(total, 1e-12), 1.0)
    return codes * scale[:, None]
