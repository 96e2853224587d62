"""Reading a synth dataset from a training job (docs/reading.md).

::

    from synth.dataset.reader import iter_frames, rays

    for frame in iter_frames("DIR"):            # a dataset, one shard directory, a .tar, or a stream
        o, d = rays(frame)                       # (H, W, 3) world-space origins and unit directions
        rgb, alpha = frame.rgb, frame.alpha      # straight colour and coverage, float32

Sources:

- a dataset directory: every *committed* shard, directory (``DIR/shards/<shard>/``) or tar
  (``DIR/shards/<shard>.tar`` with its manifest ``<shard>.tar.json``), in shard-id order, frames
  in key order; staging directories are never read;
- one shard directory (committed or not: any ``KEY.json`` with its ``KEY.exr``);
- a tar file or any binary stream of a tar (WebDataset style: members ``[prefix/]KEY.json`` and
  ``[prefix/]KEY.exr``, the two of a frame adjacent or not), read in one forward pass;
- an iterable of WebDataset sample dicts (``{"__key__": KEY, "json": bytes, "exr": bytes}``);
  :func:`decode_sample` decodes one, e.g. ``webdataset.WebDataset(urls).map(decode_sample)``.

Thread- and fork-safe: decoding works on bytes in memory and never redirects stdout/stderr, so
frames can be read from several threads or DataLoader workers at once. Schema validation is
optional (``validate=True``) and off by default, since it costs more than the decode.

Cameras follow :mod:`synth.conventions` (OpenCV axes: x right, y down, z forward; ``K`` in
pixels with the image's top-left *corner* at (0, 0), so the centre of pixel (column i, row j)
is at (i + 0.5, j + 0.5)). :func:`rays` shoots through pixel centres.
"""

from __future__ import annotations

import os
import sys
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
                                  SHARD_ID_RE, SHARDS_DIR)
from synth.dataset.tarshard import MAX_MEMBER_BYTES, TAR_MANIFEST_SUFFIX, TAR_SUFFIX, manifest_paths, read_member
from synth.errors import SynthError
from synth.io import FileRefused, loads_json, read_bounded, read_json


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

    @property
    def environment_index(self) -> int:
        """The lighting environment the view is rendered in (0 in a dataset of one environment per
        expression); ``meta["lighting"]`` describes it."""
        return int(self.meta.get("environment_index", 0))
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
    jb, eb = _frame_file(p, MAX_FRAME_JSON_BYTES), _frame_file(p.with_suffix(".exr"), MAX_EXR_BYTES)
    return decode_frame(jb, eb, key=p.stem, shard=shard or p.parent.name, validate=validate, where=str(p))


def _frame_file(path: Path, max_bytes: int) -> bytes:
    """A frame file's bytes (a regular file of at most ``max_bytes``), or a :class:`SynthError`."""
    try:
        return read_bounded(path, max_bytes)
    except FileNotFoundError as e:
        raise SynthError("frame file not found", str(e.filename), "check the path (or re-render the frame)") from None
    except FileRefused as e:
        raise SynthError(f"frame file refused: it {e.what}", os.fsdecode(e.path), "re-render the frame") from None


# --------------------------------------------------------------------------- listing


class TarMembers(NamedTuple):
    """Where a frame's two files are inside a tar shard: (offset, size) of each member's data."""

    tar: Path
    json: tuple[int, int]
    exr: tuple[int, int]


class FrameRef(NamedTuple):
    """Where one frame lives on disk (for random access and samplers).

    ``json_path`` is ``KEY.json`` of a directory shard; for a tar shard it is the tar's path
    joined with the member name (a name for messages, not a file to open) and ``tar`` locates
    the members. Use :meth:`json_bytes`, :meth:`exr_bytes` and :meth:`read` for either form.
    """

    shard: str
    key: str
    json_path: Path
    tar: TarMembers | None = None

    def json_bytes(self) -> bytes:
        if self.tar is not None:
            if self.tar.json[1] > MAX_FRAME_JSON_BYTES:  # the manifest's size, checked before reading
                raise SynthError(f"frame JSON of {self.tar.json[1]} bytes (limit {MAX_FRAME_JSON_BYTES})",
                                 str(self.json_path), "run `synth validate` on the dataset")
            return read_member(self.tar.tar, *self.tar.json, where=str(self.json_path))
        return _frame_file(self.json_path, MAX_FRAME_JSON_BYTES)

    def exr_bytes(self) -> bytes:
        if self.tar is not None:
            return read_member(self.tar.tar, *self.tar.exr, where=str(self.json_path.with_suffix(".exr")))
        return _frame_file(self.json_path.with_suffix(".exr"), MAX_EXR_BYTES)

    def meta(self) -> dict:
        """The frame JSON alone (no pixels decoded)."""
        try:
            return loads_json(self.json_bytes())
        except ValueError as e:
            raise SynthError(f"frame JSON does not parse: {str(e)[:120]}", str(self.json_path),
                             "run `synth validate` on the dataset") from None

    def read(self, *, validate: bool = False) -> Frame:
        if self.tar is None:
            return read_frame(self.json_path, shard=self.shard, validate=validate)
        return decode_frame(self.json_bytes(), self.exr_bytes(), key=self.key, shard=self.shard, validate=validate,
                            where=str(self.json_path))


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


def _tar_refs(manifest_path: Path, shard: str) -> list[FrameRef]:
    """The frames of a committed tar shard, located by its manifest's member offsets."""
    tar = manifest_path.with_name(shard + TAR_SUFFIX)
    try:
        m = read_json(manifest_path, max_bytes=MAX_MANIFEST_BYTES, follow_symlinks=False)
        files = m["files"]
        out = []
        for k in sorted(str(k) for k in m["frames"] if FRAME_KEY_RE.match(str(k))):
            j, e = files[f"{k}.json"], files[f"{k}.exr"]
            out.append(FrameRef(shard, k, tar / f"{k}.json",
                                TarMembers(tar, (j["offset"], j["bytes"]), (e["offset"], e["bytes"]))))
        return out
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise SynthError(f"tar shard manifest is unusable ({type(e).__name__}: {str(e)[:80]})", str(manifest_path),
                         "run `synth validate` on the dataset") from None


def list_frames(source, *, shards: Iterable[str] | None = None) -> list[FrameRef]:
    """Every frame of a dataset directory (committed shards, directories or tars) or of one
    shard directory, sorted by (shard, key). ``shards`` restricts a dataset to those shard ids."""
    return [r for refs in shard_frames(source, shards=shards) for r in refs]


def shard_frames(source, *, shards: Iterable[str] | None = None) -> Iterator[list[FrameRef]]:
    """:func:`list_frames` one shard at a time (a list per shard, in shard order): a pass over a
    large dataset holds one shard's references, not 585,000. Missing ``shards`` are refused
    before the first list."""
    root = Path(source)
    if not root.is_dir():
        raise SynthError("not a dataset or shard directory", str(root), "pass the --out directory of synth render")
    if not (root / SHARDS_DIR).is_dir():
        return iter([[FrameRef(root.name, k, root / f"{k}.json") for k in _shard_keys(root)]])
    wanted = set(shards) if shards is not None else None
    found: dict[str, Path] = {}
    for sid, mp in manifest_paths(root):  # a shard in both forms (a defect): its directory
        if (wanted is None or sid in wanted) and mp.is_file():
            found.setdefault(sid, mp)
    if wanted is not None and len(found) != len(wanted):
        missing = sorted(wanted - set(found))
        raise SynthError(f"shard(s) not committed in this dataset: {', '.join(missing[:5])}", str(root),
                         "render them first, or leave them out")
    return (_tar_refs(mp, sid) if mp.name.endswith(TAR_MANIFEST_SUFFIX)
            else [FrameRef(sid, k, mp.parent / f"{k}.json") for k in _shard_keys(mp.parent)]
            for sid, mp in sorted(found.items()))


# --------------------------------------------------------------------------- iteration


def _iter_tar(stream: IO[bytes], validate: bool, where: str, shard: str | None = None) -> Iterator[Frame]:
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
            limit = MAX_FRAME_JSON_BYTES if ext == "json" else MAX_MEMBER_BYTES  # a frame JSON's bound, as on disk
            if m.size > limit:
                raise SynthError(f"tar member {m.name} has {m.size} bytes (limit {limit})", where,
                                 "this is not a synth frame; check the tar")
            data = tf.extractfile(m).read()  # type: ignore[union-attr]
            parts = pending.setdefault(stem, {})
            parts[ext] = data
            if len(parts) == 2:
                del pending[stem]
                prefix = m.name.rsplit("/", 2)[-2] if m.name.count("/") else shard
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
        if p.is_file():  # a tar; one named like a tar shard (shard_000042.tar) names the frames' shard
            sid = p.name[:-len(TAR_SUFFIX)] if p.name.endswith(TAR_SUFFIX) else None
            with open(p, "rb") as f:
                yield from _iter_tar(f, validate, str(p), sid if sid and SHARD_ID_RE.match(sid) else None)
            return
        for ref in list_frames(p, shards=shards):
            yield ref.read(validate=validate)
        return
    if hasattr(source, "read"):
        yield from _iter_tar(source, validate, getattr(source, "name", "<stream>"))
        return
    for sample in source:
        yield decode_sample(sample, validate=validate)


def decode_sample(sample: dict, *, validate: bool = False) -> Frame:
    """A :class:`Frame` from one WebDataset sample ``{"__key__": KEY, "json": bytes, "exr":
    bytes}`` (undecoded, as ``webdataset.WebDataset(urls)`` yields them): the reader's bytes
    decoder, e.g. ``WebDataset(urls).map(decode_sample)``. The shard is taken from
    ``__url__`` when it names a tar shard (``.../shard_000042.tar``)."""
    key = sample.get("__key__")
    if not isinstance(sample.get("json"), (bytes, bytearray)) or not isinstance(sample.get("exr"), (bytes, bytearray)):
        raise SynthError(f"sample {key!r} lacks 'json' or 'exr' bytes", "<samples>",
                         "pass undecoded WebDataset samples with both members (no .decode())")
    k = str(key).rsplit("/", 1)[-1] if key is not None else None
    url = str(sample.get("__url__") or "")
    name = url.rsplit("/", 1)[-1]
    sid = name[:-len(TAR_SUFFIX)] if name.endswith(TAR_SUFFIX) else ""
    return decode_frame(bytes(sample["json"]), bytes(sample["exr"]), key=k,
                        shard=sid if SHARD_ID_RE.match(sid) else None, validate=validate,
                        where=f"{url or '<samples>'}:{key}")


def by_worker(items: Iterable) -> Iterator:
    """This ``torch.utils.data.DataLoader`` worker's share of ``items``: every ``num_workers``-th
    item, from the worker's id on, so that the workers together yield each item exactly once
    whatever the number of shards (all items outside a worker). Split before decoding, e.g.
    ``WebDataset(urls, shardshuffle=False, workersplitter=None, empty_check=False)
    .compose(by_worker).map(decode_sample)``, or ``by_worker(list_frames(DIR))`` in an
    ``IterableDataset`` (docs/reading.md, "DataLoader workers")."""
    torch = sys.modules.get("torch")  # a DataLoader worker has imported torch; nothing else needs it
    info = torch.utils.data.get_worker_info() if torch is not None else None
    if info is None or info.num_workers <= 1:
        yield from items
        return
    for n, item in enumerate(items):
        if n % info.num_workers == info.id:
            yield item


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
    ``R_c2w @ normalise(K^-1 @ [i + 0.5, j + 0.5, 1])``. Several cameras at once: ``K`` (B, 3, 3),
    ``camera_to_world`` (B, 4, 4) and ``pixels`` of shape (B, N) give (B, N, 3) outputs.
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
    lead = (slice(None),) * (K.ndim - 2) + (None,) * (uu.ndim - (K.ndim - 2))  # camera axes, then pixel axes
    # K^-1 for a camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] (skew allowed)
    fx, s, cx, fy, cy = (K[..., a, b][lead] for a, b in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2)))
    y = (vv - cy) / fy
    x = (uu - cx - s * y) / fx
    inv_norm = 1.0 / np.sqrt(x * x + y * y + 1.0)
    R = c2w[..., :3, :3][lead]
    d = (x * inv_norm)[..., None] * R[..., 0] + (y * inv_norm)[..., None] * R[..., 1] + inv_norm[..., None] * R[..., 2]
    o = np.broadcast_to(c2w[..., :3, 3][lead], d.shape)
    return Rays(o.astype(dtype), d.astype(dtype), inv_norm.astype(dtype))


def rays(frame: Frame, *, pixels=None, dtype=np.float32) -> Rays:
    """Per-pixel world-space rays of a frame (see :func:`camera_rays`)."""
    return camera_rays(frame.K, frame.camera_to_world, frame.width, frame.height, pixels=pixels, dtype=dtype)


__all__ = ["Frame", "FrameRef", "Rays", "TarMembers", "by_worker", "camera_rays", "decode_frame", "decode_sample",
           "iter_frames", "list_frames", "read_frame", "rays", "shard_frames"]
