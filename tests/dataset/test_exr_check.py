"""The byte-level EXR checks that run before OpenEXR decodes (synth.dataset.exr_check).

OpenEXR is the oracle: files it wrote must pass, and whatever passes with ``inflate`` must be
read by it without a word printed on stdout or stderr.
"""

from __future__ import annotations

import io
import struct

import numpy as np
import pytest

from synth.dataset.exr import encode_frame_exr
from synth.dataset.exr_check import MAX_SIDE, ExrDamaged, check_exr_bytes

OpenEXR = pytest.importorskip("OpenEXR")


def frame_bytes(h=40, w=9, compression="ZIP", seed=0) -> bytes:
    rng = np.random.default_rng(seed)
    return encode_frame_exr(rng.uniform(0, 1, (h, w, 4)), rng.uniform(0.3, 3, (h, w)),
                            rng.uniform(-1, 1, (h, w, 3)), rng.integers(0, 12, (h, w)).astype(np.uint32),
                            compression=compression)


@pytest.mark.parametrize("compression", ["NO", "RLE", "ZIPS", "ZIP", "PIZ", "PXR24", "B44", "DWAA", "DWAB", "ZSTD"])
@pytest.mark.parametrize("size", [(1, 1), (17, 5), (40, 33)])
def test_files_openexr_wrote_pass(compression, size):
    data = frame_bytes(*size, compression=compression)
    layout = check_exr_bytes(data, inflate=True)
    assert (layout.height, layout.width) == size
    assert layout.compression == int(getattr(OpenEXR, f"{compression}_COMPRESSION"))
    assert layout.channels["depth.Z"] == 2 and layout.channels["segmentation.id"] == 0 and layout.channels["R"] == 1
    lines = {"NO": 1, "RLE": 1, "ZIPS": 1, "ZIP": 16, "PIZ": 32, "PXR24": 16, "B44": 32, "DWAA": 32, "DWAB": 256}
    if compression in lines:
        assert len(layout.chunks) == -(-size[0] // lines[compression])
        assert [y for _, y, _ in layout.chunks] == list(range(0, size[0], lines[compression]))


def test_every_truncation_is_rejected():
    data = frame_bytes()
    assert len(check_exr_bytes(data).chunks) == 3
    for n in range(len(data)):
        with pytest.raises(ExrDamaged):
            check_exr_bytes(data[:n])


def _channels(data: bytes) -> dict:
    return {n: c.pixels for n, c in OpenEXR.File(io.BytesIO(data), separate_channels=True).channels().items()}


def test_what_passes_is_read_without_a_word(capfd):
    """Flip bit 0 and bit 7 of every byte: either the check rejects the file, or OpenEXR reads
    it (or raises) without printing anything. Past the header, what passes decodes: the flip hit
    bits deflate ignores (padding, unused code lengths), or, rarely, it is one of the changes
    Adler-32 cannot see (the manifest's sha256 catches those in ``synth validate``)."""
    data = frame_bytes()
    original = _channels(data)
    chunks = check_exr_bytes(data).chunks
    table = min(offset for offset, _, _ in chunks) - 8 * len(chunks)  # where the offset table starts
    passed, changed = [], []
    for i in range(len(data)):
        for bit in (0x01, 0x80):
            damaged = bytearray(data)
            damaged[i] ^= bit
            try:
                check_exr_bytes(bytes(damaged), inflate=True)
            except ExrDamaged:
                continue
            passed.append(i)
            try:
                got = _channels(bytes(damaged))
            except Exception:  # noqa: BLE001 - any refusal is fine, as long as it is silent
                assert i < table, f"flip at byte {i} passed the check but does not decode"
                continue
            if i >= table:
                changed.append(any((got[n] != px).any() for n, px in original.items()))
    assert capfd.readouterr() == ("", "")
    assert passed and len(changed) < 0.005 * (len(data) - table) and sum(changed) <= 2


def test_pixel_damage_needs_inflate_to_be_seen():
    data = bytearray(frame_bytes())
    data[-40] ^= 0x01
    check_exr_bytes(bytes(data))  # the structure is intact
    with pytest.raises(ExrDamaged, match="does not decode"):
        check_exr_bytes(bytes(data), inflate=True)


def _set_data_window(data: bytes, x1: int, y1: int) -> bytes:
    at = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    return data[:at + 8] + struct.pack("<2i", x1, y1) + data[at + 16:]


def test_implausible_headers_are_rejected_without_allocating():
    data = frame_bytes()
    with pytest.raises(ExrDamaged, match="implausible data window"):
        check_exr_bytes(_set_data_window(data, 2**31 - 2, 39), inflate=True)
    with pytest.raises(ExrDamaged, match="implausible data window"):
        check_exr_bytes(_set_data_window(data, 8, MAX_SIDE), inflate=True)
    with pytest.raises(ExrDamaged, match="implausible"):
        check_exr_bytes(_set_data_window(data, -5, 39))
    with pytest.raises(ExrDamaged, match="magic"):
        check_exr_bytes(b"")
    missing = data.replace(b"lineOrder\0lineOrder\0", b"lineOrdeX\0lineOrder\0")
    with pytest.raises(ExrDamaged, match="lacks the 'lineOrder'"):
        check_exr_bytes(missing)


def test_multi_part_files_are_refused():
    parts = [OpenEXR.Part({"type": OpenEXR.scanlineimage}, {"Z": np.zeros((4, 4), np.float32)}, name=n)
             for n in ("a", "b")]
    buf = io.BytesIO()
    OpenEXR.File(parts).write(buf)
    with pytest.raises(ExrDamaged, match="single-part"):
        check_exr_bytes(buf.getvalue())
