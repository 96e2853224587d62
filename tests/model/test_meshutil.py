"""Closest points on triangles and the mirror image of surface points."""

from __future__ import annotations

import numpy as np
import pytest

from synth.model.meshutil import closest_point_on_triangle, mesh_mirror


def test_closest_point_on_triangle_against_dense_samples():
    rng = np.random.default_rng(3)
    regions = set()
    for _ in range(300):
        tri = rng.normal(size=(3, 3))
        x = 2.0 * rng.normal(size=3)
        q, w = closest_point_on_triangle(x, tri)
        assert abs(w.sum() - 1.0) < 1e-12 and np.all(w >= -1e-12)
        np.testing.assert_allclose(w @ tri, q, atol=1e-12)
        dense = rng.dirichlet([1.0, 1.0, 1.0], 20000) @ tri
        assert np.linalg.norm(q - x) <= np.linalg.norm(dense - x, axis=1).min() + 1e-9
        regions.add(int((w > 1e-12).sum()))  # 1: a vertex, 2: an edge, 3: the face
    assert regions == {1, 2, 3}
    # degenerate: a point on the triangle is its own closest point
    tri = np.eye(3)
    q, w = closest_point_on_triangle(np.full(3, 1 / 3), tri)
    np.testing.assert_allclose(w, 1 / 3)


def test_mesh_mirror_of_the_default_model(default_model):
    T = np.asarray(default_model.template, np.float64)
    tris = np.asarray(default_model.triangles, np.int64)
    mirror = mesh_mirror(T, tris)
    rng = np.random.default_rng(0)
    t = np.arange(len(tris))
    b = rng.dirichlet([1.0, 1.0, 1.0], len(tris))
    mt, mb = mirror(t, b)
    x = np.einsum("ck,ckd->cd", b, T[tris[t]])
    y = np.einsum("ck,ckd->cd", mb, T[tris[mt]])
    miss = np.linalg.norm(x * (-1.0, 1.0, 1.0) - y, axis=1)
    assert miss.max() < 1e-6  # quads split the other way on the mirror side: their fold only
    assert np.all(mb >= -1e-12) and np.allclose(mb.sum(1), 1.0)
    tt, bb = mirror(mt, mb)  # the mirror of the mirror is the point itself
    np.testing.assert_allclose(np.einsum("ck,ckd->cd", bb, T[tris[tt]]), x, atol=1e-6)
    # a mesh that is not symmetric is refused
    T2 = T.copy()
    T2[np.argmax(T2[:, 0])] += (0.0, 0.001, 0.0)
    with pytest.raises(ValueError, match="not mirror-symmetric"):
        mesh_mirror(T2, tris)


def test_mesh_midline_snaps_onto_x_zero(default_model):
    from synth.model.meshutil import mesh_midline

    T = np.asarray(default_model.template, np.float64)
    tris = np.asarray(default_model.triangles, np.int64)
    snap = mesh_midline(T, tris)
    rng = np.random.default_rng(1)
    near = np.nonzero(np.abs(T[tris].mean(axis=1)[:, 0]) < 0.01)[0]  # triangles within 1 cm of the midline
    t = rng.choice(near, 300)
    b = rng.dirichlet([1.0, 1.0, 1.0], 300)
    st, sb = snap(t, b)
    y = np.einsum("ck,ckd->cd", sb, T[tris[st]])
    assert np.abs(y[:, 0]).max() < 1e-9 and np.allclose(sb.sum(1), 1.0) and np.all(sb >= 0)
    x = np.einsum("ck,ckd->cd", b, T[tris[t]])
    assert np.all(np.linalg.norm(y - x, axis=1) >= np.abs(x[:, 0]) - 1e-12)  # never nearer than the plane
    assert np.median(np.linalg.norm(y - x, axis=1) - np.abs(x[:, 0])) < 0.002  # and about as near on the face
    st2, sb2 = snap(st, sb)  # a midline point stays where it is
    np.testing.assert_allclose(np.einsum("ck,ckd->cd", sb2, T[tris[st2]]), y, atol=1e-12)
