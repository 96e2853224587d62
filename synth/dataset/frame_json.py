"""The frame JSON (docs/frame-format.md): the record builder, schema validation, reading and writing.

The schema lives in ``synth/schemas/frame.schema.json`` (JSON Schema draft 2020-12).
:func:`validate_frame_json` adds the checks a schema cannot express (the key agrees with the
indices, the two camera matrices are inverse rigid transforms, landmarks_2d is the projection
of landmarks_3d, ...). The writer, the reader and ``synth validate`` all use it.
:func:`build_frame_record` assembles a frame's record from what the worker planned and rendered.
"""

from __future__ import annotations

import functools
import itertools
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import orjson

from synth.dataset.exr import CHANNELS
from synth.dataset.layout import MAX_FRAME_JSON_BYTES, frame_files, parse_frame_key_env
from synth.dataset.schema_fast import compile_sufficient
from synth.errors import SynthError
from synth.io import atomic_write_json, read_json

SCHEMA_PATH = Path(__file__).parent.parent / "schemas" / "frame.schema.json"
#: Largest allowed distance (pixels) between landmarks_2d and the projection of landmarks_3d.
PROJECTION_TOL_PX = 0.01
#: Tolerance on world_to_camera @ camera_to_world == I and on the rotation being orthonormal.
MATRIX_TOL = 1e-5


@functools.lru_cache(maxsize=1)
def frame_schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))


@functools.lru_cache(maxsize=1)
def _validator():
    import jsonschema

    schema = frame_schema()
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


#: keywords a plain array schema may have (see :func:`_plain_check`)
_PLAIN_KEYS = frozenset({"type", "minItems", "maxItems", "items", "description", "title"})


_NUMBER_TYPES = frozenset({int, float})  # JSON Schema's number: not a bool
_BOOL_TYPES = frozenset({bool})


def _plain_check(sub):
    """An exact check of ``sub`` in plain Python when it is a plain array schema (``type``
    array, ``minItems``/``maxItems``, ``items`` a plain array schema or ``{"type": "number"}``
    or ``{"type": "boolean"}``), else None. jsonschema takes about 30 us per array element; the
    frame's landmarks, codes and matrices are most of its elements."""
    dims: list[tuple[int, int | None]] = []
    while isinstance(sub, dict) and not set(sub) - _PLAIN_KEYS and sub.get("type") == "array":
        lo, hi = sub.get("minItems", 0), sub.get("maxItems")
        if type(lo) is not int or (hi is not None and type(hi) is not int):
            return None
        dims.append((lo, hi))
        sub = sub.get("items")
    if not isinstance(sub, dict) or set(sub) - {"description", "title"} != {"type"} or sub["type"] not in (
            "number", "boolean"):
        return None
    leaf = _NUMBER_TYPES if sub["type"] == "number" else _BOOL_TYPES
    if not dims:
        return lambda x: type(x) in leaf
    return functools.partial(_nested_ok, dims=tuple(dims), leaf=leaf)


def _nested_ok(x, dims: tuple, leaf: frozenset) -> bool:
    """Whether ``x`` is nested lists with the item counts of ``dims`` (one (min, max) per level)
    whose innermost values all have a type in ``leaf``; the types are collected by ``map`` in C,
    not by a Python call per value."""
    level = [x]
    for lo, hi in dims:
        for v in level:
            if type(v) is not list or len(v) < lo or (hi is not None and len(v) > hi):
                return False
        level = level[0] if len(level) == 1 else list(itertools.chain.from_iterable(level))
    return set(map(type, level)) <= leaf


def _split(schema: dict, path: tuple, checks: list) -> dict:
    """``schema`` with each plain array schema under ``properties`` replaced by ``{}``; their
    paths and checks go to ``checks``. An instance whose values at those paths (where present)
    pass the checks is valid under ``schema`` exactly when it is valid under the result."""
    props = schema.get("properties")
    if not isinstance(props, dict):
        return schema
    out = {}
    for name, sub in props.items():
        fn = _plain_check(sub)
        if fn is not None:
            checks.append((path + (name,), fn))
            out[name] = {}
        else:
            out[name] = _split(sub, path + (name,), checks) if isinstance(sub, dict) else sub
    return {**schema, "properties": out}


#: root keywords under which each property's value is valid or not on its own
_ROOT_KEYS = frozenset({"$schema", "$id", "title", "description", "type", "required", "properties", "$defs"})


@functools.lru_cache(maxsize=1)
def _fast_validator():
    """(the root's check, property -> (its compiled check or None, a validator of its value),
    the plain-array checks): the schema of :func:`_split`, taken apart where that is exact.
    A check is :func:`synth.dataset.schema_fast.compile_sufficient`'s: True means valid."""
    checks: list = []
    light = _split(frame_schema(), (), checks)
    full = _validator()
    defs = light.get("$defs", {})
    if set(light) - _ROOT_KEYS:
        return full.evolve(schema=light).is_valid, {}, tuple(checks)
    props = {name: (compile_sufficient(sub, defs), full.evolve(schema={**sub, "$defs": defs}))
             for name, sub in light["properties"].items() if isinstance(sub, dict) and sub}
    root_schema = {**light, "properties": {name: {} for name in light["properties"]}}
    root = compile_sufficient(root_schema, defs)
    if root is None:
        root = full.evolve(schema=root_schema).is_valid
    return root, props, tuple(checks)


@functools.lru_cache(maxsize=4096)
def _value_valid(name: str, value: bytes) -> bool:
    """Whether a property's value (its JSON bytes) is valid: frames of a shard repeat most of
    their objects (assets, render settings, software), so each is checked once."""
    return _fast_validator()[1][name][1].is_valid(orjson.loads(value))


def _fast_valid(obj) -> bool:
    """Valid under the whole schema (see :func:`_split`); False may still be valid."""
    root, props, checks = _fast_validator()
    if not _plain_values_ok(obj, checks) or not root(obj):
        return False
    try:
        for k, v in obj.items():
            if k in props:
                quick = props[k][0]
                if not ((quick is not None and quick(v)) or _value_valid(k, orjson.dumps(v))):
                    return False
        return True
    except (TypeError, orjson.JSONEncodeError):  # not plain JSON: the whole schema says why
        return False


def _plain_values_ok(obj, checks) -> bool:
    for path, fn in checks:
        v = obj
        for p in path:
            if type(v) is not dict or p not in v:
                break  # absent or not an object: the rest of the schema says whether that is allowed
            v = v[p]
        else:
            if not fn(v):
                return False
    return True


def _path(err) -> str:
    return "/".join(str(p) for p in err.absolute_path) or "<root>"


_JSON_SCALARS = frozenset({int, float, str, bool, type(None)})


def jsonable(obj):
    """A copy of ``obj`` with numpy arrays/scalars and tuples turned into plain JSON types."""
    if type(obj) is list and _JSON_SCALARS.issuperset(map(type, obj)):  # a plain array: types checked in C
        return list(obj)
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    return obj


def _floats(a) -> list:
    return np.asarray(a, dtype=np.float64).tolist()


class PlannedFrame(Protocol):
    """The plan's frame (:class:`synth.plan.records.Frame`; the dataset layer names only what
    it reads)."""

    frame_id: str
    seed: int

    def to_json(self) -> dict[str, Any]: ...


class PlannedExpression(Protocol):
    """The plan's expression (:class:`synth.plan.records.Expression`): what the frame records of it."""

    kind: str
    preset: str | None
    pose: Mapping[str, float]


@dataclass(frozen=True)
class ModelEvaluation:
    """The head model as evaluated for one frame: ``info`` (the model's ``name`` and
    ``sha256``), the identity and expression codes it was evaluated with, the plan's
    ``expression`` (its ``preset``, ``kind`` and ``pose`` are recorded), ``joint_rotations``
    (joint name -> axis-angle (3,), in the model's joint order), ``head_pose`` (the head
    joint's 4x4 world transform) and the landmarks: (68, 3) world metres, (68, 2) pixels,
    (68,) booleans. Arrays of any float dtype; they are recorded as float64 values."""

    info: Mapping[str, str]
    identity_code: np.ndarray
    expression: PlannedExpression
    expression_code: np.ndarray
    joint_rotations: Mapping[str, np.ndarray]
    head_pose: np.ndarray
    landmarks_3d: np.ndarray
    landmarks_2d: np.ndarray
    landmarks_visible: np.ndarray


@dataclass(frozen=True)
class SceneRecord:
    """The identity's scene as the frame JSON records it: ``assets`` (class -> the plan's pick
    with its ``build``, every class), ``skin`` (the plan's parameters and the albedos) and
    ``lighting`` (the plan's lighting record of the frame's environment)."""

    assets: Mapping[str, Any]
    skin: Mapping[str, Any]
    lighting: Mapping[str, Any]


@dataclass(frozen=True)
class RenderRecord:
    """How a frame was rendered: its shard, the image size, the render preset and the
    effective engine settings (``blender_scripts.scene.configure_render``), the software versions."""

    shard_id: str
    width: int
    height: int
    preset: str | None
    settings: Mapping[str, Any]
    software: Mapping[str, str]


def build_frame_record(frame: PlannedFrame, model: ModelEvaluation, scene: SceneRecord, render: RenderRecord) -> dict:
    """The frame JSON of one rendered view, in the documented key order (docs/frame-format.md):
    the plan's ``frame`` first and unchanged, then the shard, the image, the model block, the
    landmarks, the scene, ``render`` (the preset, the image size, the planned seed and the
    engine settings) and the software versions.

    Arrays become plain lists (float64 values, bit for bit); nothing is validated here
    (:func:`write_frame_json` and ``StagingShard.write_frame`` do that).
    """
    record = jsonable(frame.to_json())
    e = model.expression
    record["shard_id"] = render.shard_id
    record["image"] = {"width": render.width, "height": render.height, "file": frame_files(frame.frame_id)[0],
                       "layers": list(CHANNELS)}
    record["model"] = {**model.info, "identity": _floats(model.identity_code),
                       "expression": _floats(model.expression_code), "expression_preset": e.preset, "expression_kind": e.kind,
                       "joint_rotations": {name: _floats(r) for name, r in model.joint_rotations.items()},
                       "pose": dict(e.pose), "head_pose": _floats(model.head_pose)}
    record["landmarks_3d"] = _floats(model.landmarks_3d)
    record["landmarks_2d"] = _floats(model.landmarks_2d)
    record["landmarks_visible"] = np.asarray(model.landmarks_visible, dtype=bool).tolist()
    record["assets"] = jsonable(scene.assets)
    record["skin"] = jsonable(scene.skin)
    record["lighting"] = jsonable(scene.lighting)
    record["render"] = {"preset": render.preset, "resolution": [render.width, render.height], "seed": int(frame.seed),
                        **render.settings}
    record["software"] = render.software
    return record


def validate_frame_json(obj) -> list[str]:
    """All problems with a frame object, as ``"json/path: message"`` strings; ``[]`` when valid."""
    if _fast_valid(obj):
        return _semantic_errors(obj)
    errors = sorted(_validator().iter_errors(obj), key=lambda e: (list(map(str, e.absolute_path)), e.message))
    out = [f"{_path(e)}: {e.message if len(e.message) < 200 else e.message[:200] + '...'}" for e in errors]
    if out:
        return out
    return _semantic_errors(obj)


_EYE3, _EYE4 = np.eye(3), np.eye(4)
_LAST_ROW, _K_ROW = np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])


def _close(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    """``np.allclose(a, b, atol=atol)`` for finite ``b`` (rtol 1e-5; NaN is never close),
    without its general-case cost: this runs several times per frame in ``synth validate``."""
    return bool((np.abs(a - b) <= atol + 1e-5 * np.abs(b)).all())


def _semantic_errors(f: dict) -> list[str]:
    out: list[str] = []
    key = f["frame_id"]
    indices = (f["identity_index"], f["expression_index"], f.get("environment_index", 0), f["view_index"])
    if parse_frame_key_env(key) != indices:
        out.append(f"frame_id: {key!r} disagrees with the indices (identity, expression, environment, view) = "
                   f"{indices}")
    img, cam = f["image"], f["camera"]
    exr_file = frame_files(key)[0]
    if img["file"] != exr_file:
        out.append(f"image/file: {img['file']!r}, expected {exr_file!r}")
    if (cam["width"], cam["height"]) != (img["width"], img["height"]):
        out.append(f"camera: size {cam['width']}x{cam['height']} differs from image {img['width']}x{img['height']}")
    if sorted(img["layers"]) != sorted(CHANNELS):
        out.append(f"image/layers: {img['layers']} differs from the EXR channels {list(CHANNELS)}")
    if not cam["near"] < cam["far"]:
        out.append(f"camera: near {cam['near']} is not below far {cam['far']}")
    K = np.asarray(cam["K"], dtype=np.float64)
    # the three rigid transforms checked together (one array op per test instead of three)
    M = np.asarray([cam["world_to_camera"], cam["camera_to_world"], f["model"]["head_pose"]], dtype=np.float64)
    w2c, c2w = M[0], M[1]
    if not (K[0, 0] > 0 and K[1, 1] > 0 and _close(K[2], _K_ROW, 1e-8) and K[1, 0] == 0):
        out.append("camera/K: not an intrinsics matrix (fx, fy > 0, last row [0, 0, 1], K[1][0] = 0)")
    R = M[:, :3, :3]
    tol = MATRIX_TOL + 1e-5 * np.abs(_EYE3)  # _close's bound, per element
    rigid = ((np.abs(M[:, 3] - _LAST_ROW) <= MATRIX_TOL + 1e-5 * _LAST_ROW).all(axis=1)
             & (np.abs(R @ R.transpose(0, 2, 1) - _EYE3) <= tol).all(axis=(1, 2)))
    if not rigid.all() or not (np.linalg.det(R) > 0).all():
        det = np.linalg.det(R)
        for i, name in enumerate(("camera/world_to_camera", "camera/camera_to_world", "model/head_pose")):
            if not (rigid[i] and det[i] > 0):
                out.append(f"{name}: not a rigid transform "
                           "(rotation not orthonormal with det +1, or last row not [0, 0, 0, 1])")
    if not _close(w2c @ c2w, _EYE4, MATRIX_TOL * max(1.0, float(np.abs(c2w[:3, 3]).max()))):
        out.append("camera: world_to_camera @ camera_to_world is not the identity")
    X = np.asarray(f["landmarks_3d"], dtype=np.float64)
    x2 = np.asarray(f["landmarks_2d"], dtype=np.float64)
    pc = X @ w2c[:3, :3].T + w2c[:3, 3]
    front = pc[:, 2] > 0
    proj = pc @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        proj = proj[:, :2] / proj[:, 2:3]
    err = np.abs(proj - x2).max(axis=1)
    bad = np.flatnonzero(front & ~(err <= PROJECTION_TOL_PX))
    if bad.size:
        out.append(f"landmarks_2d: {bad.size} point(s) differ from the projection of landmarks_3d by more than "
                   f"{PROJECTION_TOL_PX} px (first: #{bad[0]}, {err[bad[0]]:.3g} px)")
    vis = np.asarray(f["landmarks_visible"], dtype=bool)
    if (vis & ~front).any():
        out.append("landmarks_visible: a landmark behind the camera is marked visible")
    return out


def check_frame_json(obj, where: str) -> None:
    """Raise :class:`SynthError` (first problem, and a count) when ``obj`` is not a valid frame."""
    errs = validate_frame_json(obj)
    if errs:
        more = f" (+{len(errs) - 1} more)" if len(errs) > 1 else ""
        raise SynthError(f"invalid frame JSON: {errs[0]}{more}", where,
                         "fix the frame object (schema: synth/schemas/frame.schema.json, docs/frame-format.md)")


def read_frame_json(path, *, validate: bool = True) -> dict:
    """Read a frame JSON (strict: NaN/Infinity refused) and, by default, validate it."""
    path = Path(path)
    try:
        obj = read_json(path, max_bytes=MAX_FRAME_JSON_BYTES)
    except FileNotFoundError:
        raise SynthError("frame JSON not found", str(path), "check the path") from None
    except ValueError as e:
        raise SynthError(f"frame JSON does not parse: {e}", str(path), "the file is corrupt; re-render it") from None
    if validate:
        check_frame_json(obj, str(path))
    return obj


def write_frame_json(path, obj, *, validate: bool = True, durable: bool = True) -> bytes:
    """Validate (by default) and write a frame JSON atomically; returns the bytes written.

    numpy arrays and scalars in ``obj`` are converted to lists/numbers first.
    """
    path = Path(path)
    obj = jsonable(obj)
    if validate:
        check_frame_json(obj, str(path))
    try:
        return atomic_write_json(path, obj, durable=durable, indent=None)
    except (TypeError, ValueError) as e:
        raise SynthError(f"frame object is not JSON-serialisable: {e}", str(path),
                         "convert numpy arrays with .tolist() and replace NaN/inf") from None
