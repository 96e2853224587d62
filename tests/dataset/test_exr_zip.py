"""synth validate's own decoding of ZIP/ZIPS/uncompressed frame EXRs against OpenEXR's, bit for bit,
and damaged bytes refused with the same one line."""

from __future__ import annotations

import numpy as np
import pytest

from synth.dataset.exr import decode_frame_exr, encode_frame_exr, verify_frame_exr
from synth.dataset.exr_check import check_exr_bytes
from synth.dataset.exr_zip import decode_planes
from synth.errors import SynthError

pytest.importorskip("OpenEXR")

ARRAYS = ("rgba", "depth", "normals", "segmentation")


def frame(h: int, w: int, seed: int, smooth: bool):
    """A frame whose pixels are noise (chunks that do not deflate: stored) or smooth gradients
    with a background (chunks that deflate well), with values at the half-float limits."""
    rng = np.random.default_rng(seed)
    if smooth:
        yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
        rgba = np.stack([xx, yy, xx * yy, (xx + yy < 1).astype(float)], -1).astype(np.float32)
        depth = np.where(rgba[..., 3] > 0, 0.5 + xx, 0.0).astype(np.float32)
    else:
        rgba = rng.uniform(-6e4, 6e4, (h, w, 4)).astype(np.float32)
        rgba[..., 3] = rng.uniform(0, 1, (h, w))
        depth = rng.uniform(0.3, 3.0, (h, w)).astype(np.float32)
    rgba.flat[:3] = [65504.0, 6e-8, -65504.0]  # largest half, a subnormal, the most negative
    n = rng.normal(size=(h, w, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    seg = rng.integers(0, 12, (h, w)).astype(np.uint32) if smooth else rng.integers(0, 2**32, (h, w), np.uint32)
    seg.flat[-1] = 2**32 - 1
    return rgba, depth, n.astype(np.float32), seg


def same(a: dict, b: dict) -> None:
    for k in ARRAYS:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
        assert a[k].tobytes() == b[k].tobytes(), k
    assert (a["width"], a["height"], a["channels"]) == (b["width"], b["height"], b["channels"])


@pytest.mark.parametrize("compression", ["ZIP", "ZIPS", "NO"])
@pytest.mark.parametrize("h, w", [(1, 1), (7, 33), (16, 5), (17, 16), (64, 64), (33, 1)])
@pytest.mark.parametrize("smooth", [False, True])
def test_decoded_as_openexr_decodes(compression, h, w, smooth):
    data = encode_frame_exr(*frame(h, w, h * 100 + w, smooth), {"synthFrameKey": "id000003_ex01_v02"},
                            compression=compression)
    assert decode_planes(data, check_exr_bytes(data)) is not None  # this path, not OpenEXR's
    mine = verify_frame_exr(data)
    same(mine, decode_frame_exr(data, verify=True))
    assert mine["frame_key"] == "id000003_ex01_v02"


def test_stored_and_deflated_chunks_in_one_file():
    """Noise above, smooth below, one line per chunk (ZIPS): the noise lines are stored as they
    are (deflating does not shrink them), the smooth ones deflated."""
    rgba, depth, n, seg = frame(64, 48, 1, smooth=False)
    s = frame(64, 48, 1, smooth=True)
    rgba[32:], depth[32:], n[32:], seg[32:] = s[0][32:], s[1][32:], 0.0, 0
    data = encode_frame_exr(rgba, depth, n, seg, compression="ZIPS")
    layout = check_exr_bytes(data)
    stored = [size == 48 * (4 * 2 + 4 + 3 * 2 + 4) for _, _, size in layout.chunks]
    assert any(stored) and not all(stored)
    same(verify_frame_exr(data), decode_frame_exr(data, verify=True))


def test_other_compressions_go_through_openexr():
    data = encode_frame_exr(*frame(20, 12, 3, smooth=True), compression="PIZ")
    assert decode_planes(data, check_exr_bytes(data)) is None
    same(verify_frame_exr(data), decode_frame_exr(data, verify=True))
    assert verify_frame_exr(data)["frame_key"] is None


@pytest.mark.parametrize("smooth", [False, True])
def test_damaged_bytes_are_refused_with_the_same_line(smooth):
    """Every byte position of the pixel data, changed: both readers refuse it with the same
    message, or (a change zlib's checksum cannot see, or one in stored pixels) both decode it to
    the same arrays."""
    data = encode_frame_exr(*frame(24, 20, 5, smooth), {"synthFrameKey": "id000000_ex00_v00"})
    start = check_exr_bytes(data).chunks[0][0]
    refused = 0
    for pos in range(start, len(data), 7):
        bad = bytearray(data)
        bad[pos] ^= 0x5A
        results = []
        for read in (lambda b: verify_frame_exr(b, "f.exr"), lambda b: decode_frame_exr(b, "f.exr", verify=True)):
            try:
                results.append(read(bytes(bad)))
            except SynthError as e:
                results.append(str(e))
        if isinstance(results[0], str) or isinstance(results[1], str):
            assert results[0] == results[1]
            refused += 1
        else:
            same(*results)
    assert refused > 0
