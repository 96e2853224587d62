"""synth.dataset.reader: frames from datasets, shard directories, tars and streams; rays."""

from __future__ import annotations

import io
import os
import tarfile
import threading

import numpy as np
import pytest

from tests.support import fake_frames as ff
from synth.dataset.layout import parse_frame_key
from synth.dataset.reader import camera_rays, decode_frame, iter_frames, list_frames, rays, read_frame
from synth.dataset.shards import open_dataset
from synth.errors import SynthError
from synth.dataset.exr import read_frame_exr

pytest.importorskip("OpenEXR")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds") / "d"
    expected = ff.plan(n_shards=2, n_expr=2, n_views=3)
    ds = open_dataset(root, "f" * 64, expected)
    ff.render_dataset(ds, size=16)
    return root, expected


def _tar_bytes(root, shards) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w") as tf:
        for sid in shards:
            d = root / "shards" / sid
            for name in sorted(os.listdir(d)):
                tf.add(d / name, arcname=f"{sid}/{name}")
    return buf.getvalue()


def test_dataset_order_and_content(dataset):
    root, expected = dataset
    frames = list(iter_frames(root))
    assert [(f.shard, f.key) for f in frames] == [(s, k) for s in sorted(expected) for k in sorted(expected[s])]
    f = frames[4]
    ex = read_frame_exr(root / "shards" / f.shard / f"{f.key}.exr")
    np.testing.assert_array_equal(f.rgba, ex["rgba"].astype(np.float32))
    np.testing.assert_array_equal(f.depth, ex["depth"])
    np.testing.assert_array_equal(f.segmentation, ex["segmentation"])
    assert f.rgba.dtype == f.normals.dtype == f.depth.dtype == np.float32 and f.segmentation.dtype == np.uint32
    # straight colour: premultiplied / alpha where covered, 0 elsewhere
    a = f.alpha
    np.testing.assert_allclose(f.rgb[a > 0] * a[a > 0, None], f.rgb_premultiplied[a > 0], rtol=1e-6)
    assert (f.rgb[a == 0] == 0).all()
    assert f.identity_code.dtype == np.float32 and f.identity_code.tolist() == pytest.approx([0.1, -0.2])
    assert f.joint_rotations["jaw"].tolist() == pytest.approx([0.1, 0.0, 0.0])
    assert (f.identity_index, f.expression_index, f.view_index) == parse_frame_key(f.key)
    np.testing.assert_allclose(f.world_to_camera @ f.camera_to_world, np.eye(4), atol=1e-9)


def test_shard_subset_and_single_shard_dir(dataset):
    root, expected = dataset
    one = sorted(expected)[1]
    a = [f.key for f in iter_frames(root, shards=[one])]
    b = [f.key for f in iter_frames(root / "shards" / one)]
    assert a == b == sorted(expected[one])
    with pytest.raises(SynthError, match="not committed"):
        list_frames(root, shards=["shard_999999"])


def test_staging_is_never_read(dataset, tmp_path):
    expected = ff.plan(n_shards=2, n_expr=1, n_views=2)
    ds = open_dataset(tmp_path / "d", "e" * 64, expected)
    ff.render_dataset(ds, size=8, shards=[sorted(expected)[0]])
    with ds.staging(sorted(expected)[1]) as st:  # staged, never committed
        key = st.expected_keys[0]
        st.write_frame(key, *ff.pixels(key, 8), ff.frame_json(key, 8))
    assert {f.shard for f in iter_frames(tmp_path / "d")} == {sorted(expected)[0]}


@pytest.mark.parametrize("how", ["path", "stream", "pipe", "samples"])
def test_tar_sources_give_the_same_frames(dataset, tmp_path, how):
    root, expected = dataset
    ref = list(iter_frames(root))
    data = _tar_bytes(root, sorted(expected))
    if how == "path":
        (tmp_path / "d.tar").write_bytes(data)
        got = list(iter_frames(tmp_path / "d.tar"))
    elif how == "stream":
        got = list(iter_frames(io.BytesIO(data)))
    elif how == "pipe":  # a non-seekable stream, as from a socket or `curl | `
        r, w = os.pipe()
        t = threading.Thread(target=lambda: (os.write(w, data), os.close(w)))
        t.start()
        with os.fdopen(r, "rb") as f:
            got = list(iter_frames(f))
        t.join()
    else:
        samples = []
        for fr in ref:
            d = root / "shards" / fr.shard
            samples.append({"__key__": f"{fr.shard}/{fr.key}", "json": (d / f"{fr.key}.json").read_bytes(),
                            "exr": (d / f"{fr.key}.exr").read_bytes()})
        got = list(iter_frames(samples))
    assert [f.key for f in got] == [f.key for f in ref]
    for a, b in zip(got, ref):
        assert a.meta == b.meta
        np.testing.assert_array_equal(a.rgba, b.rgba)
        np.testing.assert_array_equal(a.normals, b.normals)
    if how != "samples":
        assert [f.shard for f in got] == [f.shard for f in ref]


def test_tar_with_a_missing_half_is_refused(dataset):
    root, expected = dataset
    buf = io.BytesIO()
    sid = sorted(expected)[0]
    with tarfile.open(fileobj=buf, mode="w") as tf:
        tf.add(root / "shards" / sid / f"{expected[sid][0]}.json", arcname=f"{expected[sid][0]}.json")
    buf.seek(0)
    with pytest.raises(SynthError, match="incomplete frame"):
        list(iter_frames(buf))


def test_corrupt_exr_is_one_clear_error(dataset):
    root, expected = dataset
    sid = sorted(expected)[0]
    jp = root / "shards" / sid / f"{expected[sid][0]}.json"
    exr = jp.with_suffix(".exr").read_bytes()
    with pytest.raises(SynthError, match="EXR") as e:
        decode_frame(jp.read_bytes(), exr[: len(exr) // 2], where="x")
    assert "\n" not in str(e.value)
    with pytest.raises(SynthError, match="does not parse"):
        decode_frame(b"{", exr)
    with pytest.raises(SynthError, match="not 'id000009"):
        decode_frame(jp.read_bytes(), exr, key="id000009_ex00_v00")


def test_validate_option_checks_schema(dataset, tmp_path):
    root, expected = dataset
    sid = sorted(expected)[0]
    jp = root / "shards" / sid / f"{expected[sid][0]}.json"
    assert read_frame(jp, validate=True).key == jp.stem
    bad = jp.read_text().replace('"width": 16', '"width": 17', 1)
    with pytest.raises(SynthError, match="invalid frame JSON"):
        decode_frame(bad.encode(), jp.with_suffix(".exr").read_bytes(), validate=True)


def test_threads_read_the_same_frames(dataset):
    root, _ = dataset
    refs = list_frames(root)
    want = [r.read().rgba for r in refs]
    results: list = [None] * 8
    errors: list = []

    def work(i):
        try:
            results[i] = [r.read().rgba for r in refs]
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    ts = [threading.Thread(target=work, args=(i,)) for i in range(8)]
    [t.start() for t in ts]
    [t.join() for t in ts]
    assert not errors
    for res in results:
        for a, b in zip(res, want):
            np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------- rays

def _random_camera(rng, w, h):
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    c2w = np.eye(4)
    c2w[:3, :3] = R
    c2w[:3, 3] = rng.normal(size=3)
    K = np.array([[rng.uniform(20, 200), rng.uniform(-2, 2), rng.uniform(0, w)],
                  [0, rng.uniform(20, 200), rng.uniform(0, h)], [0, 0, 1]])
    return K, c2w


@pytest.mark.parametrize("seed", range(5))
def test_rays_reproject_to_pixel_centres(seed):
    rng = np.random.default_rng(seed)
    w, h = 7, 5
    K, c2w = _random_camera(rng, w, h)
    r = camera_rays(K, c2w, w, h, dtype=np.float64)
    assert r.origins.shape == r.directions.shape == (h, w, 3) and r.cos_z.shape == (h, w)
    np.testing.assert_allclose(np.linalg.norm(r.directions, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(r.origins, np.broadcast_to(c2w[:3, 3], (h, w, 3)))
    t = rng.uniform(0.1, 10.0, (h, w))
    X = r.origins + t[..., None] * r.directions
    w2c = np.linalg.inv(c2w)
    Xc = X @ w2c[:3, :3].T + w2c[:3, 3]
    uv = (Xc @ K.T)[..., :2] / Xc[..., 2:3]
    jj, ii = np.mgrid[0:h, 0:w]
    np.testing.assert_allclose(uv[..., 0], ii + 0.5, atol=1e-9)
    np.testing.assert_allclose(uv[..., 1], jj + 0.5, atol=1e-9)
    np.testing.assert_allclose(Xc[..., 2], t * r.cos_z, rtol=1e-12)  # planar depth = t * cos_z
    # a subset of pixels gives the same rays as the full image
    rows, cols = rng.integers(0, h, 11), rng.integers(0, w, 11)
    sub = camera_rays(K, c2w, w, h, pixels=(rows, cols), dtype=np.float64)
    np.testing.assert_allclose(sub.directions, r.directions[rows, cols], atol=1e-15)


def test_rays_of_a_frame_hit_its_depth(dataset):
    """The fake sphere's depth, placed along each covered pixel's ray, reprojects onto that pixel."""
    root, _ = dataset
    f = next(iter(iter_frames(root)))
    r = rays(f)
    assert r.directions.dtype == np.float32 and r.directions.shape == (f.height, f.width, 3)
    cov = f.depth > 0
    t = f.depth[cov] / r.cos_z[cov]
    X = r.origins[cov] + t[:, None] * r.directions[cov]
    Xc = X @ f.world_to_camera[:3, :3].T + f.world_to_camera[:3, 3]
    np.testing.assert_allclose(Xc[:, 2], f.depth[cov], rtol=1e-5)
