"""synth.geometry against library oracles: vertex normals and ray casting against trimesh,
rotations and the rigid fit against scipy's Rotation (and a brute-force optimality check),
with degenerate input: zero-area triangles, isolated vertices, rays parallel to
triangles, rotations at and near 180 degrees."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation
from trimesh.intersections import planes_lines
from trimesh.triangles import points_to_barycentric

from synth.geometry.normals import face_normals, normalize, vertex_normals
from synth.geometry.raycast import first_hits, ray_hit_counts
from synth.geometry.rotations import axis_angle_to_matrix, fit_rigid, matrix_to_axis_angle, rotation_pivot


def _bumpy_sphere_with_degenerates(seed: int = 0):
    """An icosphere with noisy radii, plus a zero-area triangle with a repeated corner, a
    zero-area triangle with collinear corners, a vertex used only by those, and an isolated
    vertex (the last one)."""
    rng = np.random.default_rng(seed)
    s = trimesh.creation.icosphere(subdivisions=2)
    v = s.vertices * (1.0 + 0.15 * rng.random(len(s.vertices)))[:, None]
    f = s.faces
    n = len(v)
    extra = np.array([[3.0, 0.0, 0.0], [4.0, 0.0, 0.0], [5.0, 0.0, 0.0], [9.0, 9.0, 9.0]])
    v = np.concatenate([v, extra])
    f = np.concatenate([f, [[0, 1, 1], [n, n + 1, n + 2]]])
    return v, f


# --------------------------------------------------------------------------- normals

def test_vertex_normals_match_trimesh_area_and_angle_weighted():
    v, f = _bumpy_sphere_with_degenerates()
    m = trimesh.Trimesh(v, f, process=False)
    fn = m.face_normals  # unit, zero for the degenerate faces
    want_area = trimesh.geometry.mean_vertex_normals(len(v), f, fn * m.area_faces[:, None])
    want_angle = trimesh.geometry.weighted_vertex_normals(len(v), f, fn, m.face_angles)
    np.testing.assert_allclose(vertex_normals(v, f), want_area, atol=1e-12)
    np.testing.assert_allclose(vertex_normals(v, f, weighting="angle"), want_angle, atol=1e-12)
    np.testing.assert_allclose(face_normals(v, f), fn, atol=1e-12)


def test_vertex_normals_degenerate_cases():
    v, f = _bumpy_sphere_with_degenerates()
    n_sphere = len(v) - 4
    for weighting in ("area", "angle"):
        vn = vertex_normals(v, f, weighting=weighting)
        assert np.all(np.isfinite(vn))
        # vertices only in zero-area triangles, and the isolated vertex: zero, or the fallback
        np.testing.assert_array_equal(vn[n_sphere:], 0.0)
        fb = vertex_normals(v, f, weighting=weighting, fallback=[0.0, 0.0, 1.0])
        np.testing.assert_array_equal(fb[n_sphere:], [[0.0, 0.0, 1.0]] * 4)
        np.testing.assert_array_equal(fb[:n_sphere], vn[:n_sphere])
        # the zero-area triangle (0, 1, 1) adds nothing: same normals as without it
        np.testing.assert_allclose(vn[:n_sphere], vertex_normals(v, f[:-2], weighting=weighting)[:n_sphere],
                                   atol=1e-15)
        np.testing.assert_allclose(np.linalg.norm(vn[:n_sphere], axis=1), 1.0, atol=1e-12)
        assert np.all(np.einsum("ij,ij->i", vn[:n_sphere], v[:n_sphere]) > 0)  # outward on a sphere
    np.testing.assert_array_equal(face_normals(v, f)[-2:], 0.0)
    with pytest.raises(ValueError, match="weighting"):
        vertex_normals(v, f, weighting="uniform")


def test_normalize_is_safe_at_zero():
    out = normalize(np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]]))
    np.testing.assert_allclose(out, [[0.6, 0.8, 0.0], [0.0, 0.0, 0.0]])


# --------------------------------------------------------------------------- ray casting

def _oracle_crossings(o, d, v, f):
    """(N, T) crossing parameter t (nan where the line misses the triangle or is parallel to
    it) and the smallest barycentric coordinate, from trimesh's plane-line intersection and
    barycentric conversion, every ray against every triangle."""
    tris = v[f]
    n, nt = len(o), len(f)
    unit, ok = trimesh.triangles.normals(tris)
    nrm = np.zeros((nt, 3))
    nrm[ok] = unit
    pairs_tri = np.tile(np.arange(nt), n)
    O, D = np.repeat(o, nt, 0), np.repeat(d, nt, 0)
    pts, valid, dist = planes_lines(tris[pairs_tri, 0], nrm[pairs_tri], O, D / np.linalg.norm(D, axis=1)[:, None],
                                    return_distance=True)
    t = np.full(n * nt, np.nan)
    bmin = np.full(n * nt, np.nan)
    t[valid] = dist / np.linalg.norm(D[valid], axis=1)
    bmin[valid] = points_to_barycentric(tris[pairs_tri[valid]], pts).min(1)
    return t.reshape(n, nt), bmin.reshape(n, nt)


def test_ray_casting_matches_trimesh():
    v, f = _bumpy_sphere_with_degenerates(1)
    rng = np.random.default_rng(2)
    o = rng.uniform(-2.5, 2.5, (300, 3))
    d = rng.normal(size=(300, 3)) * rng.uniform(0.5, 2.0, (300, 1))  # not unit: t in units of |d|
    t, bmin = _oracle_crossings(o, d, v, f)
    clear = ~np.any(np.abs(bmin) < 1e-9, axis=1) & ~np.any(np.abs(t - 1e-4) < 1e-9, axis=1)  # no edge grazing
    assert clear.sum() > 290
    hit = (bmin >= 0) & (t > 1e-4)
    np.testing.assert_array_equal(ray_hit_counts(o, d, v, f)[clear], hit.sum(1)[clear])
    assert np.any(hit.sum(1) == 0) and np.any(hit.sum(1) == 1) and np.any(hit.sum(1) >= 2)
    # a small chunk (one ray per block) gives the same answer
    np.testing.assert_array_equal(ray_hit_counts(o, d, v, f, chunk=1), ray_hit_counts(o, d, v, f))
    for farthest in (False, True):
        tri, bary, tt = first_hits(o, d, v, f, t_min=1e-4, farthest=farthest)
        tm = np.where(hit, t, -np.inf if farthest else np.inf)
        want = np.argmax(tm, 1) if farthest else np.argmin(tm, 1)
        some = hit.any(1)
        np.testing.assert_array_equal(tri[clear & some], want[clear & some])
        np.testing.assert_array_equal(tri[clear & ~some], -1)
        np.testing.assert_allclose(tt[clear & some], t[clear & some, want[clear & some]], rtol=1e-9)
        assert np.all(np.isinf(tt[~some]))
        # the barycentric point is the point on the ray
        k = np.nonzero(clear & some)[0]
        on_tri = np.einsum("nk,nkc->nc", bary[k], v[f[tri[k]]])
        np.testing.assert_allclose(on_tri, o[k] + tt[k, None] * d[k], atol=1e-9)


def test_ray_casting_degenerate_cases():
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [2.0, 2.0, 0.0], [2.0, 2.0, 0.0]])
    f = np.array([[0, 1, 2], [3, 4, 3], [0, 1, 1]])  # one real triangle in z = 0, two of zero area
    # rays in the plane of the triangle (parallel to it), through its interior: no hit
    o = np.array([[-1.0, 0.2, 0.0], [0.2, -1.0, 0.0]])
    d = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    assert ray_hit_counts(o, d, v, f, t_min=0.0).tolist() == [0, 0]
    tri, bary, t = first_hits(o, d, v, f)
    assert tri.tolist() == [-1, -1] and np.all(bary == 0) and np.all(np.isinf(t))
    # a ray straight through a zero-area triangle's point: never hits it
    assert ray_hit_counts([[2.0, 2.0, 1.0]], [[0.0, 0.0, -1.0]], v, f).tolist() == [0]
    # a corner and an edge count as hits (inclusive barycentric test)
    assert ray_hit_counts([[0.0, 0.0, 1.0], [0.5, 0.5, 1.0]], [[0.0, 0.0, -1.0]] * 2, v, f).tolist() == [1, 1]
    # t_min / t_max are exclusive bounds on the ray parameter
    o, d = [[0.2, 0.2, 1.0]], [[0.0, 0.0, -2.0]]  # hit at t = 0.5
    assert ray_hit_counts(o, d, v, f, t_min=0.49).tolist() == [1]
    assert ray_hit_counts(o, d, v, f, t_min=0.51).tolist() == [0]
    assert ray_hit_counts(o, d, v, f, t_min=0.0, t_max=0.49).tolist() == [0]
    tri, bary, t = first_hits(o, d, v, f)
    assert tri.tolist() == [0] and t[0] == pytest.approx(0.5)
    np.testing.assert_allclose(bary, [[0.6, 0.2, 0.2]], atol=1e-15)
    # no triangles at all
    tri, _, _ = first_hits(o, d, v, np.zeros((0, 3), np.int64))
    assert tri.tolist() == [-1]


# --------------------------------------------------------------------------- rotations

def _rotvecs(rng):
    axes = normalize(rng.normal(size=(40, 3)))
    return np.concatenate([
        rng.normal(size=(200, 3)),
        rng.normal(size=(30, 3)) * 1e-9, np.zeros((1, 3)),  # near and at zero
        np.pi * np.eye(3), np.pi * axes,  # exactly 180 degrees
        (np.pi - 1e-7) * axes, (np.pi - 1e-4) * axes, (np.pi - 2e-3) * axes,  # near 180 degrees
    ])


def test_axis_angle_to_matrix_matches_scipy():
    r = _rotvecs(np.random.default_rng(3))
    np.testing.assert_allclose(axis_angle_to_matrix(r), Rotation.from_rotvec(r).as_matrix(), atol=1e-14)
    r32 = r.astype(np.float32)
    R32 = axis_angle_to_matrix(r32)
    assert R32.dtype == np.float32
    np.testing.assert_allclose(R32, Rotation.from_rotvec(r32.astype(np.float64)).as_matrix(), atol=1e-6)


def test_matrix_to_axis_angle_matches_scipy():
    r = _rotvecs(np.random.default_rng(4))
    R = Rotation.from_rotvec(r).as_matrix()
    got = matrix_to_axis_angle(R)
    want = Rotation.from_matrix(R).as_rotvec()
    angle = np.linalg.norm(want, axis=1)
    at_pi = angle > np.pi - 1e-6  # r and -r are the same rotation there: compare up to sign
    err = np.linalg.norm(got - want, axis=1)
    err[at_pi] = np.minimum(err[at_pi], np.linalg.norm(got[at_pi] + want[at_pi], axis=1))
    assert err.max() < 1e-7
    assert np.all(np.linalg.norm(got, axis=1) <= np.pi + 1e-12)


def _weighted_cost(R, t, src, dst, w):
    return np.sum(w * np.sum((src @ R.T + t - dst) ** 2, axis=1))


@pytest.mark.parametrize("rotvec", [[0.3, -0.2, 0.5], [np.pi, 0.0, 0.0], [0.0, np.pi - 1e-6, 0.0],
                                    list(np.pi * normalize(np.array([1.0, 2.0, -2.0]))), [1e-10, 0.0, 0.0]])
def test_fit_rigid_recovers_exact_motions(rotvec):
    rng = np.random.default_rng(5)
    src = rng.normal(size=(30, 3))
    R0 = Rotation.from_rotvec(rotvec).as_matrix()
    t0 = np.array([0.1, -2.0, 0.7])
    R, t = fit_rigid(src, src @ R0.T + t0)
    np.testing.assert_allclose(R, R0, atol=1e-12)
    np.testing.assert_allclose(t, t0, atol=1e-12)


def test_fit_rigid_is_the_weighted_optimum():
    rng = np.random.default_rng(6)
    src = rng.normal(size=(50, 3))
    R0 = Rotation.from_rotvec([0.4, 1.1, -0.3]).as_matrix()
    dst = src @ R0.T + [1.0, 2.0, 3.0] + 0.2 * rng.normal(size=src.shape)
    w = rng.uniform(0.1, 2.0, len(src))
    R, t = fit_rigid(src, dst, w)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    best = _weighted_cost(R, t, src, dst, w)
    # no other rotation does better: 2000 random ones and small perturbations in all directions
    # (each with its own optimal translation)
    others = Rotation.random(2000, random_state=7).as_matrix()
    small = Rotation.from_rotvec(1e-3 * normalize(rng.normal(size=(200, 3)))).as_matrix() @ R
    wn = w / w.sum()
    for Rc in np.concatenate([others, small]):
        tc = wn @ dst - Rc @ (wn @ src)
        assert _weighted_cost(Rc, tc, src, dst, w) >= best - 1e-12


def test_fit_rigid_degenerate_input():
    rng = np.random.default_rng(8)
    src = rng.normal(size=(12, 3))
    # mirrored target: still a proper rotation
    R, _ = fit_rigid(src, src * [-1.0, 1.0, 1.0])
    assert np.linalg.det(R) == pytest.approx(1.0)
    # zero weights drop points
    dst = src @ Rotation.from_rotvec([0.2, 0.1, 0.0]).as_matrix().T
    dst[:4] += 5.0  # outliers, weighted out
    w = np.r_[np.zeros(4), np.ones(8)]
    R, t = fit_rigid(src, dst, w)
    R8, t8 = fit_rigid(src[4:], dst[4:])
    np.testing.assert_allclose(R, R8, atol=1e-12)
    np.testing.assert_allclose(t, t8, atol=1e-12)
    # one point: identity rotation, pure translation
    R, t = fit_rigid(src[:1], src[:1] + 1.0)
    np.testing.assert_array_equal(R, np.eye(3))
    np.testing.assert_allclose(t, [1.0, 1.0, 1.0])
    # collinear points: the rotation about the line is undetermined; scipy warns, the line is still aligned
    line = np.outer(np.arange(5.0), [1.0, 0.0, 0.0])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        R, t = fit_rigid(line, line[:, [1, 0, 2]])
    assert caught and np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(line @ R.T + t, line[:, [1, 0, 2]], atol=1e-12)
    with pytest.raises(ValueError):
        fit_rigid(src, src[:5])
    with pytest.raises(ValueError):
        fit_rigid(src, src, -np.ones(len(src)))


def test_rotation_pivot_at_180_degrees():
    R = Rotation.from_rotvec([np.pi, 0.0, 0.0]).as_matrix()
    pivot = np.array([0.0, 0.5, -0.25])
    c, axis, slide = rotation_pivot(R, pivot - R @ pivot, 0)
    np.testing.assert_allclose(np.cross(c - pivot, axis), 0.0, atol=1e-12)  # c lies on the axis through pivot
    assert abs(abs(axis[0]) - 1.0) < 1e-12 and abs(slide) < 1e-12
    with pytest.raises(ValueError, match="no rotation"):
        rotation_pivot(np.eye(3), np.zeros(3))
