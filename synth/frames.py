"""The frame JSON (docs/frame-format.md): keys, schema validation, reading and writing.

The schema lives in ``synth/schemas/frame.schema.json`` (JSON Schema draft 2020-12).
:func:`validate_frame_json` adds the checks a schema cannot express (the key agrees with the
indices, the two camera matrices are inverse rigid transforms, landmarks_2d is the projection
of landmarks_3d, ...). The reader and ``synth validate`` both use it.
"""

from __future__ import annotations

import functools
import json
import re
from pathlib import Path

import numpy as np

from synth.dataset.fsio import atomic_write_json, loads_json
from synth.errors import SynthError

FRAME_KEY_RE = re.compile(r"^id(\d{6})_ex(\d{2})_v(\d{2})$")
NUM_LANDMARKS = 68
SCHEMA_PATH = Path(__file__).parent / "schemas" / "frame.schema.json"
#: Largest allowed distance (pixels) between landmarks_2d and the projection of landmarks_3d.
PROJECTION_TOL_PX = 0.01
#: Tolerance on world_to_camera @ camera_to_world == I and on the rotation being orthonormal.
MATRIX_TOL = 1e-5


def frame_key(identity: int, expression: int, view: int) -> str:
    """``id{identity:06d}_ex{expression:02d}_v{view:02d}`` (sortable, zero-padded)."""
    if not (0 <= identity <= 999999 and 0 <= expression <= 99 and 0 <= view <= 99):
        raise SynthError(f"frame indices out of range (identity {identity}, expression {expression}, view {view})",
                         None, "identity must be < 1e6, expression and view < 100")
    return f"id{identity:06d}_ex{expression:02d}_v{view:02d}"


def parse_frame_key(key: str) -> tuple[int, int, int]:
    m = FRAME_KEY_RE.match(key)
    if not m:
        raise SynthError(f"bad frame key {key!r}", None, "keys look like id000042_ex07_v13")
    return int(m[1]), int(m[2]), int(m[3])


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


def _path(err) -> str:
    return "/".join(str(p) for p in err.absolute_path) or "<root>"


def jsonable(obj):
    """A copy of ``obj`` with numpy arrays/scalars and tuples turned into plain JSON types."""
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


def validate_frame_json(obj) -> list[str]:
    """All problems with a frame object, as ``"json/path: message"`` strings; ``[]`` when valid."""
    errors = sorted(_validator().iter_errors(obj), key=lambda e: (list(map(str, e.absolute_path)), e.message))
    out = [f"{_path(e)}: {e.message if len(e.message) < 200 else e.message[:200] + '...'}" for e in errors]
    if out:
        return out
    return _semantic_errors(obj)


def _semantic_errors(f: dict) -> list[str]:
    out: list[str] = []
    key = f["frame_id"]
    expect = f"id{f['identity_index']:06d}_ex{f['expression_index']:02d}_v{f['view_index']:02d}"
    if key != expect:
        out.append(f"frame_id: {key!r} disagrees with the indices (expected {expect!r})")
    img, cam = f["image"], f["camera"]
    if img["file"] != f"{key}.exr":
        out.append(f"image/file: {img['file']!r}, expected {key + '.exr'!r}")
    if (cam["width"], cam["height"]) != (img["width"], img["height"]):
        out.append(f"camera: size {cam['width']}x{cam['height']} differs from image {img['width']}x{img['height']}")
    from synth.exr import CHANNELS

    if sorted(img["layers"]) != sorted(CHANNELS):
        out.append(f"image/layers: {img['layers']} differs from the EXR channels {list(CHANNELS)}")
    if not cam["near"] < cam["far"]:
        out.append(f"camera: near {cam['near']} is not below far {cam['far']}")
    K = np.asarray(cam["K"], dtype=np.float64)
    w2c = np.asarray(cam["world_to_camera"], dtype=np.float64)
    c2w = np.asarray(cam["camera_to_world"], dtype=np.float64)
    if not (K[0, 0] > 0 and K[1, 1] > 0 and np.allclose(K[2], [0, 0, 1]) and K[1, 0] == 0):
        out.append("camera/K: not an intrinsics matrix (fx, fy > 0, last row [0, 0, 1], K[1][0] = 0)")
    for name, M in (("world_to_camera", w2c), ("camera_to_world", c2w), ("model/head_pose",
                                                                        np.asarray(f["model"]["head_pose"], float))):
        R = M[:3, :3]
        if not (np.allclose(M[3], [0, 0, 0, 1], atol=MATRIX_TOL) and np.allclose(R @ R.T, np.eye(3), atol=MATRIX_TOL)
                and np.linalg.det(R) > 0):
            out.append(f"{name if '/' in name else 'camera/' + name}: not a rigid transform "
                       "(rotation not orthonormal with det +1, or last row not [0, 0, 0, 1])")
    if not np.allclose(w2c @ c2w, np.eye(4), atol=MATRIX_TOL * max(1.0, float(np.abs(c2w[:3, 3]).max()))):
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


def landmark_visibility(landmarks_2d, landmarks_z, depth, *, tol_m: float = 0.01) -> np.ndarray:
    """Per-landmark visibility from the rendered depth (``depth.Z`` of the frame EXR).

    ``landmarks_2d``: (N, 2) pixels (top-left corner at (0, 0), pixel centres at +0.5, as in
    :mod:`synth.conventions`); ``landmarks_z``: (N,) camera-space z of the landmarks (metres);
    ``depth``: (H, W) camera-space z, 0 = background. A landmark is visible when it is in front
    of the camera, inside the image, and no surface at its pixel is closer than ``z - tol_m``
    (a background pixel at a silhouette edge does not occlude it).
    """
    xy = np.asarray(landmarks_2d, np.float64)
    z = np.asarray(landmarks_z, np.float64)
    depth = np.asarray(depth)
    h, w = depth.shape
    ok = np.isfinite(xy).all(axis=1) & np.isfinite(z) & (z > 0)
    col = np.floor(np.where(ok, xy[:, 0], -1)).astype(np.int64)
    row = np.floor(np.where(ok, xy[:, 1], -1)).astype(np.int64)
    ok &= (col >= 0) & (col < w) & (row >= 0) & (row < h)
    d = np.zeros(len(z))
    d[ok] = depth[row[ok], col[ok]]
    occluded = (d > 0) & (d < z - tol_m)
    return ok & ~occluded


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
        obj = loads_json(path.read_bytes())
    except FileNotFoundError:
        raise SynthError("frame JSON not found", str(path), "check the path") from None
    except (ValueError, UnicodeDecodeError) as e:
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
