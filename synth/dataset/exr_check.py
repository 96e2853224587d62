"""Checks on the bytes of an EXR file, made before OpenEXR decodes them.

OpenEXR reports a damaged file by printing (the C library on stderr, its Python binding on
stdout) before it raises, and the only way to silence that is to redirect file descriptor 2
for the whole process, which is not safe in threads or DataLoader workers. So the readers
check the bytes first, in plain Python: the magic number and version, the header attributes
the frame format needs, the offset table and every chunk's leader (its first line and its
size lie inside the file), and, with ``inflate``, that every ZIP chunk inflates to exactly
its size. Bytes that pass are a complete file whose ZIP (or uncompressed) pixel data decodes,
so OpenEXR reads them without printing anything.

Only what frame EXRs use is accepted: one part, scanlines, no deep data. Layout facts from
the OpenEXR file format specification ("OpenEXR File Layout").
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

MAGIC = b"\x76\x2f\x31\x01"
_TILED, _LONG_NAMES, _DEEP, _MULTIPART = 0x200, 0x400, 0x800, 0x1000
NO_COMPRESSION, ZIPS_COMPRESSION, ZIP_COMPRESSION = 0, 2, 3
#: Scanlines per chunk for each compression (OpenEXR's enum values); others are not checked.
LINES_PER_CHUNK = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}
#: Bytes per sample of the pixel types UINT, HALF, FLOAT.
SAMPLE_BYTES = {0: 4, 1: 2, 2: 4}
#: Sizes of the fixed-size attribute types.
TYPE_SIZES = {"box2i": 16, "box2f": 16, "chromaticities": 32, "compression": 1, "double": 8, "envmap": 1,
              "float": 4, "int": 4, "keycode": 28, "lineOrder": 1, "m33f": 36, "m44f": 64, "rational": 8,
              "tiledesc": 9, "timecode": 8, "v2f": 8, "v2i": 8, "v3f": 12, "v3i": 12}
#: The attributes every OpenEXR header has, with their types.
REQUIRED = {"channels": "chlist", "compression": "compression", "dataWindow": "box2i", "displayWindow": "box2i",
            "lineOrder": "lineOrder", "pixelAspectRatio": "float", "screenWindowCenter": "v2f",
            "screenWindowWidth": "float"}
#: Largest image side accepted (far above any render; bounds the memory a damaged header asks for).
MAX_SIDE = 1 << 14


class ExrDamaged(ValueError):
    """The bytes are not a complete single-part scanline EXR (the message says what is wrong)."""


@dataclass(frozen=True)
class ExrLayout:
    width: int
    height: int
    compression: int
    #: name -> pixel type (0 UINT, 1 HALF, 2 FLOAT)
    channels: dict[str, int]
    #: (file offset, first line, packed size) of each chunk, in line order
    chunks: tuple[tuple[int, int, int], ...]
    #: every channel has one sample per pixel (no subsampling)
    plain: bool = True
    #: the header's string attributes, name -> text
    strings: tuple[tuple[str, str], ...] = ()


def _utf8(raw: bytes, what: str) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ExrDamaged(f"header is damaged ({what} is not UTF-8)") from None


def _cstring(data: bytes, pos: int, max_len: int) -> tuple[str, int]:
    end = data.find(b"\0", pos, pos + max_len + 1)
    if end < 0:
        raise ExrDamaged("header is truncated or damaged (a name does not end)")
    return _utf8(data[pos:end], "a name"), end + 1


def _attributes(data: bytes, max_name: int) -> tuple[dict[str, tuple[str, bytes]], int]:
    attrs: dict[str, tuple[str, bytes]] = {}
    pos = 8
    while True:
        if pos >= len(data):
            raise ExrDamaged("header is truncated")
        if data[pos] == 0:
            return attrs, pos + 1
        name, pos = _cstring(data, pos, max_name)
        kind, pos = _cstring(data, pos, max_name)
        if pos + 4 > len(data):
            raise ExrDamaged("header is truncated")
        (size,) = struct.unpack_from("<i", data, pos)
        pos += 4
        if size < 0 or pos + size > len(data):
            raise ExrDamaged(f"header is truncated or damaged (attribute {name!r})")
        if TYPE_SIZES.get(kind, size) != size:
            raise ExrDamaged(f"header is damaged (attribute {name!r} of type {kind} has {size} bytes)")
        attrs[name] = (kind, data[pos:pos + size])
        if kind == "string":  # the binding turns these into str
            _utf8(attrs[name][1], f"attribute {name!r}")
        pos += size


def _channels(value: bytes) -> list[tuple[str, int, int, int]]:
    out, pos = [], 0
    while pos < len(value) and value[pos] != 0:
        name, pos = _cstring(value, pos, 255)
        if pos + 16 > len(value):
            raise ExrDamaged("header is damaged (channel list)")
        ptype, _, xs, ys = struct.unpack_from("<iB3xii", value, pos)
        if ptype not in SAMPLE_BYTES:
            raise ExrDamaged(f"header is damaged (channel {name!r} has pixel type {ptype})")
        out.append((name, ptype, xs, ys))
        pos += 16
    return out




def check_exr_bytes(data: bytes, *, inflate: bool = False) -> ExrLayout:
    """Check ``data`` as a frame EXR (see the module docstring); raises :class:`ExrDamaged`.

    ``inflate``: also inflate every ZIP/ZIPS chunk to exactly its size (zlib checks the stream's
    Adler-32) and check uncompressed chunks' sizes, so that damaged pixel data is caught here
    too. Adler-32 misses some rare changes (two swapped bytes): those decode, to wrong pixels,
    and only a checksum of the file (the shard manifest's sha256) can tell.
    """
    if len(data) < 8 or data[:4] != MAGIC:
        raise ExrDamaged("not an OpenEXR file (bad magic number)")
    (version,) = struct.unpack_from("<i", data, 4)
    if version & 0xFF != 2 or version & (_TILED | _DEEP | _MULTIPART):
        raise ExrDamaged(f"not a single-part scanline OpenEXR 2 file (version field {version:#x})")
    attrs, pos = _attributes(data, 255 if version & _LONG_NAMES else 31)
    for name, kind in REQUIRED.items():
        if attrs.get(name, ("",))[0] != kind:
            raise ExrDamaged(f"header lacks the {name!r} attribute")
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"][1])
    compression = attrs["compression"][1][0]
    if attrs["lineOrder"][1][0] > 2:
        raise ExrDamaged(f"header is damaged (line order {attrs['lineOrder'][1][0]})")
    channels = _channels(attrs["channels"][1])
    width, height = x1 - x0 + 1, y1 - y0 + 1
    if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
        raise ExrDamaged(f"header has an implausible data window ({width}x{height})")
    types = {name: ptype for name, ptype, _, _ in channels}
    plain = all(xs == 1 and ys == 1 for _, _, xs, ys in channels)
    strings = tuple((name, value.decode("utf-8")) for name, (kind, value) in attrs.items() if kind == "string")
    lines = LINES_PER_CHUNK.get(compression)
    if lines is None:  # a compression frame EXRs never use: leave the pixel data to OpenEXR
        return ExrLayout(width, height, compression, types, (), plain, strings)
    count = -(-height // lines)
    table_end = pos + 8 * count
    if table_end > len(data):
        raise ExrDamaged(f"pixel data does not decode (the file ends inside the offset table, at byte {len(data)})")
    line_bytes = width * sum(SAMPLE_BYTES[ptype] for _, ptype, _, _ in channels)
    chunks = []
    for i, offset in enumerate(struct.unpack_from(f"<{count}Q", data, pos)):
        first = y0 + i * lines
        if offset < table_end or offset + 8 > len(data):
            raise ExrDamaged(f"pixel data does not decode (chunk {i} of {count} lies outside the file; "
                             f"the file is {len(data)} bytes)")
        y, size = struct.unpack_from("<ii", data, offset)
        if y != first or size <= 0 or offset + 8 + size > len(data):
            raise ExrDamaged(f"pixel data does not decode (chunk {i} of {count}: line {y}, {size} bytes at byte "
                             f"{offset + 8}; the file is {len(data)} bytes)")
        chunks.append((offset, y, size))
        if inflate and plain:
            _check_chunk(data, offset + 8, size, line_bytes * min(lines, y1 - y + 1), compression, i)
    by_offset = sorted(chunks)
    for (offset, _, size), (following, _, _) in zip(by_offset, by_offset[1:]):
        if offset + 8 + size > following:
            raise ExrDamaged(f"pixel data does not decode (the chunk at byte {offset} overlaps the next one)")
    return ExrLayout(width, height, compression, types, tuple(chunks), plain, strings)


def _check_chunk(data: bytes, start: int, size: int, raw: int, compression: int, index: int) -> None:
    """A chunk holds ``raw`` bytes, stored as they are (when compressing did not help) or deflated."""
    if size == raw or compression not in (NO_COMPRESSION, ZIPS_COMPRESSION, ZIP_COMPRESSION):
        return
    if compression == NO_COMPRESSION or size > raw:
        raise ExrDamaged(f"pixel data does not decode (chunk {index} has {size} bytes, expected at most {raw})")
    inflater = zlib.decompressobj()
    try:
        n = len(inflater.decompress(memoryview(data)[start:start + size], raw + 1))
    except zlib.error as e:
        raise ExrDamaged(f"pixel data does not decode (chunk {index}: {e})") from None
    if n != raw or not inflater.eof or inflater.unused_data:
        raise ExrDamaged(f"pixel data does not decode (chunk {index} inflates to {n} bytes, expected {raw})")
