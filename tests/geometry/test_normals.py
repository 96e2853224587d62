"""synth.geometry.normals against trimesh (area- and angle-weighted vertex normals), with
zero-area triangles, isolated vertices and zero vectors."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from synth.geometry.normals import face_normals, normalize, vertex_normals
from tests.support.meshes import bumpy_sphere_with_degenerates

# --------------------------------------------------------------------------- normals

def test_vertex_normals_match_trimesh_area_and_angle_weighted():
    v, f = bumpy_sphere_with_degenerates()
    m = trimesh.Trimesh(v, f, process=False)
    fn = m.face_normals  # unit, zero for the degenerate faces
    want_area = trimesh.geometry.mean_vertex_normals(len(v), f, fn * m.area_faces[:, None])
    want_angle = trimesh.geometry.weighted_vertex_normals(len(v), f, fn, m.face_angles)
    np.testing.assert_allclose(vertex_normals(v, f), want_area, atol=1e-12)
    np.testing.assert_allclose(vertex_normals(v, f, weighting="angle"), want_angle, atol=1e-12)
    np.testing.assert_allclose(face_normals(v, f), fn, atol=1e-12)


def test_vertex_normals_degenerate_cases():
    v, f = bumpy_sphere_with_degenerates()
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
