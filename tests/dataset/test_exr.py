"""Frame EXR writer/reader: round trip, half-float limits, NaN refusal, atomic writes."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.errors import SynthError
from synth.dataset.exr import (CHANNELS, HALF_MAX, REC709_CHROMATICITIES, decode_channels, decode_frame_exr,
                               encode_frame_exr,
                               read_frame_exr, read_frame_exr_header, write_frame_exr)

OpenEXR = pytest.importorskip("OpenEXR")


def frame(h=12, w=20, seed=0):
    rng = np.random.default_rng(seed)
    rgba = rng.uniform(0, 4, (h, w, 4)).astype(np.float32)
    rgba[..., 3] = rng.uniform(0, 1, (h, w))
    depth = rng.uniform(0.3, 3.0, (h, w)).astype(np.float32)
    n = rng.normal(size=(h, w, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    seg = rng.integers(0, 12, (h, w)).astype(np.uint32)
    return rgba, depth, n.astype(np.float32), seg


def test_round_trip(tmp_path):
    rgba, depth, n, seg = frame()
    p = tmp_path / "f.exr"
    nbytes = write_frame_exr(p, rgba, depth, n, seg, {"synthFrameKey": "id000001_ex02_v03", "count": 3, "x": 0.5})
    assert nbytes == p.stat().st_size
    r = read_frame_exr(p)
    assert (r["width"], r["height"]) == (20, 12)
    assert set(r["channels"]) == set(CHANNELS)
    assert r["channels"]["R"] == "HALF" and r["channels"]["depth.Z"] == "FLOAT"
    assert r["channels"]["segmentation.id"] == "UINT"
    assert r["rgba"].dtype == np.float16 and r["rgba"].shape == (12, 20, 4)
    np.testing.assert_array_equal(r["rgba"], rgba.astype(np.float16))
    np.testing.assert_array_equal(r["depth"], depth)  # float32: exact
    np.testing.assert_allclose(r["normals"].astype(np.float32), n, atol=1e-3)
    np.testing.assert_array_equal(r["segmentation"], seg)
    hdr = r["header"]
    assert hdr["synthFrameKey"] == "id000001_ex02_v03" and hdr["count"] == 3 and hdr["x"] == 0.5
    np.testing.assert_allclose(hdr["chromaticities"], REC709_CHROMATICITIES, atol=1e-6)
    assert hdr["colorInteropID"] == "lin_rec709_scene"
    assert hdr["synthFormat"] == "synth-frame-exr/1"
    assert "ZIP" in hdr["compression"]
    h = read_frame_exr_header(p)
    assert (h["width"], h["height"]) == (20, 12) and set(h["channels"]) == set(CHANNELS)
    # the colour metadata is self-consistent by OpenEXR's own check
    assert OpenEXR.checkColorMetadata(OpenEXR.File(str(p), header_only=True).header()) == 0


def test_float64_and_int_inputs_are_accepted(tmp_path):
    rgba, depth, n, seg = frame()
    write_frame_exr(tmp_path / "f.exr", rgba.astype(np.float64), depth.astype(np.float64), n.astype(np.float64),
                    seg.astype(np.int64))
    r = read_frame_exr(tmp_path / "f.exr")
    np.testing.assert_array_equal(r["segmentation"], seg)


def test_half_limits_clamp_rgb_and_alpha(tmp_path):
    rgba, depth, n, seg = frame()
    rgba[0, 0, :3] = [1e6, -1e6, 70000.0]   # beyond half range: clamped, never inf
    rgba[0, 1, 0] = 65504.0                 # exactly the max: kept
    rgba[0, 2, 3] = 1.5                     # alpha clamped to [0, 1]
    write_frame_exr(tmp_path / "f.exr", rgba, depth, n, seg)
    r = read_frame_exr(tmp_path / "f.exr")
    assert np.isfinite(r["rgba"]).all()
    np.testing.assert_array_equal(r["rgba"][0, 0, :3].astype(np.float32), [HALF_MAX, -HALF_MAX, HALF_MAX])
    assert float(r["rgba"][0, 1, 0]) == HALF_MAX
    assert float(r["rgba"][0, 2, 3]) == 1.0


def test_background_depth_stored_as_zero(tmp_path):
    rgba, depth, n, seg = frame()
    depth[0, 0] = np.inf
    depth[0, 1] = 1e10  # what Cycles writes where no surface was hit
    depth[0, 2] = 1e20
    write_frame_exr(tmp_path / "f.exr", rgba, depth.astype(np.float64), n, seg)
    r = read_frame_exr(tmp_path / "f.exr")
    assert r["depth"][0, :3].tolist() == [0.0, 0.0, 0.0]
    assert np.isfinite(r["depth"]).all()


@pytest.mark.parametrize("what", ["rgba", "depth", "normals"])
def test_nan_is_refused_and_nothing_written(tmp_path, what):
    rgba, depth, n, seg = frame()
    {"rgba": rgba, "depth": depth, "normals": n}[what].flat[5] = np.nan
    p = tmp_path / "f.exr"
    with pytest.raises(SynthError, match="NaN"):
        write_frame_exr(p, rgba, depth, n, seg)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("case", ["rgba_inf", "normal_inf", "neg_depth", "neg_seg", "float_seg", "shape", "header"])
def test_bad_inputs_refused(tmp_path, case):
    rgba, depth, n, seg = frame()
    hdr = None
    if case == "rgba_inf":
        rgba[1, 1, 1] = np.inf
    elif case == "normal_inf":
        n[1, 1, 1] = -np.inf
    elif case == "neg_depth":
        depth[2, 2] = -0.1
    elif case == "neg_seg":
        seg = seg.astype(np.int32)
        seg[0, 0] = -1
    elif case == "float_seg":
        seg = seg.astype(np.float32)
    elif case == "shape":
        depth = depth[:-1]
    elif case == "header":
        hdr = {"compression": "x"}
    with pytest.raises(SynthError):
        write_frame_exr(tmp_path / "f.exr", rgba, depth, n, seg, hdr)
    assert os.listdir(tmp_path) == []


def test_overwrite_is_atomic_and_leaves_no_temp(tmp_path):
    p = tmp_path / "f.exr"
    write_frame_exr(p, *frame(seed=1))
    write_frame_exr(p, *frame(seed=2))
    assert os.listdir(tmp_path) == ["f.exr"]
    np.testing.assert_array_equal(read_frame_exr(p)["segmentation"], frame(seed=2)[3])


def test_failed_write_keeps_old_file(tmp_path, monkeypatch):
    p = tmp_path / "f.exr"
    write_frame_exr(p, *frame(seed=1))
    before = p.read_bytes()

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        write_frame_exr(p, *frame(seed=2))
    assert p.read_bytes() == before
    assert os.listdir(tmp_path) == ["f.exr"]


@pytest.mark.parametrize("damage", ["truncate", "garbage", "missing"])
def test_unreadable_files_raise_synth_error(tmp_path, damage):
    p = tmp_path / "f.exr"
    write_frame_exr(p, *frame(h=32, w=32))
    data = p.read_bytes()
    if damage == "truncate":
        p.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        p.write_bytes(b"not an exr at all" * 10)
    else:
        p.unlink()
    with pytest.raises(SynthError, match=str(p)):
        read_frame_exr(p)


def test_missing_channel_reported(tmp_path):
    p = tmp_path / "f.exr"
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"R": np.zeros((4, 4), np.float16)}).write(str(p))
    with pytest.raises(SynthError, match="lacks channel"):
        read_frame_exr(p)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=32), min_size=4, max_size=4),
       st.integers(0, 2**32 - 1))
def test_round_trip_property(values, seg_id):
    """Any finite colour comes back as its half-float rounding (clamped), any uint32 ID exactly."""
    rgba = np.array(values, np.float32).reshape(1, 1, 4)
    clamped = rgba.copy()
    clamped[..., :3] = np.clip(clamped[..., :3], -HALF_MAX, HALF_MAX)
    clamped[..., 3] = np.clip(clamped[..., 3], 0, 1)
    data = encode_frame_exr(rgba, np.ones((1, 1)), np.zeros((1, 1, 3)), np.array([[seg_id]], np.uint32))
    f = OpenEXR.File(__import__("io").BytesIO(data), separate_channels=True)
    ch = f.channels()
    got = np.array([ch[c].pixels[0, 0] for c in "RGBA"], np.float16)
    np.testing.assert_array_equal(got, clamped.reshape(4).astype(np.float16))
    assert np.isfinite(got.astype(np.float32)).all()
    assert int(ch["segmentation.id"].pixels[0, 0]) == seg_id


def _damaged(data: bytes, damage: str) -> bytes:
    if damage == "half":
        return data[: len(data) // 2]
    if damage == "last byte":
        return data[:-1]
    flipped = bytearray(data)
    flipped[len(data) - 40] ^= 0x01  # inside the last chunk's deflated data
    return bytes(flipped)


@pytest.mark.parametrize("damage", ["half", "last byte", "flipped bit"])
def test_verified_read_of_a_damaged_file_prints_nothing(tmp_path, capfd, damage):
    p = tmp_path / "f.exr"
    write_frame_exr(p, *frame(h=32, w=32))
    p.write_bytes(_damaged(p.read_bytes(), damage))
    with pytest.raises(SynthError, match="does not decode") as e:
        read_frame_exr(p, verify=True)
    assert e.value.where == str(p)
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    print("still printing")
    assert capfd.readouterr().out == "still printing\n"


def test_truncated_file_is_rejected_silently_without_verify(tmp_path, capfd):
    data = encode_frame_exr(*frame(h=32, w=32))
    for n in (len(data) // 2, len(data) - 1):
        with pytest.raises(SynthError, match="does not decode"):
            read_frame_exr(data[:n])
    assert capfd.readouterr() == ("", "")


def test_decode_channels_gives_the_frames_channels_and_refuses_what_decode_refuses(tmp_path):
    data = encode_frame_exr(*frame(h=12, w=20))
    full = decode_frame_exr(data)
    w, h, (alpha, depth) = decode_channels(data, ("A", "depth.Z"))
    assert (w, h) == (20, 12)
    np.testing.assert_array_equal(alpha, full["rgba"][..., 3])
    np.testing.assert_array_equal(depth, full["depth"])
    with pytest.raises(SynthError, match="channel nope has no pixel data"):
        decode_channels(data, ("nope",))
    with pytest.raises(SynthError, match="does not decode"):
        decode_channels(data[:len(data) // 2], ("A",))


def test_bytes_and_path_reads_agree(tmp_path):
    p = tmp_path / "f.exr"
    write_frame_exr(p, *frame(), {"synthFrameKey": "id000001_ex02_v03"})
    data = p.read_bytes()
    a, b, c = read_frame_exr(p), read_frame_exr(data), decode_frame_exr(data, "tar:f.exr", verify=True)
    assert (a["path"], b["path"], c["path"]) == (str(p), "<bytes>", "tar:f.exr")
    for k in ("rgba", "depth", "normals", "segmentation"):
        np.testing.assert_array_equal(a[k], b[k])
        np.testing.assert_array_equal(a[k], c[k])
    assert a["header"] == b["header"] == c["header"] and a["channels"] == b["channels"]
    assert read_frame_exr_header(data)["header"]["synthFrameKey"] == "id000001_ex02_v03"


def test_reads_in_threads_leave_stderr_alone(tmp_path, capfd):
    """Readers in threads (DataLoader workers) must not redirect fd 2: another thread's lines
    written while damaged files are being read all arrive, and every good read succeeds."""
    import threading

    good = encode_frame_exr(*frame(h=32, w=32))
    bad = _damaged(good, "flipped bit")
    failures = []

    def reader():
        for i in range(60):
            try:
                read_frame_exr(bad, verify=True)
                failures.append("damaged file read")
            except SynthError:
                pass
            if read_frame_exr(good)["width"] != 32:
                failures.append("bad width")

    def writer():
        for i in range(200):
            os.write(2, f"line {i}\n".encode())

    threads = [threading.Thread(target=reader) for _ in range(3)] + [threading.Thread(target=writer)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert failures == []
    assert capfd.readouterr().err.splitlines() == [f"line {i}" for i in range(200)]


@pytest.mark.parametrize("damage, says", [
    (None, None),
    (lambda p: p["rgba"].__setitem__((1, 2, 0), np.nan), "RGBA has 1 NaN and 0 Inf"),
    (lambda p: p["rgba"].__setitem__((1, 2, 1), np.inf), "RGBA has 0 NaN and 1 Inf"),
    (lambda p: p["normals"].__setitem__((0, 0, 2), -np.inf), "normals has 0 NaN and 1 Inf"),
    (lambda p: p["depth"].__setitem__((3, 3), np.nan), "depth has 1 NaN and 0 Inf value(s), 1 where alpha > 0"),
    (lambda p: p["depth"].__setitem__((3, 3), np.inf), "depth has 0 NaN and 1 Inf"),
    (lambda p: p["depth"].__setitem__((3, 3), -0.5), "depth has 1 negative value(s)"),
    (lambda p: p["rgba"].__setitem__((0, 1, 3), 1.5), "alpha outside [0, 1]"),
    (lambda p: p["rgba"].__setitem__((0, 1, 3), -0.25), "alpha outside [0, 1]"),
    (lambda p: p["segmentation"].__setitem__((2, 2), 12), "unknown class ID(s) [12]"),
    (lambda p: p["segmentation"].__setitem__((2, 2), 2**32 - 1), "unknown class ID(s) [4294967295]"),
])
def test_pixel_defects_finds_each_defect_and_nothing_on_a_clean_frame(damage, says):
    """The whole-array fast path and the messages agree: a clean frame gives no defect, each
    damage exactly its one line (``synth validate`` runs this on every frame)."""
    from synth.dataset.exr import pixel_defects

    rgba, depth, n, seg = frame()
    rgba[..., 3] = np.clip(rgba[..., 3], 0.01, 1.0)
    px = decode_frame_exr(encode_frame_exr(rgba, depth, n, seg))
    px = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in px.items()}
    if damage is not None:
        damage(px)
    found = pixel_defects(px)
    assert found == ([] if says is None else found[:1]) and len(found) == (0 if says is None else 1)
    assert says is None or says in found[0]
