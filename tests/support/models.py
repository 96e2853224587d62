"""Head models for tests that must hold on more than the embedded default: the ICT-FaceKit
sample (imported from ``shared/ict-facekit``; skipped when absent) and a remeshed copy of any
model (another density and vertex order, the same surface), so that no rig can lean on the
default model's topology."""

from __future__ import annotations

import dataclasses
import functools
import os
from pathlib import Path

import numpy as np
import pytest
from scipy import sparse

from synth.model.format import HeadModelData, validate_model

#: ICT-FaceKit sample: $SYNTH_ICT_FACEKIT_DIR, else ``shared/ict-facekit`` beside the checkout
#: (a worktree under ``wt/`` looks one level further up)
_ROOT = Path(__file__).resolve().parents[2]
ICT_CANDIDATES = [Path(p) for p in (os.environ.get("SYNTH_ICT_FACEKIT_DIR"),) if p] + [
    _ROOT.parent / "shared" / "ict-facekit", _ROOT.parent.parent / "shared" / "ict-facekit"]


def ict_dir() -> Path:
    """The ICT-FaceKit sample directory, or skip the test."""
    for d in ICT_CANDIDATES:
        if (d / "FaceXModel" / "generic_neutral_mesh.obj").is_file():
            return d
    pytest.skip(f"ICT-FaceKit sample not found at {ICT_CANDIDATES[0]} (set SYNTH_ICT_FACEKIT_DIR)")


@functools.lru_cache(maxsize=1)
def _ict(path: str) -> HeadModelData:
    from synth.model.importers.ict_facekit import import_ict_facekit

    return import_ict_facekit(path)


def ict_model() -> HeadModelData:
    """The imported ICT-FaceKit sample (imported once per process; skip if absent)."""
    return _ict(str(ict_dir()))


#: regions that partition the skin (synth/model/importers/derived.py)
SKIN_PARTS = ("face", "scalp", "ears", "neck", "shoulders")


def _child_bary(bary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(child 0..3, barycentrics in it) of points given by barycentrics in a parent triangle
    (a, b, c) split 1-to-4 as :func:`synth.assets.fit.meshops.subdivide` does:
    [a, m01, m20], [m01, b, m12], [m20, m12, c], [m01, m12, m20]."""
    x, y, z = bary.T
    child = np.where(x >= 0.5, 0, np.where(y >= 0.5, 1, np.where(z >= 0.5, 2, 3)))
    out = np.stack([x + y - z, y + z - x, x + z - y], 1)  # centre child
    out = np.where((child == 0)[:, None], np.stack([2 * x - 1, 2 * y, 2 * z], 1), out)
    out = np.where((child == 1)[:, None], np.stack([2 * x, 2 * y - 1, 2 * z], 1), out)
    out = np.where((child == 2)[:, None], np.stack([2 * x, 2 * y, 2 * z - 1], 1), out)
    return child, out


def remeshed(data: HeadModelData, seed: int = 0) -> HeadModelData:
    """``data`` subdivided 1-to-4 (midpoints: the same surface, 4x the triangles), its vertices
    and triangles shuffled. Everything per vertex is carried by the same linear map (bases, skin
    weights); a new vertex is in a region when both ends of its edge are (on the border of two
    parts of the skin, in its lower-indexed end's part); landmarks keep their
    surface points; UVs are split with the triangles; polygons and the default model's vertex-
    indexed extras (eyelid rig, mirror map) are dropped: an imported model has neither."""
    from synth.assets.fit.meshops import subdivide

    V, T = data.num_vertices, len(data.triangles)
    W, faces, _ = subdivide(sparse.identity(V, format="csr"), data.triangles)
    rng = np.random.default_rng(seed)
    perm = rng.permutation(W.shape[0])  # new vertex k is subdivided vertex perm[k]
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    W = W[perm]
    W.sort_indices()
    tperm = rng.permutation(len(faces))  # new triangle j is subdivided triangle tperm[j]
    tinv = np.empty_like(tperm)
    tinv[tperm] = np.arange(len(tperm))
    tris = inv[faces[tperm]].astype(np.int32)

    def per_vertex(a):
        return np.asarray(W @ np.asarray(a, np.float64), np.float32)

    member = {}
    for name, ids in data.regions.items():
        m = np.zeros(V)
        m[np.asarray(ids, np.int64)] = 1.0
        member[name] = np.asarray(W @ m) > 1.0 - 1e-9
    # the skin stays partitioned: a midpoint between two parts joins its lower-indexed end's
    first = np.asarray(W.indices[W.indptr[:-1]])  # each row's first (lowest) source vertex
    parts = [r for r in SKIN_PARTS if r in data.regions]
    loose = ~np.any([member[r] for r in parts], axis=0) & member.get("skin", np.zeros(len(perm), bool))
    for r in parts:
        src = np.zeros(V, bool)
        src[np.asarray(data.regions[r], np.int64)] = True
        member[r] |= loose & src[first]
    regions = {name: np.nonzero(m)[0].astype(np.int32) for name, m in member.items()}
    landmarks = {}
    for name, (tri, bary) in data.landmarks.items():
        child, b = _child_bary(np.asarray(bary, np.float64))
        landmarks[name] = (tinv[child * T + np.asarray(tri, np.int64)].astype(np.int32), b.astype(np.float32))
    uv = {}
    if data.uvs is not None and data.tri_uv is not None:
        tu = np.asarray(data.tri_uv, np.int64)
        U = len(data.uvs)
        mids = 0.5 * (data.uvs[tu] + data.uvs[np.roll(tu, -1, axis=1)])  # (T, 3): m01, m12, m20
        m = U + 3 * np.arange(T)[:, None] + np.arange(3)[None]
        a, b_, c = tu.T
        m01, m12, m20 = m.T
        kids = np.concatenate([np.stack(k, 1) for k in ([a, m01, m20], [m01, b_, m12], [m20, m12, c],
                                                          [m01, m12, m20])])
        uv = {"uvs": np.concatenate([data.uvs, mids.reshape(-1, 2)]).astype(np.float32),
              "tri_uv": kids[tperm].astype(np.int32)}
    extra = {k: v for k, v in data.extra.items() if k not in ("eyelids", "mirror")}
    out = dataclasses.replace(
        data, name=f"{data.name}-remeshed", template=per_vertex(data.template), triangles=tris,
        identity_basis=np.stack([per_vertex(b) for b in data.identity_basis]),
        expression_basis=np.stack([per_vertex(b) for b in data.expression_basis]),
        skin_weights=per_vertex(data.skin_weights), regions=regions, landmarks=landmarks,
        poly_offsets=None, poly_indices=None, poly_uv=None, uvs=uv.get("uvs"), tri_uv=uv.get("tri_uv"),
        extra=extra, provenance={**data.provenance, "remeshed": f"1-to-4 midpoint subdivision, shuffled (seed {seed})"})
    validate_model(out)
    return out
