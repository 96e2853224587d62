"""The camera in the EXR header: OpenEXR's standard ``worldToCamera`` and ``worldToNDC``.

The oracle is the attributes' definition in OpenEXR's ImfStandardAttributes.h, applied the way
Imath does it: row vectors, ``p' = p M``, then the homogeneous divide. camera space: x right,
y up, z forward (objects in front have z > 0); NDC: (0, 0) the top-left and (1, 1) the
bottom-right corner of the display window, y down.
"""

from __future__ import annotations

import numpy as np
import pytest

from synth.conventions import intrinsics, look_at, invert_rigid, project
from synth.dataset.exr import (SEGMENTATION_CONVENTION, camera_attributes, decode_frame_exr, encode_frame_exr,
                               read_camera_attributes, read_frame_exr_header)
from synth.errors import SynthError
from tests.support import fake_frames


def _imath_mult_vec_matrix(p, M):
    """Imath's M44f::multVecMatrix: [x y z 1] M, divided by w."""
    h = np.concatenate([p, np.ones((len(p), 1))], 1) @ np.asarray(M, np.float64)
    return h[:, :3] / h[:, 3:4]


@pytest.fixture
def frame():
    key = "id000003_ex01_v02"
    rgba, depth, normals, seg = fake_frames.pixels(key, 24)
    W, H = 24, 18
    rgba, depth, normals, seg = rgba[:H], depth[:H], normals[:H], seg[:H]
    K = intrinsics(W, H, 35.0, (1.5, -2.25))
    c2w = look_at([0.4, -0.9, 0.3], [0.0, 0.02, 0.05])
    return (rgba, depth, normals, seg), K, invert_rigid(c2w), W, H


def test_world_to_ndc_projects_like_K(frame):
    px, K, w2c, W, H = frame
    data = encode_frame_exr(*px, camera_attributes(K, w2c, W, H))
    hdr = read_frame_exr_header(data)["header"]
    pts = np.random.default_rng(0).uniform(-0.1, 0.1, (50, 3))
    uv, z = project(K, w2c, pts)
    assert (z > 0).all()
    ndc = _imath_mult_vec_matrix(pts, hdr["worldToNDC"])[:, :2]
    # float32 storage: ~1e-7 relative
    assert np.abs(ndc * [W, H] - uv).max() < 1e-3
    # the image corners: NDC (0, 0) is the top-left corner, (1, 1) the bottom-right
    corner_tl = np.linalg.solve(K, [0.0, 0.0, 1.0])
    corner_br = np.linalg.solve(K, [W, H, 1.0])
    c2w = invert_rigid(w2c)
    P = (np.stack([corner_tl, corner_br]) * 2.0) @ c2w[:3, :3].T + c2w[:3, 3]
    assert np.allclose(_imath_mult_vec_matrix(P, hdr["worldToNDC"])[:, :2], [[0, 0], [1, 1]], atol=1e-5)


def test_world_to_camera_axes(frame):
    px, K, w2c, W, H = frame
    hdr = read_frame_exr_header(encode_frame_exr(*px, camera_attributes(K, w2c, W, H)))["header"]
    c2w = invert_rigid(w2c)
    centre, right, down, fwd = c2w[:3, 3], c2w[:3, 0], c2w[:3, 1], c2w[:3, 2]
    M = hdr["worldToCamera"]
    assert np.allclose(_imath_mult_vec_matrix(centre[None], M), 0, atol=1e-6)
    # in front of the camera: z > 0; image right: +x; image up (= -OpenCV y): +y
    got = _imath_mult_vec_matrix(np.stack([centre + fwd, centre + right, centre - down]), M)
    assert np.allclose(got, [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-6)
    # the reader's helper gives the column-vector matrices back (float32 precision)
    cam = read_camera_attributes(hdr)
    assert np.allclose(cam["worldToCamera"], np.diag([1.0, -1.0, 1.0, 1.0]) @ w2c, atol=1e-6)


def test_pixels_unchanged_by_camera_attributes(frame):
    px, K, w2c, W, H = frame
    plain = decode_frame_exr(encode_frame_exr(*px))
    with_cam = decode_frame_exr(encode_frame_exr(*px, camera_attributes(K, w2c, W, H)))
    for k in ("rgba", "depth", "normals", "segmentation"):
        assert plain[k].dtype == with_cam[k].dtype and plain[k].tobytes() == with_cam[k].tobytes(), k
    assert read_camera_attributes(plain["header"]) is None
    assert with_cam["header"]["segmentationConvention"] == SEGMENTATION_CONVENTION


@pytest.mark.parametrize("bad", [np.eye(4), np.eye(3, dtype=np.float32), np.full((4, 4), np.nan, np.float32)])
def test_bad_camera_matrix_refused(frame, bad):
    px, *_ = frame
    with pytest.raises(SynthError, match="4x4 float32"):
        encode_frame_exr(*px, {"worldToNDC": bad})


def test_fake_dataset_frames_carry_the_camera(tmp_path):
    from synth.dataset.reader import iter_frames
    from synth.dataset.shards import open_dataset

    exp = fake_frames.plan(1, 1, 2)
    ds = open_dataset(tmp_path / "ds", "h" * 64, exp)
    fake_frames.render_dataset(ds)
    for f in iter_frames(tmp_path / "ds"):
        hdr = read_frame_exr_header(ds.shard_dir(f.shard) / f"{f.key}.exr")["header"]
        lm = np.asarray(f.meta["landmarks_3d"])
        ndc = _imath_mult_vec_matrix(lm, hdr["worldToNDC"])[:, :2]
        assert np.abs(ndc * [f.width, f.height] - np.asarray(f.meta["landmarks_2d"])).max() < 1e-3
