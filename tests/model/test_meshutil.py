"""The mirror image of surface points and the midline of a symmetric mesh."""

from __future__ import annotations

import numpy as np
import pytest

from synth.model.meshutil import mesh_mirror


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
