"""One multi-layer EXR per frame: the pixel half of the frame format (docs/frame-format.md).

Channels (one single-part scanline file, sorted by name as OpenEXR stores them):

=================  ======  ==========================================================
``R G B A``        HALF    scene-linear Rec.709 primaries, D65 white, premultiplied
                           alpha (Cycles' film output); RGB clamped to +-65504
``depth.Z``        FLOAT   camera-space z along the optical axis, metres (planar
                           depth, not ray length); ``0.0`` = no surface (background)
``normal.X/Y/Z``   HALF    unit surface normal in world space (Blender world: Z up,
                           metres); ``(0, 0, 0)`` = background
``segmentation.id`` UINT   class ID from :mod:`synth.dataset.segmentation` (0 = background),
                           the integer itself: not normalised, not a colour
=================  ======  ==========================================================

The header carries ``chromaticities`` (Rec.709 primaries, D65 white) and
``colorInteropID = "lin_rec709_scene"``, the conventions as string attributes
(``synthFormat``, ``depthConvention``, ``normalConvention``, ``segmentationConvention``),
the camera as OpenEXR's standard ``worldToCamera`` and ``worldToNDC`` matrices when the
caller passes them (:func:`camera_attributes`; the worker does), and any string/int/float
attributes the caller passes (e.g. the frame key). Compression is ZIP (lossless, readable by
every OpenEXR >= 1.x reader; see docs/frame-format.md for the size/speed comparison).

Writes are atomic (temp file, fsync, rename): a reader sees the complete file or none.
Reads take a path or the bytes (:func:`decode_frame_exr`) and are safe in threads: the bytes
are checked by :mod:`synth.dataset.exr_check` before OpenEXR decodes them.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from synth.dataset.exr_check import ExrDamaged, check_exr_bytes
from synth.dataset.exr_zip import TYPE_NAMES, decode_planes
from synth.dataset.segmentation import NAMES
from synth.errors import SynthError
from synth.dataset.layout import MAX_EXR_BYTES
from synth.io import FileRefused, atomic_write_bytes, read_bounded

FORMAT = "synth-frame-exr/1"
HALF_MAX = 65504.0
#: Depth values at or above this (and +inf) are background: Cycles writes 1e10 there.
BACKGROUND_DEPTH_THRESHOLD = 1e9
#: The value a stored frame EXR holds for "no surface" in ``depth.Z`` (and what the readers
#: return). The worker's pass arrays use +inf (``blender_scripts.passes.PASS_BACKGROUND_DEPTH``);
#: the writer maps every value at or above :data:`BACKGROUND_DEPTH_THRESHOLD` to this one.
STORED_BACKGROUND_DEPTH = 0.0

RGBA_CHANNELS = ("R", "G", "B", "A")
DEPTH_CHANNEL = "depth.Z"
NORMAL_CHANNELS = ("normal.X", "normal.Y", "normal.Z")
SEG_CHANNEL = "segmentation.id"
#: Every channel of a frame EXR, in the order used for ``image.layers`` in the frame JSON.
CHANNELS: tuple[str, ...] = RGBA_CHANNELS + (DEPTH_CHANNEL,) + NORMAL_CHANNELS + (SEG_CHANNEL,)

#: Linear Rec.709 / sRGB primaries with a D65 white point, in OpenEXR's 8-tuple order.
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
COLOR_INTEROP_ID = "lin_rec709_scene"
DEPTH_CONVENTION = "camera-space z along the optical axis (OpenCV camera, +z forward), metres; 0 = background"
NORMAL_CONVENTION = "unit normal, world space (Blender world, Z up); 0,0,0 = background"
SEGMENTATION_CONVENTION = ("UINT class id, the integer itself (not normalised to [0, 1]); 0 = background; "
                           "ids: synth.dataset.segmentation")
#: OpenEXR's standard camera attributes (ImfStandardAttributes.h), stored as M44f.
CAMERA_ATTRIBUTES = ("worldToCamera", "worldToNDC")

_RESERVED = {"channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
             "screenWindowCenter", "screenWindowWidth", "type", "chromaticities", "colorInteropID",
             "synthFormat", "depthConvention", "normalConvention", "segmentationConvention", "name", "tiles",
             "version", "chunkCount"}


def _openexr():
    try:
        import OpenEXR
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise SynthError("the OpenEXR Python package is not installed", None,
                         "install it with `.venv/bin/pip install 'OpenEXR>=3.3'` (or `make setup`)") from e
    if not hasattr(OpenEXR, "File"):  # pragma: no cover
        raise SynthError(f"OpenEXR {getattr(OpenEXR, '__version__', '?')} is too old (no OpenEXR.File)", None,
                         "install OpenEXR>=3.3")
    return OpenEXR


def _check_array(name: str, a: Any, shape: tuple, where: str) -> np.ndarray:
    a = np.asarray(a)
    if a.shape != shape:
        raise SynthError(f"{name} has shape {a.shape}, expected {shape}", where, "pass arrays of one image size")
    return a


def encode_frame_exr(rgba, depth, normals, segmentation, header: dict | None = None, *,
                     where: str = "<memory>", compression: str = "ZIP") -> bytes:
    """Validate and encode one frame to EXR bytes (see :func:`write_frame_exr`)."""
    OpenEXR = _openexr()
    rgba = np.asarray(rgba)
    if rgba.ndim != 3 or rgba.shape[2] != 4 or rgba.shape[0] < 1 or rgba.shape[1] < 1:
        raise SynthError(f"rgba has shape {rgba.shape}, expected (H, W, 4)", where, "pass an RGBA image")
    h, w = rgba.shape[:2]
    depth = _check_array("depth", depth, (h, w), where)
    normals = _check_array("normals", normals, (h, w, 3), where)
    seg = _check_array("segmentation", segmentation, (h, w), where)
    for name, a in (("rgba", rgba), ("depth", depth), ("normals", normals)):
        if a.dtype.kind not in "fiu":
            raise SynthError(f"{name} has dtype {a.dtype}, expected a float array", where, "pass float pixels")
        if a.dtype.kind == "f" and np.isnan(a).any():
            n = int(np.isnan(a).sum())
            raise SynthError(f"{name} contains {n} NaN pixel value(s); refusing to write", where,
                             "fix the render (NaNs are never stored)")
    if np.isinf(rgba).any() or np.isinf(normals).any():
        raise SynthError("rgba or normals contain infinite values; refusing to write", where,
                         "clamp the render output (fireflies) before writing")
    if seg.dtype.kind not in "iu" or (seg.size and (int(seg.min()) < 0 or int(seg.max()) > 0xFFFFFFFF)):
        raise SynthError(f"segmentation must hold non-negative integer class IDs (dtype {seg.dtype})", where,
                         "pass an integer array of synth.dataset.segmentation IDs")
    d = depth.astype(np.float32)  # float64 -> float32 first, so 1e10 stays "large", not inf
    if (d < 0).any():
        raise SynthError(f"depth has {int((d < 0).sum())} negative value(s) (camera-space z must be >= 0)",
                         where, "store z along the optical axis in metres (background: 0 or +inf)")
    d = np.where(d >= BACKGROUND_DEPTH_THRESHOLD, np.float32(STORED_BACKGROUND_DEPTH), d).astype(np.float32)

    c = rgba.astype(np.float32)
    c[..., :3] = np.clip(c[..., :3], -HALF_MAX, HALF_MAX)
    c[..., 3] = np.clip(c[..., 3], 0.0, 1.0)
    c16 = c.astype(np.float16)
    n16 = np.clip(normals.astype(np.float32), -1.0, 1.0).astype(np.float16)
    channels = {name: np.ascontiguousarray(c16[..., i]) for i, name in enumerate(RGBA_CHANNELS)}
    channels[DEPTH_CHANNEL] = np.ascontiguousarray(d)
    for i, name in enumerate(NORMAL_CHANNELS):
        channels[name] = np.ascontiguousarray(n16[..., i])
    channels[SEG_CHANNEL] = np.ascontiguousarray(seg.astype(np.uint32))

    try:
        comp = getattr(OpenEXR, f"{compression.upper()}_COMPRESSION")
    except AttributeError:
        raise SynthError(f"unknown EXR compression {compression!r}", where, "use ZIP, PIZ, ZIPS or NO") from None
    hdr: dict[str, Any] = {
        "compression": comp,
        "type": OpenEXR.scanlineimage,
        "chromaticities": REC709_CHROMATICITIES,
        "colorInteropID": COLOR_INTEROP_ID,
        "synthFormat": FORMAT,
        "depthConvention": DEPTH_CONVENTION,
        "normalConvention": NORMAL_CONVENTION,
        "segmentationConvention": SEGMENTATION_CONVENTION,
    }
    for k, v in (header or {}).items():
        if not isinstance(k, str) or not k or k in _RESERVED:
            raise SynthError(f"EXR header attribute name {k!r} is reserved or invalid", where,
                             "pick another attribute name")
        if k in CAMERA_ATTRIBUTES:
            m = np.asarray(v)
            if m.shape != (4, 4) or m.dtype != np.float32 or not np.isfinite(m).all():
                raise SynthError(f"EXR header attribute {k!r} must be a finite 4x4 float32 matrix", where,
                                 "make it with synth.dataset.exr.camera_attributes")
            hdr[k] = np.ascontiguousarray(m)
            continue
        if isinstance(v, bool) or not isinstance(v, (str, int, float)):
            raise SynthError(f"EXR header attribute {k!r} has type {type(v).__name__}", where,
                             "pass str, int or float values (put structured data in the frame JSON)")
        hdr[k] = v
    buf = io.BytesIO()
    OpenEXR.File(hdr, channels).write(buf)
    return buf.getvalue()


def camera_attributes(K, world_to_camera, width: int, height: int) -> dict[str, np.ndarray]:
    """OpenEXR's standard camera attributes of a frame, ready for the ``header`` argument.

    ``worldToCamera`` maps world points to OpenEXR's camera space (x right, y up, z forward,
    left-handed); ``worldToNDC`` maps them to the image plane with (0, 0) and (1, 1) at its
    top-left and bottom-right corners (:func:`synth.conventions.exr_world_to_ndc`). Imath
    multiplies row vectors (``p' = p M``, translation in the last row), so the stored matrices
    are the transposes of the column-vector ones; :func:`read_camera_attributes` undoes that.
    """
    from synth.conventions import exr_world_to_camera, exr_world_to_ndc

    return {"worldToCamera": exr_world_to_camera(world_to_camera).T.astype(np.float32),
            "worldToNDC": exr_world_to_ndc(K, world_to_camera, width, height).T.astype(np.float32)}


def read_camera_attributes(header: dict) -> dict[str, np.ndarray] | None:
    """The column-vector (4, 4) float64 ``worldToCamera`` and ``worldToNDC`` of a header read by
    :func:`read_frame_exr` (its ``"header"``), or None when the file has none."""
    if not all(k in header for k in CAMERA_ATTRIBUTES):
        return None
    return {k: np.asarray(header[k], np.float64).reshape(4, 4).T for k in CAMERA_ATTRIBUTES}


def write_frame_exr(path, rgba, depth, normals, segmentation, header: dict | None = None, *,
                    durable: bool = True, compression: str = "ZIP") -> int:
    """Write one frame's EXR atomically; returns the file size in bytes.

    - ``rgba``: (H, W, 4) float, scene-linear Rec.709, premultiplied alpha. Stored as HALF: RGB
      is clamped to +-65504 (half max; larger finite values would become inf), alpha to [0, 1].
      NaN or inf anywhere is refused (:class:`SynthError`), never silently stored.
    - ``depth``: (H, W) camera-space z in metres (float). Values >= 1e9 or +inf (Cycles writes
      1e10 where no surface was hit) are stored as ``0.0`` = background. NaN or negative: refused.
    - ``normals``: (H, W, 3) world-space unit normals (Blender world, Z up), stored as HALF.
    - ``segmentation``: (H, W) integer class IDs (:mod:`synth.dataset.segmentation`), stored as UINT.
    - ``header``: extra attributes (str -> str | int | float), e.g. ``{"synthFrameKey": key}``,
      and the camera attributes of :func:`camera_attributes`.
    """
    path = Path(path)
    data = encode_frame_exr(rgba, depth, normals, segmentation, header, where=str(path), compression=compression)
    atomic_write_bytes(path, data, durable=durable)
    return len(data)


def _plain(v):
    """Header values as plain Python (JSON-friendly) types."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    name = getattr(v, "name", None)
    return name if isinstance(name, str) else str(v)


def _bytes(source, where: str | None) -> tuple[bytes, str]:
    """The bytes of ``source`` (bytes-like, or a path to read) and a name for messages."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source), where or "<bytes>"
    path = Path(source)
    try:
        return read_bounded(path, MAX_EXR_BYTES), where or str(path)
    except FileNotFoundError:
        raise SynthError("EXR file not found", str(path), "check the path (or re-render the frame)") from None
    except FileRefused as e:
        raise SynthError(f"EXR file refused: it {e.what}", str(path), "re-render the frame") from None
    except OSError as e:
        raise SynthError(f"cannot read EXR ({e.strerror})", str(path), "check the file's permissions") from None


def _open(data: bytes, where: str, header_only: bool, verify: bool):
    """OpenEXR's header and channels of checked bytes (:mod:`synth.dataset.exr_check` first, so
    that a damaged file is reported by that check rather than printed about by OpenEXR)."""
    OpenEXR = _openexr()
    try:
        check_exr_bytes(data, inflate=verify and not header_only)
        f = OpenEXR.File(io.BytesIO(data), separate_channels=True, header_only=header_only)
        hdr = f.header()
        chans = {} if header_only else f.channels()
    except Exception as e:  # ExrDamaged, or what the binding raises (RuntimeError/ValueError)
        raise _unreadable(e, where) from None
    return hdr, chans


def _unreadable(e: Exception, where: str) -> SynthError:
    """The one-line error of bytes that do not read as an EXR."""
    msg = str(e).splitlines()[0] if str(e) else type(e).__name__
    if "has 0 parts" in msg:
        msg = "pixel data does not decode"
    return SynthError(f"cannot read EXR: {msg}", where, "the file is corrupt or truncated; re-render the frame")


def read_frame_exr_header(source, *, where: str | None = None) -> dict:
    """Only the header of a frame EXR (a path or its bytes): ``{"width", "height", "channels":
    {name: None}, "header": {...}, "path"}``. The file's structure is checked, not its pixels."""
    data, where = _bytes(source, where)
    hdr, _ = _open(data, where, header_only=True, verify=False)
    return _describe(hdr, where)


def _describe(hdr: dict, where: str, chans: dict | None = None) -> dict:
    (x0, y0), (x1, y1) = (np.asarray(hdr["dataWindow"][0]).tolist(), np.asarray(hdr["dataWindow"][1]).tolist())
    if chans:
        types = {name: c.type().name for name, c in chans.items()}
    else:  # header-only reads carry no pixel types in this binding
        types = {c.name: None for c in hdr.get("channels", [])}
    plain = {k: _plain(v) for k, v in hdr.items() if k != "channels"}
    return {"path": where, "width": int(x1 - x0 + 1), "height": int(y1 - y0 + 1), "channels": types,
            "header": plain}


def read_frame_exr(source, *, verify: bool = False, where: str | None = None) -> dict:
    """Read a frame EXR written by :func:`write_frame_exr`, from a path or from its bytes.

    Returns ``{"rgba": (H,W,4) float16, "depth": (H,W) float32, "normals": (H,W,3) float16 or
    float32 (as stored), "segmentation": (H,W) uint32, "width", "height", "channels": {name:
    pixel type}, "header": {attribute: plain value}, "path"}`` (``path``: ``where``, else the
    path, else ``"<bytes>"``). Raises :class:`SynthError` for a missing, unreadable or truncated
    file or missing channels. Pixel values are returned as stored; checks on them (NaN, IDs)
    belong to ``synth validate``.

    Safe in threads and DataLoader workers: nothing process-wide is touched. A truncated or
    garbled file is rejected by our own checks before OpenEXR sees it; ``verify`` also inflates
    every chunk first (about twice the decode time), so that damaged pixel data is reported
    without OpenEXR printing about it (``synth validate`` and ``synth preview`` use it).
    """
    data, where = _bytes(source, where)
    return decode_frame_exr(data, where, verify=verify)


def decode_frame_exr(data: bytes, where: str = "<bytes>", *, verify: bool = False) -> dict:
    """:func:`read_frame_exr` of bytes already in memory (a shard file, a tar member)."""
    hdr, chans = _open(data, where, header_only=False, verify=verify)
    desc = _describe(hdr, where, chans)
    desc.update(_frame_arrays({name: c.pixels for name, c in chans.items()}, desc["width"], desc["height"], where))
    return desc


def _frame_arrays(planes: dict, w: int, h: int, where: str) -> dict:
    """``rgba``, ``depth``, ``normals`` and ``segmentation`` of a frame from its channels' (h, w)
    pixels; one clear error for a missing channel, a wrong size or a wrong pixel type."""
    missing = [c for c in CHANNELS if c not in planes]
    if missing:
        raise SynthError(f"EXR lacks channel(s) {', '.join(missing)}", where,
                         "it was not written by synth.dataset.exr.write_frame_exr; re-render the frame")
    for name in CHANNELS:
        p = planes[name]
        if p is None or p.shape != (h, w):
            raise SynthError(f"EXR channel {name} has no pixel data of size {w}x{h}", where,
                             "the file is corrupt; re-render the frame")
    out = {"rgba": np.stack([planes[c] for c in RGBA_CHANNELS], axis=-1), "depth": planes[DEPTH_CHANNEL],
           "normals": np.stack([planes[c] for c in NORMAL_CHANNELS], axis=-1), "segmentation": planes[SEG_CHANNEL]}
    types = {"rgba": out["rgba"].dtype, "depth": out["depth"].dtype, "segmentation": out["segmentation"].dtype}
    if types["segmentation"] != np.uint32 or types["depth"] != np.float32:
        raise SynthError(f"EXR channel types are wrong ({types})", where,
                         "depth.Z must be FLOAT and segmentation.id UINT; re-render the frame")
    return out


def verify_frame_exr(data: bytes, where: str = "<bytes>") -> dict:
    """What ``synth validate`` reads of a frame EXR in memory, every chunk checked to decode:
    ``{"width", "height", "channels": {name: pixel type}, "rgba", "depth", "normals",
    "segmentation", "frame_key"}`` (``frame_key``: the ``synthFrameKey`` attribute, else None),
    the arrays bit for bit those of :func:`decode_frame_exr` with ``verify``. Frames stored ZIP,
    ZIPS or uncompressed are decoded by :mod:`synth.dataset.exr_zip` from the bytes the check
    inflates (OpenEXR would inflate them again); others by OpenEXR."""
    try:
        layout = check_exr_bytes(data)
        planes = decode_planes(data, layout)
    except ExrDamaged as e:
        raise _unreadable(e, where) from None
    if planes is None:
        px = decode_frame_exr(data, where, verify=True)
        return {**{k: px[k] for k in ("width", "height", "channels", "rgba", "depth", "normals", "segmentation")},
                "frame_key": px["header"].get("synthFrameKey")}
    out = {"width": layout.width, "height": layout.height,
           "channels": {name: TYPE_NAMES[t] for name, t in layout.channels.items()}}
    out.update(_frame_arrays(planes, layout.width, layout.height, where))
    out["frame_key"] = dict(layout.strings).get("synthFrameKey")
    return out


def decode_channels(data: bytes, names: tuple[str, ...], where: str = "<bytes>") -> tuple[int, int, list]:
    """(width, height, the (H, W) pixels of each of ``names``) of a frame EXR in memory: what a
    pass that needs a few channels (depth and alpha for bounds) reads, without stacking the
    frame's arrays or converting its header. The same checks as :func:`decode_frame_exr`."""
    hdr, chans = _open(data, where, header_only=False, verify=False)
    (x0, y0), (x1, y1) = (np.asarray(hdr["dataWindow"][0]).tolist(), np.asarray(hdr["dataWindow"][1]).tolist())
    w, h = int(x1 - x0 + 1), int(y1 - y0 + 1)
    out = []
    for name in names:
        p = chans[name].pixels if name in chans else None
        if p is None or p.shape != (h, w):
            raise SynthError(f"EXR channel {name} has no pixel data of size {w}x{h}", where,
                             "the file is corrupt or was not written by synth; re-render the frame")
        out.append(p)
    return w, h, out


#: The largest segmentation ID when the known IDs are 0..N without gaps (else None).
_DENSE_MAX_ID = max(NAMES) if sorted(NAMES) == list(range(len(NAMES))) else None


def _pixels_clean(px: dict) -> bool:
    """Whether :func:`pixel_defects` finds nothing, decided with a few whole-array reductions
    (``synth validate`` runs it on every frame; the messages are only built when it is False)."""
    rgba, normals, depth, seg = px["rgba"], px["normals"], px["depth"], px["segmentation"]
    if _DENSE_MAX_ID is None or seg.dtype.kind != "u" or (seg.size and int(seg.max()) > _DENSE_MAX_ID):
        return False
    if not (np.isfinite(rgba).all() and np.isfinite(normals).all()):
        return False
    alpha = rgba[..., 3]
    with np.errstate(invalid="ignore"):  # NaN depth: the comparison is False, so not clean
        return bool((depth >= 0).all() and (depth < np.inf).all() and (alpha >= 0).all() and (alpha <= 1).all())


def pixel_defects(px: dict) -> list[str]:
    """Problems in the pixels of a frame read by :func:`synth.dataset.exr.read_frame_exr`."""
    if _pixels_clean(px):
        return []
    out = []
    rgba = px["rgba"].astype(np.float32)
    normals = px["normals"].astype(np.float32)
    depth = px["depth"]
    seg = px["segmentation"]
    for name, a in (("RGBA", rgba), ("normals", normals), ("depth", depth)):
        bad = ~np.isfinite(a)
        if bad.any():
            n_nan = int(np.isnan(a).sum())
            where = ""
            if name == "depth":
                where = f", {int((bad & (rgba[..., 3] > 0)).sum())} where alpha > 0"
            out.append(f"{name} has {n_nan} NaN and {int(bad.sum()) - n_nan} Inf value(s){where}")
    fin = np.isfinite(depth)
    if (depth[fin] < 0).any():
        out.append(f"depth has {int((depth[fin] < 0).sum())} negative value(s)")
    a = rgba[..., 3]
    if ((a < 0) | (a > 1)).any():
        out.append("alpha outside [0, 1]")
    ids = np.unique(seg)
    unknown = [int(i) for i in ids if int(i) not in NAMES]
    if unknown:
        out.append(f"segmentation has unknown class ID(s) {unknown[:5]} (known: 0..{max(NAMES)})")
    return out


__all__ = ["CHANNELS", "REC709_CHROMATICITIES", "HALF_MAX", "STORED_BACKGROUND_DEPTH", "BACKGROUND_DEPTH_THRESHOLD",
           "camera_attributes",
           "encode_frame_exr", "read_camera_attributes", "write_frame_exr", "read_frame_exr", "decode_frame_exr", "decode_channels", "verify_frame_exr",
           "read_frame_exr_header", "pixel_defects"]
