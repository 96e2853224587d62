"""The synth head-model file format (``.npz``, no pickle): dataclass, reader, writer, schema check.

The format is documented in ``docs/model-format.md``. A file is an uncompressed or
compressed NumPy ``.npz`` archive whose members are plain numeric arrays, plus one
member ``meta`` holding UTF-8 JSON bytes (as a uint8 array). It is always loaded with
``allow_pickle=False``.

Conventions (shared by every model): metres; Blender world axes, Z up, the face looks
toward -Y, +X is the subject's left. Codes are dimensionless: identity code ``beta``
is about N(0, 1) per component (the basis is scaled by ``identity_scale``), expression
code ``psi`` is in the units of the source rig (ARKit-style weights in [0, 1] for the
embedded default).
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from synth.errors import ModelFormatError
from synth.io import atomic_place, loads_json

FORMAT_NAME = "synth-head-model"
FORMAT_VERSION = 1

#: Joints every model must have (more are allowed).
REQUIRED_JOINTS = ("neck", "head", "jaw", "eye_l", "eye_r")
#: Region names every model is expected to define (the asset rigs read them; hair needs
#: ``scalp``). validate_model does not require them.
REQUIRED_REGIONS = ("face", "scalp", "ears", "eyes", "teeth", "mouth_interior", "eyelash_lines", "neck")
#: Landmark sets every model must define.
REQUIRED_LANDMARK_SETS = ("ibug68",)


@dataclasses.dataclass
class HeadModelData:
    """Everything a linear head model holds. Arrays are numpy; see docs/model-format.md."""

    name: str
    template: np.ndarray  # (V, 3) float32, metres
    triangles: np.ndarray  # (T, 3) int32, a triangulation of all polygons
    identity_basis: np.ndarray  # (Ki, V, 3) float32, unit-scale directions
    identity_scale: np.ndarray  # (Ki,) float32, std-dev (metres per unit of code)
    expression_basis: np.ndarray  # (Ke, V, 3) float32
    expression_scale: np.ndarray  # (Ke,) float32
    expression_names: list[str]
    joint_names: list[str]
    joint_parents: np.ndarray  # (J,) int32, -1 for the root, parents precede children
    joint_rest: np.ndarray  # (J, 3) float32, joint positions of the template
    joint_identity_basis: np.ndarray  # (Ki, J, 3) float32, joints follow identity
    skin_weights: np.ndarray  # (V, J) float32, rows sum to 1
    regions: dict[str, np.ndarray]  # name -> (n,) int32 vertex indices
    landmarks: dict[str, tuple[np.ndarray, np.ndarray]]  # set -> (tri (L,) int32, bary (L,3) float32)
    prior_weights: np.ndarray  # (M,) float64
    prior_means: np.ndarray  # (M, Ki) float64
    prior_covs: np.ndarray  # (M, Ki, Ki) float64
    license: str
    provenance: dict[str, Any]
    poly_offsets: np.ndarray | None = None  # (P+1,) int32, original polygons (quads kept)
    poly_indices: np.ndarray | None = None  # (N,) int32
    uvs: np.ndarray | None = None  # (U, 2) float32
    tri_uv: np.ndarray | None = None  # (T, 3) int32 indices into uvs
    poly_uv: np.ndarray | None = None  # (N,) int32, parallel to poly_indices
    landmark_names: dict[str, list[str]] = dataclasses.field(default_factory=dict)
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)  # free-form JSON metadata

    num_vertices = property(lambda self: int(self.template.shape[0]), doc="V, the number of vertices.")
    identity_dims = property(lambda self: int(self.identity_basis.shape[0]), doc="Ki, identity code length.")
    expression_dims = property(lambda self: int(self.expression_basis.shape[0]), doc="Ke, expression code length.")

    def meta(self) -> dict[str, Any]:
        return {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "name": self.name,
            "units": "m",
            "axes": {"up": "+Z", "face_forward": "-Y", "subject_left": "+X"},
            "expression_names": list(self.expression_names),
            "joint_names": list(self.joint_names),
            "regions": sorted(self.regions),
            "landmark_sets": sorted(self.landmarks),
            "landmark_names": {k: list(v) for k, v in self.landmark_names.items()},
            "license": self.license,
            "provenance": self.provenance,
            "extra": self.extra,
        }


# --------------------------------------------------------------------------- schema

# member name -> (dtype kind, ndim), one concept a line; shapes are cross-checked in
# validate_model. The order is the order of the members in the file.
_ARRAY_SCHEMA: dict[str, tuple[str, int]] = {
    "template": ("f", 2), "triangles": ("i", 2),
    "identity_basis": ("f", 3), "identity_scale": ("f", 1),
    "expression_basis": ("f", 3), "expression_scale": ("f", 1),
    "joint_parents": ("i", 1), "joint_rest": ("f", 2), "joint_identity_basis": ("f", 3),
    "skin_weights": ("f", 2),
    "prior_weights": ("f", 1), "prior_means": ("f", 2), "prior_covs": ("f", 3),
}
_OPTIONAL_ARRAYS: dict[str, tuple[str, int]] = {
    "poly_offsets": ("i", 1), "poly_indices": ("i", 1),
    "uvs": ("f", 2), "tri_uv": ("i", 2), "poly_uv": ("i", 1),
}

_META_SCHEMA = {
    "type": "object",
    "required": ["format", "format_version", "name", "units", "expression_names", "joint_names",
                 "regions", "landmark_sets", "license", "provenance"],
    "properties": {
        "format": {"const": FORMAT_NAME},
        "format_version": {"type": "integer", "minimum": 1, "maximum": FORMAT_VERSION},
        "name": {"type": "string", "minLength": 1},
        "units": {"const": "m"},
        "expression_names": {"type": "array", "items": {"type": "string"}},
        "joint_names": {"type": "array", "items": {"type": "string"}, "minItems": 1},
        "regions": {"type": "array", "items": {"type": "string"}},
        "landmark_sets": {"type": "array", "items": {"type": "string"}},
        "landmark_names": {"type": "object"},
        "license": {"type": "string", "minLength": 1},
        "provenance": {"type": "object"},
        "extra": {"type": "object"},
    },
}


def _fail(what: str, where: str) -> None:
    raise ModelFormatError(what, where, "rebuild or re-import the model (see docs/model-format.md)")


def validate_model(m: HeadModelData, where: str = "model") -> None:
    """Check types, shapes, index ranges and numeric sanity. Raises ModelFormatError."""
    import jsonschema

    try:
        jsonschema.validate(m.meta(), _META_SCHEMA)
    except jsonschema.ValidationError as e:
        _fail(f"metadata invalid: {e.message}", where)

    def arr(name: str, kind: str, ndim: int, optional: bool = False) -> np.ndarray | None:
        a = getattr(m, name)
        if a is None:
            if optional:
                return None
            _fail(f"missing array '{name}'", where)
        if not isinstance(a, np.ndarray) or a.dtype.kind not in (kind, "u" if kind == "i" else kind):
            _fail(f"array '{name}' must be {'float' if kind == 'f' else 'integer'}", where)
        if a.ndim != ndim:
            _fail(f"array '{name}' must have {ndim} dimensions, has {a.ndim}", where)
        if kind == "f" and not np.all(np.isfinite(a)):
            _fail(f"array '{name}' contains NaN or Inf", where)
        return a

    for k, (kind, nd) in _ARRAY_SCHEMA.items():
        arr(k, kind, nd)
    for k, (kind, nd) in _OPTIONAL_ARRAYS.items():
        arr(k, kind, nd, optional=True)

    V = m.template.shape[0]
    if m.template.shape != (V, 3) or V < 3:
        _fail(f"template must be (V, 3), is {m.template.shape}", where)
    if m.triangles.shape[1:] != (3,) or m.triangles.size == 0:
        _fail(f"triangles must be (T, 3), is {m.triangles.shape}", where)
    if m.triangles.min() < 0 or m.triangles.max() >= V:
        _fail("triangle index out of range", where)
    Ki, Ke = m.identity_basis.shape[0], m.expression_basis.shape[0]
    if m.identity_basis.shape != (Ki, V, 3):
        _fail(f"identity_basis must be (Ki, {V}, 3), is {m.identity_basis.shape}", where)
    if m.identity_scale.shape != (Ki,) or np.any(m.identity_scale <= 0):
        _fail("identity_scale must be (Ki,) and positive", where)
    if m.expression_basis.shape != (Ke, V, 3):
        _fail(f"expression_basis must be (Ke, {V}, 3), is {m.expression_basis.shape}", where)
    if m.expression_scale.shape != (Ke,) or np.any(m.expression_scale <= 0):
        _fail("expression_scale must be (Ke,) and positive", where)
    if len(m.expression_names) != Ke or len(set(m.expression_names)) != Ke:
        _fail("expression_names must be unique, one per expression component", where)
    J = len(m.joint_names)
    if len(set(m.joint_names)) != J:
        _fail("joint names must be unique", where)
    for j in REQUIRED_JOINTS:
        if j not in m.joint_names:
            _fail(f"required joint '{j}' missing", where)
    if m.joint_parents.shape != (J,):
        _fail("joint_parents must be (J,)", where)
    for j, p in enumerate(m.joint_parents.tolist()):
        if not (p == -1 and j == 0 or 0 <= p < j):
            _fail(f"joint '{m.joint_names[j]}' has parent {p}; parents must precede children and "
                  "only joint 0 may be the root", where)
    if m.joint_rest.shape != (J, 3) or m.joint_identity_basis.shape != (Ki, J, 3):
        _fail("joint_rest must be (J, 3) and joint_identity_basis (Ki, J, 3)", where)
    if m.skin_weights.shape != (V, J):
        _fail(f"skin_weights must be (V, J) = ({V}, {J}), is {m.skin_weights.shape}", where)
    if np.any(m.skin_weights < -1e-6) or not np.allclose(m.skin_weights.sum(1), 1.0, atol=1e-4):
        _fail("skin_weights must be non-negative with rows summing to 1", where)
    for name, idx in m.regions.items():
        if not isinstance(idx, np.ndarray) or idx.ndim != 1 or idx.dtype.kind not in "iu":
            _fail(f"region '{name}' must be a 1-D integer array", where)
        if idx.size and (idx.min() < 0 or idx.max() >= V):
            _fail(f"region '{name}' has a vertex index out of range", where)
    for s in REQUIRED_LANDMARK_SETS:
        if s not in m.landmarks:
            _fail(f"required landmark set '{s}' missing", where)
    T = m.triangles.shape[0]
    for s, (tri, bary) in m.landmarks.items():
        if tri.ndim != 1 or bary.shape != (tri.shape[0], 3):
            _fail(f"landmark set '{s}' must be tri (L,) and bary (L, 3)", where)
        if tri.size and (tri.min() < 0 or tri.max() >= T):
            _fail(f"landmark set '{s}' references a triangle out of range", where)
        if not np.all(np.isfinite(bary)) or not np.allclose(bary.sum(1), 1.0, atol=1e-4):
            _fail(f"landmark set '{s}' barycentric weights must sum to 1", where)
    M = m.prior_weights.shape[0]
    if M < 1 or m.prior_means.shape != (M, Ki) or m.prior_covs.shape != (M, Ki, Ki):
        _fail("prior must be weights (M,), means (M, Ki), covs (M, Ki, Ki)", where)
    if np.any(m.prior_weights <= 0) or abs(float(m.prior_weights.sum()) - 1.0) > 1e-6:
        _fail("prior weights must be positive and sum to 1", where)
    for c in m.prior_covs:
        if not np.allclose(c, c.T, atol=1e-8):
            _fail("prior covariances must be symmetric", where)
        try:
            np.linalg.cholesky(c)
        except np.linalg.LinAlgError:
            _fail("prior covariance is not positive definite", where)
    if (m.poly_offsets is None) != (m.poly_indices is None):
        _fail("poly_offsets and poly_indices come together", where)
    if m.poly_offsets is not None:
        off = m.poly_offsets
        if off[0] != 0 or off[-1] != m.poly_indices.shape[0] or np.any(np.diff(off) < 3):
            _fail("poly_offsets must start at 0, end at len(poly_indices), polygons >= 3 corners", where)
        if m.poly_indices.min() < 0 or m.poly_indices.max() >= V:
            _fail("polygon vertex index out of range", where)
    if m.uvs is not None:
        if m.uvs.shape[1:] != (2,):
            _fail("uvs must be (U, 2)", where)
        if m.tri_uv is None or m.tri_uv.shape != m.triangles.shape:
            _fail("tri_uv must match triangles when uvs are present", where)
        if m.tri_uv.min() < 0 or m.tri_uv.max() >= m.uvs.shape[0]:
            _fail("tri_uv index out of range", where)
        if m.poly_uv is not None and (m.poly_indices is None or m.poly_uv.shape != m.poly_indices.shape):
            _fail("poly_uv must be parallel to poly_indices", where)


# --------------------------------------------------------------------------- I/O

_DTYPES = {"f": np.float32, "i": np.int32}


def _to_members(m: HeadModelData) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for k, (kind, _) in {**_ARRAY_SCHEMA, **_OPTIONAL_ARRAYS}.items():
        a = getattr(m, k)
        if a is None:
            continue
        dt = np.float64 if k.startswith("prior_") else _DTYPES[kind]
        out[k] = np.ascontiguousarray(a, dtype=dt)
    for name, idx in m.regions.items():
        out[f"region.{name}"] = np.ascontiguousarray(idx, dtype=np.int32)
    for s, (tri, bary) in m.landmarks.items():
        out[f"landmarks.{s}.tri"] = np.ascontiguousarray(tri, dtype=np.int32)
        out[f"landmarks.{s}.bary"] = np.ascontiguousarray(bary, dtype=np.float32)
    out["meta"] = np.frombuffer(json.dumps(m.meta(), sort_keys=True).encode("utf-8"), dtype=np.uint8)
    return out


def write_model(m: HeadModelData, path: str | os.PathLike, compress: bool = False) -> Path:
    """Validate and write atomically (temp file + rename). Returns the path."""
    path = Path(path)
    validate_model(m, where=str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    members = _to_members(m)

    def fill(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            (np.savez_compressed if compress else np.savez)(f, **members)

    atomic_place(path, fill)
    return path


def read_model(path: str | os.PathLike) -> HeadModelData:
    """Read and validate a model file. Never unpickles."""
    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise ModelFormatError("model file not found", where, "check the path or run 'synth model info'")
    try:
        with np.load(path, allow_pickle=False) as z:
            members = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError) as e:
        raise ModelFormatError(f"not a readable .npz model file ({e.__class__.__name__}: {e})", where,
                               "the file must be written by synth's write_model") from None
    if "meta" not in members:
        _fail("no 'meta' member", where)
    try:
        meta = loads_json(members.pop("meta").tobytes())
    except ValueError as e:
        _fail(f"'meta' is not UTF-8 JSON: {e}", where)
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        _fail(f"not a {FORMAT_NAME} file (format={meta.get('format') if isinstance(meta, dict) else None!r})", where)
    kw: dict[str, Any] = {}
    for k in list(_ARRAY_SCHEMA) + list(_OPTIONAL_ARRAYS):
        kw[k] = members.pop(k, None)
    regions = {}
    landmarks: dict[str, list] = {}
    for k in list(members):
        if k.startswith("region."):
            regions[k[len("region."):]] = members.pop(k)
        elif k.startswith("landmarks."):
            s, part = k[len("landmarks."):].rsplit(".", 1)
            landmarks.setdefault(s, [None, None])[0 if part == "tri" else 1] = members.pop(k)
    for s, (tri, bary) in landmarks.items():
        if tri is None or bary is None:
            _fail(f"landmark set '{s}' is incomplete", where)
    try:
        m = HeadModelData(
            name=meta["name"],
            expression_names=list(meta["expression_names"]),
            joint_names=list(meta["joint_names"]),
            regions=regions,
            landmarks={s: (v[0], v[1]) for s, v in landmarks.items()},
            landmark_names={k: list(v) for k, v in meta.get("landmark_names", {}).items()},
            license=meta["license"],
            provenance=meta["provenance"],
            extra=meta.get("extra", {}),
            **kw,
        )
    except KeyError as e:
        _fail(f"metadata key {e} missing", where)
    validate_model(m, where)
    return m


def model_bytes(m: HeadModelData) -> bytes:
    """Serialise to bytes (used for hashing and tests)."""
    buf = io.BytesIO()
    np.savez(buf, **_to_members(m))
    return buf.getvalue()
