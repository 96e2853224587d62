"""synth.geometry.raycast: brute-force ray casting against trimesh's plane/barycentric maths,
rays parallel to triangles and through zero-area ones, exclusive t bounds; the grid of
parity rays (RayGrid) against brute force on a torus (a surface that folds back on itself)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from trimesh.intersections import planes_lines
from trimesh.triangles import points_to_barycentric

from synth.geometry.raycast import RayGrid, first_hits, ray_hit_counts
from tests.support.meshes import bumpy_sphere_with_degenerates

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
    v, f = bumpy_sphere_with_degenerates(1)
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


def _torus_mesh():
    m = trimesh.creation.torus(0.1, 0.03, major_sections=40, minor_sections=20)
    return np.asarray(m.vertices), np.asarray(m.faces)


@pytest.mark.parametrize("axis", [[0.0, 1.0, 0.0], [1.0, 0.3, 0.1], [0.0, 0.0, 1.0]])
def test_ray_grid_matches_brute_force_crossings(axis):
    """Lines along one axis through a torus (up to four crossings: a surface that folds back
    over itself): the grid gives the same crossings as brute-force ray casting both ways, and
    the parity on either side decides inside (the winding number is 1 inside a torus)."""
    V, F = _torus_mesh()
    d = np.asarray(axis) / np.linalg.norm(axis)
    g = RayGrid(V, F, d, cell=0.004)
    rng = np.random.default_rng(7)
    P = rng.uniform(-0.14, 0.14, (400, 3)) * [1, 1, 0.3]
    t = g.hits(P)
    fwd = ray_hit_counts(P, np.broadcast_to(d, P.shape), V, F, t_min=0.0)
    back = ray_hit_counts(P, np.broadcast_to(-d, P.shape), V, F, t_min=0.0)
    np.testing.assert_array_equal(np.sum(t > 0, axis=1), fwd)
    np.testing.assert_array_equal(np.sum(t < 0, axis=1), back)
    assert np.any(fwd + back == (2 if abs(d[2]) > 0.9 else 4))
    ring = np.hypot(np.hypot(P[:, 0], P[:, 1]) - 0.1, P[:, 2])
    sure = np.abs(ring - 0.03) > 2e-3  # away from the faceted surface
    for direction in (1.0, -1.0):
        np.testing.assert_array_equal(g.inside(P[sure], direction), ring[sure] < 0.03)
    _, _, t_first = first_hits(P, np.broadcast_to(d, P.shape), V, F)
    np.testing.assert_allclose(g.first_hit(P, 1.0), t_first, rtol=1e-9, atol=1e-12)


def test_ray_grid_outside_the_grid_and_shared_edges():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float64)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    g = RayGrid(V, F, [0.0, 0.0, 1.0], cell=0.25)
    far = np.array([[5.0, 5.0, 1.0], [-3.0, 0.5, -1.0]])
    assert np.isnan(g.hits(far)).all() and not g.inside(far).any() and np.isinf(g.first_hit(far)).all()
    # the documented edge rule: a shared edge's interior counts in both triangles; a corner
    # only where it is corner 2 (vertex 2 is corner 2 of both triangles, vertex 1 of neither)
    lines = np.array([[0.5, 0.5, -1.0], [0.25, 0.75, -2.0], [0.0, 1.0, -1.0], [1.0, 0.0, -1.0], [0.2, 0.2, -3.0]])
    np.testing.assert_array_equal(np.sum(g.hits(lines) > 0, axis=1), [2, 2, 2, 0, 1])
    np.testing.assert_allclose(g.first_hit(lines), [1.0, 2.0, 1.0, np.inf, 3.0])



def test_edge_eps_keeps_rays_along_a_shared_edge_from_slipping_between_its_triangles():
    """A ray in a symmetric mesh's midline plane runs along its midline edges. Cast from a metre
    away at a 6 mm triangle pair whose off-plane corners come first (as hm08's do at the chin),
    rounding often gives *both* triangles a barycentric coordinate of about -2e-15 there, and the
    ray passes between them to whatever lies behind (prior.fit.contour's chin line did). With
    ``edge_eps`` every ray hits the pair, on the edge."""
    rng = np.random.default_rng(0)
    a = np.array([0.0, -0.13, 0.62])
    b = a + [0.0, 0.004, -0.005]
    c = 0.5 * (a + b) + [0.0058, 0.002, 0.001]
    behind = [[-1.0, 1.0, -1.0], [1.0, 1.0, -1.0], [0.0, 1.0, 2.0]]
    v = np.array([a, b, c, c * [-1.0, 1.0, 1.0], *behind])
    f = np.array([[3, 1, 0], [2, 0, 1], [4, 5, 6]])  # the pair (mirror images), then a plane behind
    target = a + rng.uniform(0.0, 1.0, (400, 1)) * (b - a)
    ang = rng.uniform(0.0, 2.0 * np.pi, 400)
    d = np.stack([np.zeros(400), np.cos(ang), np.sin(ang)], 1)
    o = target - d  # a metre out
    tri, bary, t = first_hits(o, d, v, f, edge_eps=1e-9)
    assert np.all((tri == 0) | (tri == 1))
    np.testing.assert_allclose(t, 1.0, atol=1e-9)
    assert np.all(bary >= 0.0) and np.allclose(bary.sum(1), 1.0)
    np.testing.assert_allclose(np.einsum("nk,nkc->nc", bary, v[f[tri]]), target, atol=1e-9)
    tri0, _, _ = first_hits(o, d, v, f)  # without: some slip through (about one in six here)
    assert np.all(np.isin(tri0, [-1, 0, 1, 2])) and np.sum(tri0 < 0) + np.sum(tri0 == 2) > 10
