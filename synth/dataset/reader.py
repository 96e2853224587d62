"""Reading a synth dataset from a training job (docs/reading.md).

::

    from synth.dataset.reader import iter_frames, rays

    for frame in iter_frames("DIR"):            # a dataset, one shard directory, a .tar, or a stream
        o, d = rays(frame)                       # (H, W, 3) world-space origins and unit directions
        rgb, alpha = frame.rgb, frame.alpha      # straight colour and coverage, float32

Sources:

- a dataset directory (``DIR/shards/<shard>/``): every *committed* shard, in shard-id order,
  frames in key order; staging directories are never read;
- one shard directory (committed or not: any ``KEY.json`` with its ``KEY.exr``);
- a tar file or any binary stream of a tar (WebDataset style: members ``[prefix/]KEY.json`` and
  ``[prefix/]KEY.exr``, the two of a frame adjacent or not), read in one forward pass;
- an iterable of WebDataset sample dicts (``{"__key__": KEY, "json": bytes, "exr": bytes}``).

Thread- and fork-safe: decoding works on bytes in memory and never redirects stdout/stderr, so
frames can be read from several threads or DataLoader workers at once. Schema validation is
optional (``validate=True``) and off by default, since it costs more than the decode.

Cameras follow :mod:`synth.conventions` (OpenCV axes: x right, y down, z forward; ``K`` in
pixels with the image's top-left *corner* at (0, 0), so the centre of pixel (column i, row j)
is at (i + 0.5, j + 0.5)). :func:`rays` shoots through pixel centres.
"""

from __future__ import annotations

import os
import tarfile
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import IO, NamedTuple

import numpy as np

from synth.dataset.exr import decode_frame_exr
from synth.dataset.frame_json import check_frame_json
from synth.dataset.layout import (FRAME_KEY_RE, MANIFEST_FILE, MAX_EXR_BYTES, MAX_FRAME_JSON_BYTES, MAX_MANIFEST_BYTES,
                                  SHARDS_DIR, SHARD_ID_RE)
from synth.errors import SynthError
from synth.io import FileRefused, loads_json, read_bounded, read_json

#: Largest frame member read from a tar stream (bytes); a larger one is refused, not read.
MAX_MEMBER_BYTES = 1 << 30


def _meta_field(section: str | None, key: str, kind, doc: str) -> cached_property:
    """A read-only frame attribute taken from the frame JSON (``meta[section][key]``, or
    ``meta[key]`` without a section): an int, or an array of dtype ``kind``."""

    def get(self):
        v = (self.meta if section is None else self.meta[section])[key]
        return int(v) if kind is int else np.asarray(v, kind)

    get.__doc__ = doc
    return cached_property(get)


@dataclass(eq=False)
class Frame:
    """One decoded frame. Pixel arrays are float32 (segmentation uint32), shape (H, W[, C]).

    ``rgba`` is as stored: scene-linear Rec.709, *premultiplied* alpha. ``depth`` is camera-space
    z in metres (planar, not ray length; 0 = background). ``normals`` are world-space unit
    normals (0 = background). ``meta`` is the frame JSON (docs/frame-format.md).
    """

    key: str
    meta: dict
    rgba: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    segmentation: np.ndarray
    shard: str | None = None

    # ---------------------------------------------------------------- pixels
    height = property(lambda self: int(self.rgba.shape[0]), doc="Image height, pixels.")
    width = property(lambda self: int(self.rgba.shape[1]), doc="Image width, pixels.")
    alpha = property(lambda self: self.rgba[..., 3], doc="(H, W) coverage in [0, 1].")
    rgb_premultiplied = property(lambda self: self.rgba[..., :3],
                                 doc="(H, W, 3) colour premultiplied by alpha (= colour over a black background).")

    @cached_property
    def rgb(self) -> np.ndarray:
        """(H, W, 3) straight (un-premultiplied) colour; 0 where alpha is 0."""
        a = self.alpha[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(a > 0, self.rgb_premultiplied / np.where(a > 0, a, 1), 0)
        return out.astype(np.float32, copy=False)

    # ---------------------------------------------------------------- indices, codes, camera
    identity_index = _meta_field(None, "identity_index", int, "The frame's identity index.")
    expression_index = _meta_field(None, "expression_index", int, "The expression's index within the identity.")
    view_index = _meta_field(None, "view_index", int, "The view's index within the expression.")
    identity_code = _meta_field("model", "identity", np.float32, "The head model's identity code (beta), float32.")
    expression_code = _meta_field("model", "expression", np.float32,
                                  "The head model's expression code (psi), float32.")
    K = _meta_field("camera", "K", np.float64, "(3, 3) intrinsics in pixels (top-left corner at (0, 0)).")
    world_to_camera = _meta_field("camera", "world_to_camera", np.float64, "(4, 4) rigid world -> OpenCV camera.")
    camera_to_world = _meta_field("camera", "camera_to_world", np.float64, "(4, 4) rigid OpenCV camera -> world.")

    @cached_property
    def joint_rotations(self) -> dict[str, np.ndarray]:
        """Joint name -> axis-angle (3,) radians, float32, in the model's joint order."""
        return {k: np.asarray(v, np.float32) for k, v in (self.meta["model"].get("joint_rotations") or {}).items()}


def decode_frame(json_bytes: bytes, exr_bytes: bytes, *, key: str | None = None, shard: str | None = None,
                 validate: bool = False, where: str = "<memory>") -> Frame:
    """A :class:`Frame` from the bytes of its JSON and EXR."""
    try:
        meta = loads_json(json_bytes)
    except (ValueError, UnicodeDecodeError, RecursionError) as e:
        raise SynthError(f"frame JSON does not parse: {str(e)[:120]}", where, "the file is corrupt; re-render it") \
            from None
    if not isinstance(meta, dict):
        raise SynthError("frame JSON is not an object", where, "the file is corrupt; re-render it")
    if validate:
        check_frame_json(meta, where)
    key = key or meta.get("frame_id")
    if key is not None and meta.get("frame_id") != key:
        raise SynthError(f"frame JSON names frame {meta.get('frame_id')!r}, not {key!r}", where,
                         "the JSON and EXR do not belong together")
    px = decode_frame_exr(exr_bytes, where)
    rgba = px["rgba"].astype(np.float32)
    normals = px["normals"].astype(np.float32)
    depth = np.asarray(px["depth"], np.float32)
    seg = np.asarray(px["segmentation"], np.uint32)
    if validate:
        img = meta.get("image") or {}
        if (img.get("width"), img.get("height")) != (rgba.shape[1], rgba.shape[0]):
            raise SynthError(f"EXR is {rgba.shape[1]}x{rgba.shape[0]} but the JSON says "
                             f"{img.get('width')}x{img.get('height')}", where, "re-render the frame")
    return Frame(key=str(key), meta=meta, rgba=rgba, depth=depth, normals=normals, segmentation=seg, shard=shard)


def read_frame(json_path, *, shard: str | None = None, validate: bool = False) -> Frame:
    """Read ``KEY.json`` and the ``KEY.exr`` beside it."""
    p = Path(json_path)
    try:
        jb, eb = read_bounded(p, MAX_FRAME_JSON_BYTES), read_bounded(p.with_suffix(".exr"), MAX_EXR_BYTES)
    except FileNotFoundError as e:
        raise SynthError("frame file not found", str(e.filename), "check the path (or re-render the frame)") from None
    except FileRefused as e:
        raise SynthError(f"frame file refused: it {e.what}", os.fsdecode(e.path), "re-render the frame") from None
    return decode_frame(jb, eb, key=p.stem, shard=shard or p.parent.name, validate=validate, where=str(p))


# --------------------------------------------------------------------------- listing


class FrameRef(NamedTuple):
    """Where one frame lives on disk (for random access and samplers)."""

    shard: str
    key: str
    json_path: Path

    def read(self, *, validate: bool = False) -> Frame:
        return read_frame(self.json_path, shard=self.shard, validate=validate)


def _shard_keys(shard_dir: Path) -> list[str]:
    """Frame keys of a shard: the manifest's list when committed, else the JSON files present."""
    man = shard_dir / MANIFEST_FILE
    if man.is_file():
        try:
            m = read_json(man, max_bytes=MAX_MANIFEST_BYTES, follow_symlinks=False)
        except ValueError as e:
            raise SynthError(f"manifest.json cannot be read ({e})", str(man), "run `synth validate` on the dataset") \
                from None
        if isinstance(m, dict) and isinstance(m.get("frames"), list):
            return sorted(str(k) for k in m["frames"] if FRAME_KEY_RE.match(str(k)))
    return sorted(n[:-5] for n in os.listdir(shard_dir) if n.endswith(".json") and n != MANIFEST_FILE
                  and (shard_dir / (n[:-5] + ".exr")).is_file())


def list_frames(source, *, shards: Iterable[str] | None = None) -> list[FrameRef]:
    """Every frame of a dataset directory (committed shards only) or of one shard directory,
    sorted by (shard, key). ``shards`` restricts a dataset to those shard ids."""
    root = Path(source)
    if not root.is_dir():
        raise SynthError("not a dataset or shard directory", str(root), "pass the --out directory of synth render")
    if (root / SHARDS_DIR).is_dir():
        wanted = set(shards) if shards is not None else None
        names = sorted(n for n in os.listdir(root / SHARDS_DIR) if SHARD_ID_RE.match(n)
                       and (root / SHARDS_DIR / n / MANIFEST_FILE).is_file() and (wanted is None or n in wanted))
        dirs = [root / SHARDS_DIR / n for n in names]
        if wanted is not None and len(dirs) != len(wanted):
            missing = sorted(wanted - set(names))
            raise SynthError(f"shard(s) not committed in this dataset: {', '.join(missing[:5])}", str(root),
                             "render them first, or leave them out")
    else:
        dirs = [root]
    return [FrameRef(d.name, k, d / f"{k}.json") for d in dirs for k in _shard_keys(d)]


# --------------------------------------------------------------------------- iteration


def _iter_tar(stream: IO[bytes], validate: bool, where: str) -> Iterator[Frame]:
    pending: dict[str, dict[str, bytes]] = {}
    try:
        tf = tarfile.open(fileobj=stream, mode="r|*")
    except tarfile.TarError as e:
        raise SynthError(f"not a tar stream: {e}", where, "pass a dataset directory, a shard directory or a .tar")
    with tf:
        for m in tf:
            name = m.name.rsplit("/", 1)[-1]
            stem, dot, ext = name.partition(".")
            if not m.isreg() or ext not in ("json", "exr") or name == MANIFEST_FILE:
                continue
            if m.size > MAX_MEMBER_BYTES:
                raise SynthError(f"tar member {m.name} has {m.size} bytes (limit {MAX_MEMBER_BYTES})", where,
                                 "this is not a synth frame; check the tar")
            data = tf.extractfile(m).read()  # type: ignore[union-attr]
            parts = pending.setdefault(stem, {})
            parts[ext] = data
            if len(parts) == 2:
                del pending[stem]
                prefix = m.name.rsplit("/", 2)[-2] if m.name.count("/") else None
                yield decode_frame(parts["json"], parts["exr"], key=stem, shard=prefix, validate=validate,
                                   where=f"{where}:{stem}")
    if pending:
        raise SynthError(f"tar ends with {len(pending)} incomplete frame(s) (first: {sorted(pending)[0]})", where,
                         "each frame needs both KEY.json and KEY.exr; re-create the tar")


def iter_frames(source, *, shards: Iterable[str] | None = None, validate: bool = False) -> Iterator[Frame]:
    """Frames from a dataset directory, a shard directory, a tar file, a binary stream of a tar,
    or an iterable of WebDataset sample dicts (see the module docstring)."""
    if isinstance(source, (str, os.PathLike)):
        p = Path(source)
        if p.is_file():
            with open(p, "rb") as f:
                yield from _iter_tar(f, validate, str(p))
            return
        for ref in list_frames(p, shards=shards):
            yield ref.read(validate=validate)
        return
    if hasattr(source, "read"):
        yield from _iter_tar(source, validate, getattr(source, "name", "<stream>"))
        return
    for sample in source:
        key = sample.get("__key__")
        if "json" not in sample or "exr" not in sample:
            raise SynthError(f"sample {key!r} lacks 'json' or 'exr'", "<samples>",
                             "pass WebDataset samples with both members")
        k = str(key).rsplit("/", 1)[-1] if key is not None else None
        yield decode_frame(sample["json"], sample["exr"], key=k, validate=validate, where=f"<samples>:{key}")


# --------------------------------------------------------------------------- rays


class Rays(NamedTuple):
    """World-space rays: ``origins`` and unit ``directions`` (..., 3), and ``cos_z`` (...,), the
    cosine between each ray and the optical axis, so planar depth z = t * cos_z for a point at
    distance t along the ray."""

    origins: np.ndarray
    directions: np.ndarray
    cos_z: np.ndarray


def camera_rays(K, camera_to_world, width: int, height: int, *, pixels=None, dtype=np.float32) -> Rays:
    """Rays through pixel centres of an OpenCV camera.

    ``pixels``: None for every pixel ((H, W, 3) outputs, row-major), or ``(rows, cols)`` integer
    arrays for a subset ((N, 3) outputs). The direction of pixel (col i, row j) is
    ``R_c2w @ normalise(K^-1 @ [i + 0.5, j + 0.5, 1])``.
    """
    K = np.asarray(K, np.float64)
    c2w = np.asarray(camera_to_world, np.float64)
    if pixels is None:
        u = np.arange(width, dtype=np.float64) + 0.5
        v = np.arange(height, dtype=np.float64) + 0.5
        uu, vv = np.meshgrid(u, v)  # (H, W): uu[j, i] = i + 0.5
    else:
        rows, cols = (np.asarray(a) for a in pixels)
        uu, vv = cols.astype(np.float64) + 0.5, rows.astype(np.float64) + 0.5
    # K^-1 for a camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] (skew allowed)
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    y = (vv - cy) / fy
    x = (uu - cx - s * y) / fx
    inv_norm = 1.0 / np.sqrt(x * x + y * y + 1.0)
    R = c2w[:3, :3]
    d = (x * inv_norm)[..., None] * R[:, 0] + (y * inv_norm)[..., None] * R[:, 1] + inv_norm[..., None] * R[:, 2]
    o = np.broadcast_to(c2w[:3, 3], d.shape)
    return Rays(o.astype(dtype), d.astype(dtype), inv_norm.astype(dtype))


def rays(frame: Frame, *, pixels=None, dtype=np.float32) -> Rays:
    """Per-pixel world-space rays of a frame (see :func:`camera_rays`)."""
    return camera_rays(frame.K, frame.camera_to_world, frame.width, frame.height, pixels=pixels, dtype=dtype)


__all__ = ["Frame", "FrameRef", "Rays", "camera_rays", "decode_frame", "iter_frames", "list_frames", "read_frame",
           "rays"]
