"""FLAME importer and its restricted unpickler, on a small synthetic FLAME-structured model.

No FLAME data is used: the test builds a sphere "head" with FLAME's keys, array layouts,
chumpy-wrapped shapedirs (the stream names chumpy.ch.Ch, as FLAME 2020 files do), a
scipy.sparse J_regressor, Python-2-style byte strings, and a 68-point embedding.
"""

from __future__ import annotations

import builtins
import io
import os
import pickle
import struct
import sys
import types

import numpy as np
import pytest
import scipy.sparse as sp

from synth.errors import ModelFormatError, SynthError
from synth.model.format import read_model, validate_model, write_model
from synth.model.head import HeadModel
from synth.model.importers.flame import import_flame, to_synth
from synth.model.importers.safe_pickle import load_npy_object, load_pickle, to_plain

R_HEAD = 0.09


# --------------------------------------------------------------------------- synthetic FLAME

def _uv_sphere(center, r, n_lat, n_lon, offset):
    verts = [np.array([0.0, r, 0.0])]
    for i in range(1, n_lat):
        th = np.pi * i / n_lat
        for j in range(n_lon):
            ph = 2 * np.pi * j / n_lon
            verts.append(np.array([r * np.sin(th) * np.sin(ph), r * np.cos(th), r * np.sin(th) * np.cos(ph)]))
    verts.append(np.array([0.0, -r, 0.0]))
    v = np.asarray(verts) + center
    tris = []
    ring = lambda i, j: 1 + (i - 1) * n_lon + (j % n_lon)  # noqa: E731
    for j in range(n_lon):
        tris.append([0, ring(1, j), ring(1, j + 1)])
        tris.append([len(v) - 1, ring(n_lat - 1, j + 1), ring(n_lat - 1, j)])
    for i in range(1, n_lat - 1):
        for j in range(n_lon):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            tris += [[a, c, b], [b, c, d]]
    return v, np.asarray(tris) + offset


def _ibug_layout() -> np.ndarray:
    """68 (x, y) points on the face plane of a FLAME-axes head (x = subject's left, y up)."""
    p = []
    for i in range(17):  # jaw: subject's right (-x) to left
        a = np.pi * i / 16
        p.append((-0.07 * np.cos(a), 0.01 - 0.07 * np.sin(a)))
    for s in (-1, 1):  # brows 17-21 (right), 22-26 (left), each from outer/inner in image order
        xs = np.linspace(-0.055, -0.012, 5) if s < 0 else np.linspace(0.012, 0.055, 5)
        p += [(x, 0.045 + 0.004 * np.cos((x - s * 0.033) * 40)) for x in xs]
    p += [(0.0, y) for y in np.linspace(0.03, 0.0, 4)]  # nose bridge 27-30 (30 = tip)
    p += [(x, -0.012) for x in np.linspace(-0.012, 0.012, 5)]  # nose base 31-35
    for cx in (-0.03, 0.03):  # eyes 36-41 (36 outer), 42-47 (42 inner): both start at -x
        p += [(cx + 0.012 * np.cos(np.radians(a)), 0.025 + 0.004 * np.sin(np.radians(a)))
              for a in (180, 135, 45, 0, -45, -135)]
    angs = np.radians(np.r_[180, 150, 120, 90, 60, 30, 0, -30, -60, -90, -120, -150])
    p += [(0.025 * np.cos(a), -0.03 + 0.01 * np.sin(a)) for a in angs]  # outer lip 48-59
    angs = np.radians(np.r_[180, 135, 90, 45, 0, -45, -90, -135])
    p += [(0.018 * np.cos(a), -0.03 + 0.003 * np.sin(a)) for a in angs]  # inner lip 60-67
    return np.asarray(p)


def make_flame(rng: np.random.Generator, n_comp: int = 400):
    head_v, head_f = _uv_sphere(np.zeros(3), R_HEAD, 18, 28, 0)
    eyes = []
    for cx in (-0.03, 0.03):  # FLAME's joint 3 here is the subject's RIGHT eye (-x): the importer must sort it out
        c = np.array([cx, 0.025, np.sqrt(R_HEAD**2 - cx**2 - 0.025**2) - 0.013])
        eyes.append(c)
    v_parts, f_parts, eye_ids = [head_v], [head_f], []
    off = len(head_v)
    for c in eyes:
        ev, ef = _uv_sphere(c, 0.012, 8, 10, off)
        v_parts.append(ev)
        f_parts.append(ef)
        eye_ids.append(np.arange(off, off + len(ev)))
        off += len(ev)
    v = np.concatenate(v_parts)
    f = np.concatenate(f_parts)
    # open the lids: drop head triangles whose centroid lies in front of an eyeball
    cen = v[f].mean(1)
    keep = np.ones(len(f), bool)
    for c in eyes:
        keep &= ~((np.linalg.norm(cen[:, :2] - c[:2], axis=1) < 0.009) & (cen[:, 2] > 0) & (f < len(head_v)).all(1))
    f = f[keep]
    n = len(v)
    w = np.zeros((n, 5))
    hv = np.arange(len(head_v))
    low = v[hv, 1] < -0.06
    jaw = (v[hv, 1] < -0.02) & (v[hv, 2] > 0.02) & ~low
    w[hv[low], 0] = 1
    w[hv[jaw], 2] = 0.7
    w[hv[jaw], 1] = 0.3
    w[hv[~low & ~jaw], 1] = 1
    w[eye_ids[0], 3] = 1
    w[eye_ids[1], 4] = 1
    jreg = np.zeros((5, n))
    jreg[0, hv[v[hv, 1] < -0.085]] = 1
    jreg[1, hv[np.abs(v[hv, 1] + 0.03) < 0.005]] = 1
    jreg[2, hv[jaw]] = 1
    jreg[3, eye_ids[0]] = 1
    jreg[4, eye_ids[1]] = 1
    jreg /= jreg.sum(1, keepdims=True)
    layout = _ibug_layout()
    targets = np.c_[layout, np.sqrt(R_HEAD**2 - (layout**2).sum(1))]
    head_tris = np.nonzero((f < len(head_v)).all(1))[0]
    cen = v[f[head_tris]].mean(1)
    lmk_f = head_tris[np.argmin(np.linalg.norm(cen[None] - targets[:, None], axis=2), axis=1)]
    bary = np.full((68, 3), 1 / 3)
    model = {
        "v_template": v, "f": f.astype(np.uint32), "shapedirs": rng.normal(0, 1e-4, (n, 3, n_comp)),
        "posedirs": np.zeros((n, 3, 36)), "J_regressor": sp.csc_matrix(jreg),
        "kintree_table": np.array([[2**32 - 1, 0, 1, 1, 1], [0, 1, 2, 3, 4]], np.int64),
        "weights": w, "J": jreg @ v, "bs_style": "lbs", "bs_type": "lrotmin",
    }
    embedding = {"full_lmk_faces_idx": lmk_f[None].astype(np.int64), "full_lmk_bary_coords": bary[None],
                 "static_lmk_faces_idx": lmk_f[17:], "static_lmk_bary_coords": bary[17:],
                 "dynamic_lmk_faces_idx": np.tile(lmk_f[:17], (79, 1)),
                 "dynamic_lmk_bary_coords": np.tile(bary[:17], (79, 1, 1))}
    return model, embedding


@pytest.fixture
def fake_chumpy(monkeypatch):
    """A stand-in module so the pickler writes 'chumpy.ch Ch' like FLAME 2020 files (the
    importer never imports it: the fixture is gone before anything is loaded)."""
    chumpy = types.ModuleType("chumpy")
    ch = types.ModuleType("chumpy.ch")

    class Ch:
        def __init__(self, x):
            self.x = np.asarray(x, np.float64)
            self._dirty_vars = set()
            self._itr = None
            self._depends_on_deps = {}
            self._make_dense = False
            self._make_sparse = False

        def __getstate__(self):
            return dict(self.__dict__)

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    ch.Ch = Ch
    chumpy.ch = ch
    monkeypatch.setitem(sys.modules, "chumpy", chumpy)
    monkeypatch.setitem(sys.modules, "chumpy.ch", ch)
    return Ch


class _Py2Pickler(pickle._Pickler):
    """Writes bytes as Python 2 'str' opcodes, as a Python 2 FLAME pickle does."""

    dispatch = pickle._Pickler.dispatch.copy()

    def save_py2_str(self, obj):
        n = len(obj)
        if n < 256:
            self.write(pickle.SHORT_BINSTRING + bytes([n]) + obj)
        else:
            self.write(pickle.BINSTRING + struct.pack("<i", n) + obj)
        self.memoize(obj)

    dispatch[bytes] = save_py2_str


def _write(tmp_path, model, embedding, name="generic_model.pkl", py2=False):
    mp, ep = tmp_path / name, tmp_path / "landmark_embedding.npy"
    buf = io.BytesIO()
    (_Py2Pickler(buf, protocol=2) if py2 else pickle.Pickler(buf, protocol=2)).dump(model)
    mp.write_bytes(buf.getvalue())
    np.save(ep, np.array(embedding, dtype=object), allow_pickle=True)
    return mp, ep


@pytest.fixture
def flame_files(tmp_path, fake_chumpy):
    model, emb = make_flame(np.random.default_rng(0))
    model["shapedirs"] = fake_chumpy(model["shapedirs"])
    files = _write(tmp_path, model, emb, py2=True)
    model["shapedirs"] = model["shapedirs"].x
    return files, model, emb


# --------------------------------------------------------------------------- tests

def test_import_converts_axes_bases_and_joints(flame_files, tmp_path):
    (mp, ep), model, _ = flame_files
    m = import_flame(mp, ep, identity_dims=300, expression_dims=100)
    validate_model(m)
    v = model["v_template"]
    np.testing.assert_allclose(m.template, to_synth(v), atol=1e-7)
    np.testing.assert_allclose(m.template[:, 2], v[:, 1], atol=1e-7)  # FLAME y (up) -> synth z
    np.testing.assert_allclose(m.template[:, 1], -v[:, 2], atol=1e-7)  # FLAME +z (face) -> synth -y
    assert m.identity_dims == 300 and m.expression_dims == 100
    sd = model["shapedirs"]
    np.testing.assert_allclose(m.identity_basis[5] * m.identity_scale[5], to_synth(sd[:, :, 5]), atol=1e-7)
    np.testing.assert_allclose(m.expression_basis[7] * m.expression_scale[7], to_synth(sd[:, :, 307]), atol=1e-7)
    # joints: J_regressor @ template, eye_l on +X although FLAME's joint 3 was on -X here
    jreg = model["J_regressor"].toarray()
    j = to_synth(jreg @ v)
    assert m.joint_names == ["neck", "head", "jaw", "eye_l", "eye_r"]
    np.testing.assert_allclose(m.joint_rest, j[[0, 1, 2, 4, 3]], atol=1e-6)
    assert m.joint_rest[3, 0] > 0 > m.joint_rest[4, 0]
    assert m.joint_parents.tolist() == [-1, 0, 1, 1, 1]
    jb = np.einsum("jv,vc->jc", jreg, to_synth(sd[:, :, 2]))[[0, 1, 2, 4, 3]]
    np.testing.assert_allclose(m.joint_identity_basis[2] * m.identity_scale[2], jb, atol=1e-7)
    np.testing.assert_allclose(m.skin_weights[:, 3], model["weights"][:, 4])
    # regions and landmarks
    assert np.all(m.skin_weights[m.regions["eye_l"], 3] == 1) and len(m.regions["eye_l"]) > 0
    assert m.regions["teeth"].size == 0 and len(m.regions["eyelash_lines"]) > 0
    assert np.all(m.template[m.regions["eyelash_lines"], 1] < 0)  # lid margins are on the face side
    assert m.landmarks["ibug68"][0].shape == (68,) and len(m.landmarks["dense"][0]) > 0
    hm = HeadModel(m)
    lms = hm.landmarks(np.zeros(300), np.zeros(100))[0]
    assert int(np.argmin(lms[:, 1])) == 30  # nose tip is the most forward landmark
    assert "licence" in m.license and "non-commercial" in m.license
    assert "posedirs" in m.extra["dropped"][0]
    # the regions the asset classes read are derived (synth/model/importers/derived.py)
    from synth.assets.classes import NAMES, unavailable

    parts = [m.regions[k] for k in ("face", "scalp", "ears", "neck", "shoulders")]
    assert sorted(np.concatenate(parts).tolist()) == m.regions["skin"].tolist()
    for side in ("l", "r"):
        assert len(m.regions[f"eyelid_{side}_upper"]) and len(m.regions[f"eyelid_{side}_lower"])
        assert np.all(np.isin(m.regions[f"iris_{side}"], m.regions[f"eye_{side}"]))
    # this synthetic FLAME is spheres: no ears, no lips; the classes that need them say so
    assert {c for c in NAMES if unavailable(m, c)} == {"glasses", "makeup"}
    assert unavailable(m, "glasses") == "the model has no ears region"
    out = write_model(m, tmp_path / "flame.npz")
    back = read_model(out)
    np.testing.assert_array_equal(back.identity_basis, m.identity_basis)
    assert back.meta() == m.meta()


def test_truncated_dims_and_static_dynamic_embedding(flame_files, tmp_path):
    (mp, ep), model, emb = flame_files
    static = {k: v for k, v in emb.items() if not k.startswith("full")}
    ep2 = tmp_path / "static.pkl"
    ep2.write_bytes(pickle.dumps(static, protocol=4))
    m = import_flame(mp, ep2, identity_dims=20, expression_dims=10)
    assert m.identity_dims == 20 and m.expression_dims == 10
    full = import_flame(mp, ep, identity_dims=20, expression_dims=10)
    np.testing.assert_array_equal(m.landmarks["ibug68"][0], full.landmarks["ibug68"][0])


def test_bad_input_is_one_clear_error(flame_files, tmp_path):
    (mp, ep), model, _ = flame_files
    with pytest.raises(SynthError, match="--landmarks"):
        import_flame(mp, None)
    with pytest.raises(ModelFormatError, match="not found"):
        import_flame(tmp_path / "missing.pkl", ep)
    with pytest.raises(ModelFormatError, match="identity_dims=301"):
        import_flame(mp, ep, identity_dims=301)
    broken = dict(model)
    del broken["weights"]
    bp = tmp_path / "broken.pkl"
    bp.write_bytes(pickle.dumps(broken))
    with pytest.raises(ModelFormatError, match="'weights' missing") as e:
        import_flame(bp, ep)
    assert "\n" not in str(e.value)
    bp.write_bytes(b"not a pickle at all")
    with pytest.raises(ModelFormatError, match="not a readable pickle"):
        import_flame(bp, ep)


class _System:
    def __init__(self, cmd):
        self.cmd = cmd

    def __reduce__(self):
        return (os.system, (self.cmd,))


class _Eval:
    def __init__(self, code):
        self.code = code

    def __reduce__(self):
        return (builtins.eval, (self.code,))


@pytest.mark.parametrize("kind", ["system", "eval"])
def test_malicious_model_pickle_is_refused_and_not_executed(tmp_path, kind, flame_files):
    (_, ep), model, _ = flame_files
    marker = tmp_path / "pwned"
    payload = _System(f"touch {marker}") if kind == "system" else _Eval(f"open({str(marker)!r}, 'w').write('x')")
    evil = dict(model, v_template=payload)
    p = tmp_path / "evil.pkl"
    for proto in (0, 2, 4):
        p.write_bytes(pickle.dumps(evil, protocol=proto))
        with pytest.raises(ModelFormatError, match=r"refusing to load .*pickle references .*(system|eval), "
                                                   r"which is not a plain array"):
            import_flame(p, ep)
    assert not marker.exists()


def test_malicious_landmark_npy_is_refused(tmp_path, flame_files):
    (mp, _), _, _ = flame_files
    marker = tmp_path / "pwned"
    ep = tmp_path / "evil.npy"
    np.save(ep, np.array({"lmk_face_idx": _System(f"touch {marker}")}, dtype=object), allow_pickle=True)
    with pytest.raises(ModelFormatError, match="refusing to load"):
        import_flame(mp, ep)
    assert not marker.exists()


def test_restricted_unpickler_round_trips_plain_arrays(tmp_path):
    data = {"a": np.arange(12.0).reshape(3, 4), "i": np.arange(5, dtype=np.uint32), "s": sp.csr_matrix(np.eye(3)),
            "c": sp.csc_matrix(np.eye(2)), "scalar": np.float32(2.5), "text": "lbs"}
    for proto in range(0, pickle.HIGHEST_PROTOCOL + 1):
        p = tmp_path / f"p{proto}.pkl"
        p.write_bytes(pickle.dumps(data, protocol=proto))
        out = to_plain(load_pickle(p))
        np.testing.assert_array_equal(out["a"], data["a"])
        assert out["i"].dtype == np.uint32 and out["s"].format == "csr" and out["c"].format == "csc"
        assert (out["s"] != data["s"]).nnz == 0 and out["scalar"] == 2.5 and out["text"] == "lbs"
    # the module names scipy used before 1.8 (how FLAME 2020's J_regressor is stored)
    old = pickle.dumps({"J": sp.csc_matrix(np.eye(3))}, protocol=2).replace(b"scipy.sparse._csc", b"scipy.sparse.csc")
    p = tmp_path / "old.pkl"
    p.write_bytes(old)
    assert to_plain(load_pickle(p))["J"].format == "csc"
    q = tmp_path / "plain.npy"
    np.save(q, np.arange(4))
    np.testing.assert_array_equal(load_npy_object(q), np.arange(4))
