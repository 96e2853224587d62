"""ICT-FaceKit importer against the real 10-identity sample in shared/ict-facekit (skipped
when it is absent; override its location with SYNTH_ICT_FACEKIT_DIR; tests.support.models), plus unit tests of
the OBJ reader and mesh utilities that need no data."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from synth.errors import ModelFormatError
from synth.model import meshutil as mu
from synth.model.format import read_model, validate_model, write_model
from synth.model.head import HeadModel
from synth.model.importers import ict_rig as ir
from synth.model.importers.obj import read_obj, read_obj_vertices
from tests.support.models import ict_dir

def _ict_dir() -> Path:
    return ict_dir()


def _plain_obj_vertices(path: Path) -> np.ndarray:
    """Independent, slow reference parser: metres, synth axes."""
    rows = [ln.split()[1:4] for ln in path.read_text().splitlines() if ln.startswith("v ")]
    p = np.asarray(rows, np.float64)
    return 0.01 * np.stack([p[:, 0], -p[:, 2], p[:, 1]], 1)


@pytest.fixture(scope="module")
def ict():
    from synth.model.importers.ict_facekit import import_ict_facekit

    d = _ict_dir()
    t0 = time.perf_counter()
    m = import_ict_facekit(d)
    return m, time.perf_counter() - t0


# --------------------------------------------------------------------------- real sample

def test_imports_and_validates(ict):
    m, seconds = ict
    validate_model(m)
    assert seconds < 30, f"import took {seconds:.1f} s"
    assert m.num_vertices == 26719 and m.identity_dims == 10
    assert m.expression_dims >= 53 and "jawOpen" in m.expression_names
    listed = json.loads((_ict_dir() / "FaceXModel" / "vertex_indices.json").read_text())["expressions"]
    assert m.expression_names[:len(listed)] == listed
    assert {"cheekRaiser_L", "PupilDilate_R"} <= set(m.expression_names)
    assert "MIT License" in m.license and "USC Institute for Creative Technologies" in m.license
    sizes = np.diff(m.poly_offsets)
    assert len(sizes) == 26384 and set(sizes.tolist()) == {3, 4}  # quads kept as polygons
    assert len(m.triangles) == int(np.sum(sizes - 2))


def test_zero_codes_reproduce_neutral_and_identity_code_reproduces_file(ict):
    m, _ = ict
    hm = HeadModel(m, dtype=np.float64)
    neutral = _plain_obj_vertices(_ict_dir() / "FaceXModel" / "generic_neutral_mesh.obj")
    v0 = hm.vertices(np.zeros(m.identity_dims), np.zeros(m.expression_dims))[0]
    np.testing.assert_allclose(v0, neutral, atol=1e-7)
    for k in (0, 3, 9):
        beta = np.zeros(m.identity_dims)
        beta[k] = 1.0
        vk = hm.vertices(beta, np.zeros(m.expression_dims))[0]
        np.testing.assert_allclose(vk, _plain_obj_vertices(_ict_dir() / "FaceXModel" / f"identity{k:03d}.obj"), atol=2e-7)
    e = np.zeros(m.expression_dims)
    e[m.expression_names.index("eyeBlink_L")] = 1.0
    np.testing.assert_allclose(hm.vertices(np.zeros(m.identity_dims), e)[0],
                               _plain_obj_vertices(_ict_dir() / "FaceXModel" / "eyeBlink_L.obj"), atol=2e-7)


def test_eye_joints_are_inside_the_eyeballs_and_follow_identity(ict):
    m, _ = ict
    hm = HeadModel(m, dtype=np.float64)
    j = m.joint_names
    eye_l, eye_r = m.joint_rest[j.index("eye_l")], m.joint_rest[j.index("eye_r")]
    assert eye_l[0] > 0.02 and eye_r[0] < -0.02  # +X is the subject's left
    for name, region in (("eye_l", "eye_l"), ("eye_r", "eye_r")):
        ids = m.regions[region]
        for beta in (np.zeros(10), 3 * np.eye(10)[0], -3 * np.eye(10)[4]):
            c = hm.joint_transforms(beta)[0, j.index(name), :3, 3]
            v = hm.vertices(beta, np.zeros(m.expression_dims))[0][ids]
            assert np.all(v.min(0) < c) and np.all(c < v.max(0))
            d = np.linalg.norm(v[np.isin(ids, m.regions["sclera"])] - c, axis=1)
            assert d.std() < 0.1 * d.mean()  # the sclera is a sphere about the joint
    assert np.abs(m.joint_identity_basis).max() > 0


def test_jaw_rotation_matches_jaw_open_on_the_lower_teeth(ict):
    m, _ = ict
    hm = HeadModel(m, dtype=np.float64)
    rot = np.zeros((5, 3))
    rot[m.joint_names.index("jaw"), 0] = m.extra["jaw_open_angle_rad"]
    assert 0.2 < rot[2, 0] < 0.8
    posed = hm.vertices(np.zeros(10), np.zeros(m.expression_dims), rot)[0]
    e = np.zeros(m.expression_dims)
    e[m.expression_names.index("jawOpen")] = 1
    shaped = hm.vertices(np.zeros(10), e)[0]
    low = ir.rng(ir.TEETH_LOWER)
    assert np.linalg.norm(posed[low] - shaped[low], axis=1).max() < 5e-4
    assert np.all(m.skin_weights[m.regions["eyes"]].max(1) == 1)  # eyeballs are rigid


def test_landmarks_and_regions(ict):
    m, _ = ict
    hm = HeadModel(m)
    lms = hm.landmarks(np.zeros(10), np.zeros(m.expression_dims))[0]
    assert lms.shape == (68, 3) and int(np.argmin(lms[:, 1])) == 30  # nose tip is the most forward
    assert lms[36, 0] < 0 < lms[45, 0]  # iBUG 36 = subject's right outer eye corner
    assert 500 <= len(m.landmarks["dense"][0]) <= 700
    skin = set(range(*ir.SKIN))
    parts = [set(m.regions[k].tolist()) for k in ("face", "scalp", "ears", "neck", "shoulders")]
    assert sum(len(p) for p in parts) == len(skin) and set().union(*parts) == skin == set(m.regions["skin"].tolist())
    for k in ("face", "scalp", "ears", "eyes", "teeth", "mouth_interior", "eyelash_lines", "neck", "brow",
              "beard", "iris", "sclera", "eye_l", "eye_r", "lips"):
        assert len(m.regions[k]) > 0, k
    v = m.template
    ears = v[m.regions["ears"]]
    assert np.all(np.abs(ears[:, 0]) > 0.05)
    assert v[m.regions["scalp"], 2].mean() > v[m.regions["face"], 2].mean() > v[m.regions["neck"], 2].mean()
    assert np.all(np.isin(m.regions["brow"], m.regions["face"]))
    # derived (synth/model/importers/derived.py): shoulders below the root joint, sides by x
    assert v[m.regions["shoulders"], 2].max() < m.joint_rest[0, 2] <= v[m.regions["neck"], 2].min()
    for k in ("ear", "brow", "iris", "sclera"):
        assert np.all(v[m.regions[f"{k}_l"], 0] > 0) and np.all(v[m.regions[f"{k}_r"], 0] < 0), k
    for side in ("l", "r"):  # the iris is the corneal cap of the eye's outer shell, in front
        c, r = mu.fit_sphere(v[m.regions[f"sclera_{side}"]])
        q = v[m.regions[f"iris_{side}"]] - c
        cos = -q[:, 1] / np.linalg.norm(q, axis=1)
        assert 150 <= len(q) <= 300 and cos.min() > np.cos(np.radians(30.0))
        assert np.linalg.norm(q, axis=1).mean() > r + 2e-4  # proud of the sclera
    assert set(m.regions["eye_interior"].tolist()) == set(range(*ir.IRIS["l"])) | set(range(*ir.IRIS["r"]))
    for side, (inner, outer) in (("l", (42, 45)), ("r", (39, 36))):
        up, lo = (v[m.regions[f"eyelid_{side}_{lid}"]] for lid in ("upper", "lower"))
        assert len(up) >= 10 and len(lo) >= 10  # ICT roots ~18 lashes a lid
        assert up[:, 2].mean() > lms[[inner, outer], 2].mean() > lo[:, 2].mean()
        assert len(np.intersect1d(m.regions[f"eyelid_{side}_upper"], m.regions[f"eyelid_{side}_lower"])) == 0


def test_generic_ear_rule_agrees_with_topology(ict):
    """The ray-cast ear rule (used for FLAME) finds most of ICT's labelled ears."""
    from synth.model.importers.regions import ear_flaps

    m, _ = ict
    lm = mu.barycentric_points(m.template, m.triangles, *m.landmarks["ibug68"])
    found = ear_flaps(m.template, m.triangles, ir.rng(ir.SKIN), lm)
    truth = m.regions["ears"]
    assert len(np.intersect1d(found, truth)) / len(found) > 0.9
    assert len(np.intersect1d(found, truth)) / len(truth) > 0.5


def test_round_trip(ict, tmp_path):
    m, _ = ict
    back = read_model(write_model(m, tmp_path / "ict.npz"))
    assert back.meta() == m.meta()
    for k in ("template", "triangles", "identity_basis", "expression_basis", "joint_rest", "joint_identity_basis",
              "skin_weights", "uvs", "tri_uv", "poly_offsets", "poly_indices", "poly_uv"):
        np.testing.assert_array_equal(getattr(back, k), getattr(m, k))
    assert back.regions.keys() == m.regions.keys()
    for s in m.landmarks:
        np.testing.assert_array_equal(back.landmarks[s][0], m.landmarks[s][0])


def test_bad_input_names_the_file(tmp_path):
    from synth.model.importers.ict_facekit import import_ict_facekit

    with pytest.raises(ModelFormatError, match="folder not found"):
        import_ict_facekit(tmp_path / "nope")
    with pytest.raises(ModelFormatError, match="generic_neutral_mesh.obj"):
        import_ict_facekit(tmp_path)
    src = _ict_dir() / "FaceXModel"
    dst = tmp_path / "FaceXModel"
    dst.mkdir()
    for p in src.iterdir():
        if p.name != "identity003.obj":
            (dst / p.name).symlink_to(p)
    lines = (src / "identity003.obj").read_text().splitlines()
    (dst / "identity003.obj").write_text("\n".join(ln for i, ln in enumerate(lines) if i != 40) + "\n")
    with pytest.raises(ModelFormatError, match=r"identity003\.obj") as e:
        import_ict_facekit(tmp_path)
    assert "vertex count 26718" in str(e.value) and "\n" not in str(e.value)


# --------------------------------------------------------------------------- no data needed

def test_obj_reader_quads_uvs_and_index_forms(tmp_path):
    p = tmp_path / "q.obj"
    p.write_text("# c\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                 "vn 0 0 1\nusemtl x\nf 1/1/1 2/2/1 3/3/1 4/4/1\nf -4/-3 -1/-2 -3/-3\n")
    m = read_obj(p)
    assert m.poly_offsets.tolist() == [0, 4, 7]
    assert m.poly_indices.tolist() == [0, 1, 2, 3, 1, 4, 2]
    assert m.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 2]]
    assert m.tri_uv.tolist() == [[0, 1, 2], [0, 2, 3], [1, 2, 1]]
    p2 = tmp_path / "n.obj"
    p2.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0 1.0\nf 1//1 2//1 3//1\n")
    m2 = read_obj(p2)
    assert m2.uvs is None and m2.triangles.tolist() == [[0, 1, 2]]
    assert m.group_names == [""] and m.poly_group.tolist() == [0, 0]  # no 'g' lines: one unnamed group
    pg = tmp_path / "g.obj"
    pg.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\ng head \nf 1 2 3\ng\tteeth\r\nf 3 2 1\ng head\nf 1 3 2\n")
    mg = read_obj(pg)
    assert mg.group_names == ["", "head", "teeth"] and mg.poly_group.tolist() == [0, 1, 2, 1]
    np.testing.assert_array_equal(read_obj_vertices(p2), [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    p3 = tmp_path / "i.obj"  # interleaved v lines: slow path
    p3.write_text("v 0 0 0\nvt 0 0\nv 1 2 3\r\nf 1 2 1\n")
    np.testing.assert_array_equal(read_obj_vertices(p3), [[0, 0, 0], [1, 2, 3]])
    bad = tmp_path / "b.obj"
    bad.write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(ModelFormatError, match="outside"):
        read_obj(bad)
    with pytest.raises(ModelFormatError, match="not found"):
        read_obj_vertices(tmp_path / "missing.obj")


def test_meshutil_sphere_rigid_fps_and_landmarks():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(200, 3))
    pts = np.array([0.1, -0.2, 0.3]) + 0.015 * d / np.linalg.norm(d, axis=1, keepdims=True)
    c, r = mu.fit_sphere(pts)
    np.testing.assert_allclose(c, [0.1, -0.2, 0.3], atol=1e-12)
    assert abs(r - 0.015) < 1e-12
    from synth.geometry.rotations import axis_angle_to_matrix, fit_rigid, rotation_pivot

    R = axis_angle_to_matrix(np.array([0.4, 0.0, 0.0]))
    pivot = np.array([0.0, -0.02, -0.005])
    moved = (pts - pivot) @ R.T + pivot
    Rf, tf = fit_rigid(pts, moved)
    cp, axis, slide = rotation_pivot(Rf, tf, 0)
    np.testing.assert_allclose(cp, pivot, atol=1e-9)
    assert abs(slide) < 1e-12 and axis[0] > 0.999
    idx = mu.farthest_point_sampling(pts, 10, start=5)
    assert idx[0] == 5 and len(set(idx.tolist())) == 10
    np.testing.assert_array_equal(idx, mu.farthest_point_sampling(pts, 10, start=5))
    tris = np.array([[0, 1, 2], [2, 1, 3]])
    tri, bary = mu.vertex_landmarks(tris, np.array([3, 0, 2]))
    assert tri.tolist() == [1, 0, 0] and bary.tolist() == [[0, 0, 1], [1, 0, 0], [0, 0, 1]]
    loops = mu.boundary_loops(tris)
    assert len(loops) == 1 and sorted(loops[0].tolist()) == [0, 1, 2, 3]
