"""Head and face dimensions of a neutral head, and the adult ranges planned heads are kept in.

Four classical dimensions (Martin's landmarks, as measured with calipers on living adults),
read off the mesh in the head frame (docs/conventions.md: +X the subject's left, -Y the face's
direction, +Z up), each from a vertex set chosen once on the model's template:

=================  ==========================================================================
head breadth       eurion-eurion: the x extent of the cranium: head skin (not ears, neck or
                   shoulders) at or above the eyes' level (mean z of ibug68 36, 39, 42, 45)
head length        glabella-opisthocranion: the y extent of the midline strip (|x| <= 15 mm)
                   of that skin at or above the nasion (ibug68 27)
face height        sellion/nasion-menton: distance from ibug68 27 (the deepest point of the
                   nose bridge, i.e. sellion) to ibug68 8 (the chin point between gnathion and
                   menton), ANSUR II's menton-sellion length
face width         zygion-zygion (bizygomatic): the x extent of the ``face`` region (skin in
                   front of the ears) between the nose tip's level (ibug68 30) and the eyes'
=================  ==========================================================================

plus the cephalic index (100 breadth / length) and the facial index (100 face height / face
width). The sets are fixed per model (file data and exact comparisons: no choice depends on a
sampled code); an extent is a max minus a min over them, so every dimension is a continuous
function of the identity code.

:func:`measure_codes` evaluates only the coordinates these need, from the template and the
identity basis with :func:`synth.geometry.exact.lincomb`, so the figures, and the plan's accept /
redraw decisions that compare them with the ranges, are the same bits on every machine
(docs/determinism.md). :func:`measure` takes any vertices (e.g. :class:`synth.model.head.HeadModel`
output, or a test shape) and the same sets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.errors import SynthError
from synth.geometry import exact
from synth.model.format import HeadModelData
from synth.model.head import landmark_basis

#: the measured quantities, in the order of the tables (mm, mm, mm, mm, %, %)
NAMES = ("head_breadth_mm", "head_length_mm", "face_height_mm", "face_width_mm", "cephalic_index", "facial_index")

#: half-width of the midline strip whose y extent is the head length (m, on the template)
MIDLINE_HALF_WIDTH_M = 0.015
#: regions that are not the head proper
_NOT_HEAD = ("ears", "neck", "shoulders")
_NASION, _MENTON, _NOSE_TIP, _EYE_CORNERS = 27, 8, 30, (36, 39, 42, 45)


@dataclass(frozen=True)
class MeasureSets:
    """Vertex sets of a model (indices into its vertices) and the two landmarks of the face height,
    each a barycentric point (3 corner vertex indices, 3 weights)."""

    breadth: np.ndarray  # x extent -> head breadth
    length: np.ndarray  # y extent -> head length
    width: np.ndarray  # x extent -> face width
    nasion: tuple[np.ndarray, np.ndarray]
    menton: tuple[np.ndarray, np.ndarray]


def measure_sets(model: HeadModelData) -> MeasureSets:
    """The sets of ``model`` (see the module docstring), chosen on its template."""
    need = [r for r in ("skin", "face") if r not in model.regions]
    if need or "ibug68" not in model.landmarks or len(model.landmarks["ibug68"][0]) < 68:
        raise SynthError(f"the model has no {' or '.join(need) or 'ibug68'} "
                         f"{'region' if need else 'landmarks'}: head shapes cannot be measured", model.name,
                         "set identity.head_shape = 'auto' or 'none' for this model")
    t = model.template.astype(np.float64)
    lm, _ = landmark_basis(model)
    drop = np.concatenate([np.asarray(model.regions[r], np.int64) for r in _NOT_HEAD if r in model.regions]
                          or [np.zeros(0, np.int64)])
    head = np.setdiff1d(np.asarray(model.regions["skin"], np.int64), drop)
    face = np.asarray(model.regions["face"], np.int64)
    z_eyes = lm[list(_EYE_CORNERS), 2].mean()
    breadth = head[t[head, 2] >= z_eyes]
    length = head[(np.abs(t[head, 0]) <= MIDLINE_HALF_WIDTH_M) & (t[head, 2] >= lm[_NASION, 2])]
    width = face[(t[face, 2] <= z_eyes) & (t[face, 2] >= lm[_NOSE_TIP, 2])]
    tri, bary = model.landmarks["ibug68"]

    def point(k):
        return model.triangles[tri[k]].astype(np.int64), bary[k].astype(np.float64)

    sets = MeasureSets(np.sort(breadth), np.sort(length), np.sort(width), point(_NASION), point(_MENTON))
    if min(len(sets.breadth), len(sets.length), len(sets.width)) < 2:
        raise SynthError("the model's template leaves a head-shape vertex set (nearly) empty", model.name,
                         "set identity.head_shape = 'auto' or 'none' for this model")
    return sets


def _extent(c: np.ndarray) -> np.ndarray:
    return c.max(axis=-1) - c.min(axis=-1)


def _point(v: np.ndarray, p: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(..., 3) barycentric point, summed corner by corner in order."""
    corners, b = p
    return (v[..., corners[0], :] * b[0] + v[..., corners[1], :] * b[1]) + v[..., corners[2], :] * b[2]


def _finish(breadth, length, width, nasion, menton) -> dict[str, np.ndarray]:
    d = nasion - menton
    height = np.sqrt((d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2])
    mm = 1000.0
    return {"head_breadth_mm": breadth * mm, "head_length_mm": length * mm, "face_height_mm": height * mm,
            "face_width_mm": width * mm, "cephalic_index": 100.0 * breadth / length,
            "facial_index": 100.0 * height / width}


def measure(vertices, sets: MeasureSets) -> dict[str, np.ndarray]:
    """The :data:`NAMES` of vertices (V, 3) or (N, V, 3) in metres: arrays of shape () or (N,)."""
    v = np.asarray(vertices, np.float64)
    return _finish(_extent(v[..., sets.breadth, 0]), _extent(v[..., sets.length, 1]),
                   _extent(v[..., sets.width, 0]), _point(v, sets.nasion), _point(v, sets.menton))


def measure_codes(model: HeadModelData, codes, sets: MeasureSets | None = None) -> dict[str, np.ndarray]:
    """The :data:`NAMES` of the neutral, unposed heads of identity codes (N, Ki): (N,) arrays,
    machine independent (only the needed coordinates, each ``template + exact.lincomb(code, basis)``)."""
    sets = measure_sets(model) if sets is None else sets
    codes = np.atleast_2d(np.asarray(codes, np.float64))
    corners = np.concatenate([sets.nasion[0], sets.menton[0]])
    cols = [(sets.breadth, 0), (sets.length, 1), (sets.width, 0), (corners, 0), (corners, 1), (corners, 2)]
    vi = np.concatenate([v for v, _ in cols])
    ci = np.concatenate([np.full(len(v), c) for v, c in cols])
    scale = model.identity_scale.astype(np.float64)[:, None]
    rows = model.identity_basis[:, vi, ci].astype(np.float64) * scale  # (Ki, M)
    vals = model.template[vi, ci].astype(np.float64) + exact.lincomb(codes, rows)  # (N, M)
    parts = np.split(vals, np.cumsum([len(v) for v, _ in cols])[:-1], axis=1)
    c = np.stack(parts[3:], axis=-1)  # (N, 6 corners, 3)
    nas, men = (np.arange(3), sets.nasion[1]), (np.arange(3, 6), sets.menton[1])
    return _finish(_extent(parts[0]), _extent(parts[1]), _extent(parts[2]), _point(c, nas), _point(c, men))


def bounds_of(cfg) -> dict[str, tuple[float, float]]:
    """The ranges of an IdentityConfig, by :data:`NAMES`."""
    return {n: tuple(map(float, getattr(cfg, n))) for n in NAMES}


def inside(m: dict[str, np.ndarray], bounds: dict[str, tuple[float, float]]) -> np.ndarray:
    """(N,) bool: every measure within its closed range. The measures are exact (machine
    independent) and the comparison is exact, so a head on a bound is accepted everywhere."""
    ok = None
    for n, (lo, hi) in bounds.items():
        o = (m[n] >= lo) & (m[n] <= hi)
        ok = o if ok is None else ok & o
    return ok


def excess(m: dict[str, np.ndarray], bounds: dict[str, tuple[float, float]]) -> np.ndarray:
    """(N,) how far outside its ranges a head lies: the sum over measures of the distance to the
    range in units of the range's width (0 inside)."""
    out = 0.0
    for n, (lo, hi) in bounds.items():
        out = out + (np.maximum(lo - m[n], 0.0) + np.maximum(m[n] - hi, 0.0)) / max(hi - lo, 1e-12)
    return out


def unmet(model: HeadModelData, centre_code, bounds: dict[str, tuple[float, float]]) -> str | None:
    """Why no identity of ``model`` could be kept inside ``bounds``, or None: the model cannot be
    measured, or its head at ``centre_code`` (the prior's mean) lies outside a range."""
    try:
        m = measure_codes(model, np.asarray(centre_code, np.float64)[None])
    except SynthError as e:
        return e.what
    for n, (lo, hi) in bounds.items():
        if not lo <= m[n][0] <= hi:
            return f"the model's mean head has {n} {m[n][0]:.1f}, outside identity.{n} = [{lo:g}, {hi:g}]"
    return None
