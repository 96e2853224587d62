"""The pixels of a checked frame EXR stored with ZIP, ZIPS or no compression, decoded in numpy.

``synth validate`` inflates every chunk of every frame to check it (:mod:`synth.dataset.exr_check`);
decoding the pixels from those same inflated bytes saves OpenEXR inflating them a second time. Each
chunk is either stored as it is (when deflating did not make it smaller) or a zlib stream of the
chunk's bytes after two reversible steps: a delta coding (each byte minus the previous one, plus
128, modulo 256) applied to the bytes reordered so that the even-indexed ones come first. Inside a
chunk the data is line by line, and in each line channel by channel in the header's (sorted) order,
``width`` samples each. Layout facts from the OpenEXR file format specification.

Anything else (another compression, subsampled channels) is left to OpenEXR (:func:`decode_planes`
returns None), and ``tests/dataset/test_exr_zip.py`` checks every array bit for bit against OpenEXR.
"""

from __future__ import annotations

import zlib

import numpy as np

from synth.dataset.exr_check import (LINES_PER_CHUNK, NO_COMPRESSION, SAMPLE_BYTES, ZIP_COMPRESSION, ZIPS_COMPRESSION,
                                     ExrDamaged, ExrLayout)

#: numpy dtypes and OpenEXR names of the pixel types UINT, HALF, FLOAT
DTYPES = {0: np.dtype("<u4"), 1: np.dtype("<f2"), 2: np.dtype("<f4")}
TYPE_NAMES = {0: "UINT", 1: "HALF", 2: "FLOAT"}
HANDLED = (NO_COMPRESSION, ZIPS_COMPRESSION, ZIP_COMPRESSION)


def _unpredict(packed: bytes) -> np.ndarray:
    """The chunk bytes from the inflated ones: undo the delta coding (a running sum modulo 256 of
    the bytes minus 128), then put the two halves back at the even and odd positions."""
    t = np.frombuffer(packed, np.uint8).copy()
    t[1:] ^= 0x80  # minus 128 modulo 256
    d = np.cumsum(t, dtype=np.uint8)  # uint8 accumulator: the sum wraps modulo 256
    out = np.empty_like(d)
    half = (d.size + 1) // 2
    out[0::2] = d[:half]
    out[1::2] = d[half:]
    return out


def decode_planes(data: bytes, layout: ExrLayout) -> dict[str, np.ndarray] | None:
    """Each channel's (height, width) pixels of ``data``, whose layout :func:`check_exr_bytes` read;
    every chunk is inflated and checked to hold exactly its lines (:class:`ExrDamaged` if not).
    None for files this module does not decode (see the module docstring)."""
    if layout.compression not in HANDLED or not layout.plain or not layout.chunks:
        return None
    w, h = layout.width, layout.height
    names, types = list(layout.channels), list(layout.channels.values())
    widths = [w * SAMPLE_BYTES[t] for t in types]
    line_bytes = sum(widths)
    lines = LINES_PER_CHUNK[layout.compression]
    y0 = layout.chunks[0][1]
    rows = np.empty((h, line_bytes), np.uint8)
    filled = 0
    for index, (offset, y, size) in enumerate(layout.chunks):
        n = min(lines, y0 + h - y)
        raw = n * line_bytes
        body = memoryview(data)[offset + 8:offset + 8 + size]
        if size == raw:  # stored: deflating did not help (or no compression)
            block = np.frombuffer(body, np.uint8)
        elif layout.compression == NO_COMPRESSION or size > raw:
            raise ExrDamaged(f"pixel data does not decode (chunk {index} has {size} bytes, expected at most {raw})")
        else:
            inflater = zlib.decompressobj()
            try:
                packed = inflater.decompress(body, raw + 1)
            except zlib.error as e:
                raise ExrDamaged(f"pixel data does not decode (chunk {index}: {e})") from None
            if len(packed) != raw or not inflater.eof or inflater.unused_data:
                raise ExrDamaged(f"pixel data does not decode (chunk {index} inflates to {len(packed)} bytes, "
                                 f"expected {raw})")
            block = _unpredict(packed)
        rows[y - y0:y - y0 + n] = block.reshape(n, line_bytes)
        filled += n
    if filled != h:  # check_exr_bytes gives one chunk per block of lines, in line order
        raise ExrDamaged(f"pixel data does not decode ({filled} of {h} lines in the chunks)")
    out, col = {}, 0
    for name, t, width in zip(names, types, widths):
        out[name] = np.ascontiguousarray(rows[:, col:col + width]).view(DTYPES[t]).reshape(h, w)
        col += width
    return out


__all__ = ["DTYPES", "TYPE_NAMES", "decode_planes"]
