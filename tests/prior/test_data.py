"""prior.data: codes layout, bounding spheres, ray bounds, sampler determinism and hold-out."""

from __future__ import annotations

import numpy as np
import pytest

from tests.prior import scene
from prior.data import CodeLayout, Loader, RaySampler, bounding_sphere, build_table, intersect_sphere, open_source, prepare
from synth.dataset.reader import iter_frames
from synth.errors import SynthError

pytest.importorskip("OpenEXR")
JOINTS = ("jaw", "eye_l", "eye_r")


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    return scene.make_dataset(tmp_path_factory.mktemp("prior") / "d", identities=3, expressions=2, views=5, size=16)


def load_all(ds, *, joints=JOINTS, holdout_views=0, margin=0.05, pixel_dtype="float16", rank=0, world=1,
             buffer=0, start=True):
    """The prepare pass and a loader holding every identity of the rank."""
    src = open_source(ds)
    table = build_table(prepare(src, ds / ".prior" / "prepare"), joints=joints, margin=margin,
                        holdout_views=holdout_views, planned=src.planned_identities)
    ld = Loader(src, table, seed=0, rank=rank, world=world, buffer_identities=buffer, holdout_views=holdout_views,
                pixel_dtype=pixel_dtype, read_ahead=0)
    if start:
        ld.start()
    return ld


def sampler(ld, **kw):
    return RaySampler(ld, **kw)


def _points_reference(frame) -> np.ndarray:
    """Foreground points by a per-pixel loop with K^-1 (independent of the reader's rays)."""
    Kinv, c2w = np.linalg.inv(frame.K), frame.camera_to_world
    pts = []
    for j in range(frame.height):
        for i in range(frame.width):
            z = float(frame.depth[j, i])
            if z > 0 and frame.alpha[j, i] > 0:
                pc = z * (Kinv @ np.array([i + 0.5, j + 0.5, 1.0]))  # planar depth: camera z = z
                pts.append(c2w[:3, :3] @ pc + c2w[:3, 3])
    return np.array(pts)


def test_bounds_contain_every_foreground_point(ds):
    st = load_all(ds, margin=0.0).table.info
    frames = list(iter_frames(ds))
    for m, ident in enumerate(st.identity_index.tolist()):
        pts = np.concatenate([_points_reference(f) for f in frames if f.identity_index == ident])
        d = np.linalg.norm(pts - st.centre[m], axis=1)
        assert d.max() <= st.radius[m] * (1 + 1e-6)
        # the prepare pass keeps hull vertices only; the sphere equals the one of every point
        c_all, r_all = bounding_sphere(pts.astype(np.float32), 0.0)
        np.testing.assert_allclose(st.centre[m], c_all, rtol=0, atol=1e-7)
        assert abs(st.radius[m] - r_all) < 1e-7
        # the sphere is tight: the scene's true head sphere is centre c, radius r, and the
        # farthest visible point lies near it
        c, r = scene.head(ident)
        assert st.radius[m] < r * 1.25
        assert np.linalg.norm(st.centre[m] - c) < 0.25 * r
    margin = load_all(ds, margin=0.1, start=False).table.info
    np.testing.assert_allclose(margin.radius - 1e-6, (st.radius - 1e-6) * 1.1, rtol=1e-9)


def test_bounding_sphere_degenerate():
    c, r = bounding_sphere(np.array([[1.0, 2.0, 3.0]]), 0.05)
    assert c.tolist() == [1.0, 2.0, 3.0] and 0 < r < 1e-5


def test_intersect_sphere_against_marching():
    rng = np.random.default_rng(0)
    o = rng.normal(size=(500, 3)) * 2
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c, r = np.array([0.1, -0.2, 0.3]), 0.8
    near, far = intersect_sphere(o, d, c, r)
    t = np.linspace(0, 8, 16001)
    inside = np.linalg.norm(o[:, None] + t[None, :, None] * d[:, None] - c, axis=-1) < r
    for k in range(len(o)):
        if inside[k].any():
            ts = t[inside[k]]
            assert abs(ts.min() - near[k]) < 1e-3 and abs(ts.max() - far[k]) < 1e-3
        else:
            assert near[k] == far[k] == 0
    # an origin inside starts at 0; a sphere behind the origin is missed
    n2, f2 = intersect_sphere(np.array([[0.0, 0, 0], [0, 0, 5]]), np.array([[1.0, 0, 0], [0, 0, 1]]), np.zeros(3), 1.0)
    assert n2.tolist() == [0.0, 0.0] and f2[0] == pytest.approx(1.0) and f2[1] == 0


def test_codes_layout_from_the_data(ds):
    ld = load_all(ds)
    layout = ld.table.layout
    assert layout == CodeLayout(scene.ID_SIZE, scene.EXPR_SIZE, JOINTS)
    codes = ld.held[0].codes
    assert codes.shape == (10, scene.ID_SIZE + scene.EXPR_SIZE + 9)
    f = next(iter_frames(ds))
    sl = layout.slices()
    code = codes[0]
    np.testing.assert_array_equal(code[sl["beta"]], f.identity_code)
    np.testing.assert_array_equal(code[sl["expression"]], f.expression_code)
    for j in JOINTS:
        np.testing.assert_array_equal(code[sl[j]], f.joint_rotations[j])
    assert CodeLayout.from_dict(layout.to_dict()) == layout
    # per (identity, expression) table used for rendering agrees with the frames
    np.testing.assert_array_equal(ld.table.info.code(0, 0), code)
    # another joint order is another layout; an unknown joint is refused
    assert load_all(ds, joints=("eye_r", "jaw"), start=False).table.layout.joints == ("eye_r", "jaw")
    with pytest.raises(SynthError, match="no rotation for joint"):
        load_all(ds, joints=("jaw", "tongue"), start=False)


def test_latent_ids_dense_and_pixels_exact(ds):
    ld = load_all(ds, pixel_dtype="float32")
    assert ld.table.info.identity_index.tolist() == [0, 1, 2] and ld.slots.tolist() == [0, 1, 2]
    frames = {f.key: f for f in iter_frames(ds)}
    half = load_all(ds)  # float16 holds the EXR's HALF colours exactly
    for m, d in ld.held.items():
        assert d.keys == sorted(k for k in frames if frames[k].identity_index == m)
        for n, k in enumerate(d.keys):
            np.testing.assert_array_equal(d.rgba[n], frames[k].rgba)
        np.testing.assert_array_equal(half.held[m].rgba.astype(np.float32), d.rgba)


def test_sampler_deterministic_and_holdout_never_drawn(ds):
    ld = load_all(ds, holdout_views=2)
    held = {(m, n) for m, d in ld.held.items() for n in np.nonzero(~d.train)[0].tolist()}
    assert len(held) == 3 * 2 * 2
    assert {int(ld.held[m].view[n]) for m, n in held} == {3, 4}
    kw = dict(seed=7, identities=2, views=3, pixels=16, foreground_fraction=0.5)
    a, b = sampler(ld, **kw), sampler(ld, **kw)
    seen = set()
    for step in range(60):
        x, y = a.batch(step), b.batch(step)
        for k in ("origins", "directions", "near", "far", "codes", "latent_ids", "rgba", "pixels"):
            np.testing.assert_array_equal(getattr(x, k), getattr(y, k))
        seen |= set(zip(x.latent_ids.tolist(), x.frames.tolist()))
        assert len(set(x.latent_ids.tolist())) == 2  # two distinct identities per batch
    assert not seen & held
    assert seen == {(m, n) for m, d in ld.held.items() for n in np.nonzero(d.train)[0].tolist()}
    assert not np.array_equal(a.batch(1).pixels, a.batch(2).pixels)
    assert not np.array_equal(a.batch(1).pixels, sampler(ld, **{**kw, "seed": 8}).batch(1).pixels)


def test_sampler_rays_and_targets_match_the_frames(ds):
    ld = load_all(ds)
    s = sampler(ld, seed=0, identities=3, views=2, pixels=32, foreground_fraction=1.0)
    b = s.batch(0)
    frames = {f.key: f for f in iter_frames(ds)}
    H, W = ld.table.size
    for k in range(0, len(b), 7):
        f = frames[ld.held[int(b.latent_ids[k])].keys[b.frames[k]]]
        row, col = divmod(int(b.pixels[k]), W)
        assert f.alpha[row, col] > 0  # foreground_fraction = 1: all foreground
        np.testing.assert_allclose(b.rgba[k], f.rgba[row, col], atol=0)
        assert b.latent_ids[k] == f.identity_index
        # the surface point lies inside [near, far]
        t = f.depth[row, col] / np.dot(b.directions[k], f.camera_to_world[:3, 2])  # planar z / cos
        assert b.near[k] <= t <= b.far[k]
    assert (b.far > b.near).all()


def test_foreground_fraction_and_misses(ds):
    ld = load_all(ds)
    uni = sampler(ld, seed=1, identities=3, views=4, pixels=64).batch(0)
    fg = sampler(ld, seed=1, identities=3, views=4, pixels=64, foreground_fraction=0.75).batch(0)
    assert fg.rgba[:, 3].mean() > uni.rgba[:, 3].mean() + 0.2
    miss = uni.far <= uni.near
    assert miss.any() and (uni.rgba[miss, 3] == 0).all()  # rays missing the sphere see background


def test_errors(tmp_path, ds):
    (tmp_path / "empty" / "shards").mkdir(parents=True)
    with pytest.raises(SynthError, match="no committed frames"):
        load_all(tmp_path / "empty")
    with pytest.raises(SynthError, match="holdout_views"):
        load_all(ds, holdout_views=5)
    with pytest.raises(SynthError, match="no committed identity"):
        load_all(ds, rank=3, world=4)
