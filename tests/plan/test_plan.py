"""The plan: content, schema, reader, CLI behaviour, expressions, identities and assets."""

from __future__ import annotations

import fnmatch
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from synth.cli.main import main
from synth.assets.catalogue import load_catalogue
from synth.assets.classes import NAMES
from synth.config import ExpressionConfig, IdentityConfig, load_config
from synth.conventions import project
from synth.dataset.layout import frame_key
from synth.errors import SynthError
from synth.plan import assets, expressions, identities, io, planner
from synth.plan.cameras import min_pairwise_angle_deg
from synth.model.builders.makehuman import ARKIT_NAMES
from tests.support.toy_model import make_toy_model, write_toy_model

ARKIT = list(ARKIT_NAMES)  # the ARKit blendshape names, as the default model uses them


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return write_toy_model(tmp_path_factory.mktemp("model") / "toy.npz")


@pytest.fixture(scope="module")
def plan20(tmp_path_factory, toy):
    """20 identities, seed 7, paper defaults (on the toy model)."""
    out = tmp_path_factory.mktemp("plans") / "p20"
    assert main(["plan", "--identities", "20", "--seed", "7", "--out", str(out), "--model", str(toy), "-q"]) == 0
    return out


def test_every_expression_has_30_views_25_degrees_apart(plan20):
    plan = io.load_plan(plan20)
    assert len(plan.shard_ids()) == 20 and plan.header["num_frames"] == 20 * 13 * 30
    n = 0
    for sid in plan.shard_ids():
        spec = plan.shard(sid, validate_spec=True)
        for ident in spec["identities"]:
            assert len(ident["expressions"]) == 13
            for e in ident["expressions"]:
                fr = e["frames"]
                assert [f["view_index"] for f in fr] == list(range(30))
                az = np.array([[f["camera"]["azimuth_deg"] for f in fr]])
                el = np.array([[f["camera"]["elevation_deg"] for f in fr]])
                assert min_pairwise_angle_deg(az, el)[0] >= 25.0 - 1e-5  # stored to 1e-8 degrees
                n += len(fr)
    assert n == 7800


def test_frames_carry_opencv_cameras_that_look_at_the_face(plan20):
    plan = io.load_plan(plan20)
    spec = plan.shard("shard_000003")
    frame_schema = json.loads((Path(io.__file__).parents[1] / "schemas" / "frame.schema.json").read_text())
    cam_schema = frame_schema["properties"]["camera"]  # the render stage's frame schema
    import jsonschema

    ident = spec["identities"][0]
    for e in ident["expressions"][:3]:
        for f in e["frames"]:
            assert f["frame_id"] == frame_key(3, e["expression_index"], f["view_index"])
            c = f["camera"]
            jsonschema.validate(c, cam_schema)
            K, w2c, c2w = (np.array(c[k]) for k in ("K", "world_to_camera", "camera_to_world"))
            assert K.shape == (3, 3) and w2c.shape == (4, 4) and (c["width"], c["height"]) == (256, 256)
            assert np.allclose(w2c @ c2w, np.eye(4), atol=1e-7)
            uv, z = project(K, w2c, np.array([c["target"]]))
            assert np.allclose(uv[0], [128.0, 128.0], atol=1e-4) and np.isclose(z[0], c["radius_m"], atol=1e-6)
            assert c["near"] < z[0] < c["far"] and 0 <= f["seed"] < 2**31
    # the target is the centre of this identity's neutral head (its bounding box, brute force
    # over every head vertex), and the distance fits the head's bounding sphere into the frame
    from synth.model.head import HeadModel

    m = plan.model_data()
    v = HeadModel(m, np.float64).vertices(np.array(ident["identity_code"]), np.zeros(m.expression_dims))[0]
    head = np.setdiff1d(m.regions.get("skin", np.arange(len(v))),
                        np.concatenate([m.regions.get(r, np.zeros(0, int)) for r in ("neck", "shoulders")]))
    box = 0.5 * (v[head].min(0) + v[head].max(0))
    assert np.allclose(ident["target"], box, atol=1e-4)
    from synth.plan.assets import hair_reach_m

    r = np.linalg.norm(v[head] - box, axis=1).max() + 0.03 + hair_reach_m([ident["assets"]])[0]  # + head_margin_m
    half = np.arctan(128.0 / K[0, 0])
    for e in ident["expressions"]:
        for f in e["frames"]:
            fill = np.arcsin(r / f["camera"]["radius_m"]) / half
            assert 0.75 - 1e-3 <= fill <= 0.95 + 1e-3  # camera.head_fill


def test_header_summary_and_reader(plan20, toy):
    plan = io.load_plan(plan20)
    h = plan.header
    assert h["run_seed"] == 7 and h["model"]["path"] == str(Path(toy).resolve())
    assert h["config"]["dataset"]["views_per_expression"] == 30 and h["config"]["render"]["resolution"] == [256, 256]
    assert plan.expected()["shard_000019"][0] == "id000019_ex00_v00" and len(plan.expected()["shard_000000"]) == 390
    assert plan.render_settings()["preset"] == "preview" and plan.lighting()["environment"] == "studio"
    assert plan.model_data().name == "toy-ellipsoid"
    s = json.loads((plan20 / "summary.json").read_text())
    assert s["plan_hash"] == plan.plan_hash and s["frames"] == 7800
    assert s["cameras"]["smallest_pairwise_angle_deg"] >= 25.0 and 0 < s["cameras"]["acceptance_rate"] < 1
    assert sum(s["expression_kinds"].values()) == 260
    assert "pucker" in s["presets_unavailable_in_model"]  # the toy model has no mouthPucker


def test_tampering_is_detected(plan20, tmp_path):
    d = tmp_path / "copy"
    shutil.copytree(plan20, d)
    f = d / "shards" / "shard_000001.json"
    f.write_bytes(f.read_bytes().replace(b'"seed":', b'"seed": ', 1))
    with pytest.raises(SynthError, match="sha256"):
        io.load_plan(d).shard("shard_000001")
    h = json.loads((d / "plan.json").read_text())
    h["run_seed"] = 8
    (d / "plan.json").write_text(json.dumps(h))
    with pytest.raises(SynthError, match="plan_hash"):
        io.load_plan(d)


def test_cli_rerun_is_a_no_op_and_conflicts_are_refused(plan20, toy, tmp_path, capsys):
    before = {p: p.stat().st_mtime_ns for p in plan20.rglob("*")}
    assert main(["plan", "-n", "20", "--seed", "7", "--out", str(plan20), "--model", str(toy), "-q"]) == 0
    assert {p: p.stat().st_mtime_ns for p in plan20.rglob("*")} == before
    capsys.readouterr()
    assert main(["plan", "-n", "20", "--seed", "8", "--out", str(plan20), "--model", str(toy)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "different plan" in err[0]
    assert {p: p.stat().st_mtime_ns for p in plan20.rglob("*")} == before
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "notes.txt").write_text("x")
    assert main(["plan", "-n", "1", "--out", str(busy), "--model", str(toy)]) == 2
    assert "not empty" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # nothing half-written


def test_cli_refuses_infeasible_view_counts(toy, tmp_path, capsys):
    out = tmp_path / "p"
    code = main(["plan", "-n", "2", "--out", str(out), "--model", str(toy), "--set", "camera.azimuth_deg=[-30,30]",
                 "--set", "camera.elevation_deg=[-10,10]"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "at most" in err[0] and "views_per_expression" in err[0]
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_cli_reports_sampling_failure_without_leftovers(toy, tmp_path, capsys):
    out = tmp_path / "p"
    code = main(["plan", "-n", "2", "--out", str(out), "--model", str(toy), "--set", "camera.max_candidates=200",
                 "--set", "camera.restarts=1"])
    assert code == 2 and "could not place" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- expressions

def test_presets_resolve_by_name_and_skip_absent_ones():
    em = expressions.resolve(ARKIT, ExpressionConfig())
    assert em.preset_names == list(expressions.PRESETS) and em.skipped_presets == []
    assert em.jaw_index == ARKIT.index("jawOpen") and em.preset_jaw.max() == 0.0  # the jaw rides on jawOpen
    toy = expressions.resolve(make_toy_model().expression_names, ExpressionConfig())
    assert "smile" in toy.preset_names and "pucker" in toy.skipped_presets and "jaw_open" in toy.preset_names
    joint = expressions.resolve(["browInnerUp"], ExpressionConfig(jaw_via="joint"))
    assert "jaw_open" in joint.preset_names and joint.jaw_index == -1
    k = joint.preset_names.index("jaw_open")
    assert joint.preset_jaw[k] == 1.0 and not joint.preset_matrix[k].any()


def test_expression_sampling_is_plausible():
    cfg = ExpressionConfig()
    em = expressions.resolve(ARKIT, cfg)
    P = 4000
    ex = expressions.sample_expressions(5, np.arange(P) // 13, np.arange(P) % 13, em, cfg)
    frac = np.bincount(ex.kind, minlength=3) / P
    w = np.array([cfg.neutral_weight, cfg.preset_weight, cfg.random_weight])
    assert np.allclose(frac, w / w.sum(), atol=0.03)
    assert ex.codes.min() >= 0.0 and ex.codes.max() <= 1.0
    neutral = ex.kind == 0
    assert not ex.codes[neutral].any() and np.all(ex.preset[neutral] == -1)
    rnd = ex.kind == 2
    excluded = [i for i, n in enumerate(ARKIT) if fnmatch.fnmatch(n, "eyeLook*") or n == "tongueOut"]
    assert not ex.codes[rnd][:, excluded].any()
    for a, b in em.conflicts:
        assert not np.any((ex.codes[rnd, a] > 0) & (ex.codes[rnd, b] > 0))
    active = (ex.codes[rnd] > 0).sum(1)
    assert active.min() >= 1 and active.max() <= 2 * cfg.random_active[1] + 1  # mirrored pairs + jawOpen
    assert np.all(ex.codes[rnd].sum(1) <= cfg.max_total_activation + 1.0 + 1e-9)  # + a jaw opening
    lo, hi = cfg.gaze_yaw_deg
    assert ex.gaze_yaw_deg.min() >= lo and ex.gaze_yaw_deg.max() <= hi
    assert np.all(np.abs(ex.gaze_pitch_deg) <= 15) and np.all((ex.vergence_deg >= 0) & (ex.vergence_deg <= 2))
    rots = ex.joint_rotations()
    assert set(rots) == {"jaw", "eye_l", "eye_r"} and np.all(np.linalg.norm(rots["eye_l"], axis=1) < np.deg2rad(40))


def test_gaze_is_centred_on_the_primary_position_and_stays_in_its_limits():
    P = 20000
    rows = np.arange(P) // 13, np.arange(P) % 13
    cfg = ExpressionConfig()
    ex = expressions.sample_expressions(3, *rows, expressions.resolve(ARKIT, cfg), cfg)
    for angle, (lo, hi), sd in ((ex.gaze_yaw_deg, cfg.gaze_yaw_deg, cfg.gaze_sd_deg[0]),
                                (ex.gaze_pitch_deg, cfg.gaze_pitch_deg, cfg.gaze_sd_deg[1])):
        assert angle.min() >= lo and angle.max() <= hi
        assert abs(np.median(angle)) < 0.3
        # a normal truncated at 2.5-4 sd: the central +-1 sd holds 68-71 %, not the uniform's 2 sd / width
        inside = np.mean(np.abs(angle) <= sd)
        assert 0.66 < inside < 0.72, inside
    # the same uniforms drawn uniformly: the old behaviour, kept as an option
    uni = ExpressionConfig(gaze_distribution="uniform")
    ux = expressions.sample_expressions(3, *rows, expressions.resolve(ARKIT, uni), uni)
    assert 0.22 < np.mean(np.abs(ux.gaze_yaw_deg) <= 6.0) < 0.26  # 12 / 50
    assert np.array_equal(np.sign(ux.gaze_pitch_deg), np.sign(ex.gaze_pitch_deg))  # one uniform each: monotone
    assert np.array_equal(ux.codes, ex.codes)  # nothing else moves
    # limits that exclude the centre, and a narrow spread: still inside, still deterministic
    far = ExpressionConfig(gaze_pitch_deg=(20.0, 30.0), gaze_sd_deg=(0.5, 0.5))
    fx = expressions.sample_expressions(3, *rows, expressions.resolve(ARKIT, far), far)
    assert fx.gaze_pitch_deg.min() >= 20.0 and fx.gaze_pitch_deg.max() <= 30.0 and np.isfinite(fx.gaze_pitch_deg).all()
    again = expressions.sample_expressions(3, *rows, expressions.resolve(ARKIT, far), far)
    assert np.array_equal(fx.gaze_pitch_deg, again.gaze_pitch_deg)


def test_jaw_rotation_stays_within_limits_when_realised_by_the_joint():
    cfg = ExpressionConfig(jaw_via="joint", jaw_open_deg=(0.0, 20.0), random_jaw_probability=1.0)
    em = expressions.resolve(ARKIT, cfg)
    ex = expressions.sample_expressions(1, np.zeros(3000, int), np.arange(3000), em, cfg)
    assert ex.jaw_open_deg.max() <= 20.0 and ex.jaw_open_deg.min() >= 0.0 and ex.jaw_open_deg.max() > 10.0
    assert np.all(np.abs(ex.jaw_lateral_deg) <= 4.0)
    assert not ex.codes[:, ARKIT.index("jawOpen")].any()
    opened = ex.jaw_open_deg > 0
    ang = np.degrees(np.linalg.norm(ex.joint_rotations()["jaw"][opened], axis=1))
    assert ang.max() <= np.hypot(20.0, 4.0) + 1e-6


# --------------------------------------------------------------------------- identities

def test_identity_codes_match_the_prior():
    m = make_toy_model()
    prior = identities.prior_of(m)
    codes = identities.sample_identities(3, np.arange(20000), prior, None)
    assert np.allclose(codes.mean(0), prior.mean(), atol=0.03)
    assert np.allclose(np.cov(codes.T), prior.covariance(), atol=0.05)
    r = identities.truncation_radius(m.identity_dims, IdentityConfig())
    t = identities.sample_identities(3, np.arange(3000), prior, r)
    assert np.sqrt(prior.mahalanobis_sq(t).min(axis=1)).max() <= r + 1e-9
    assert np.allclose(np.cov(t.T), prior.covariance(), atol=0.08)  # 0.5 % truncation barely shrinks it
    assert np.array_equal(identities.sample_identities(3, np.array([17]), prior, r), t[17:18])


# --------------------------------------------------------------------------- assets

def test_catalogue_is_valid_and_complete():
    cat = load_catalogue()
    assert set(cat.classes) == set(NAMES)
    n = {c: len(v["assets"]) for c, v in cat.classes.items()}
    assert n["hair"] >= 8 and n["beard"] >= 5 and n["glasses"] >= 6 and n["eyelashes"] == 2 and n["garment"] >= 7
    assert cat.classes["glasses"]["presence"] < 1 and cat.classes["headwear"]["presence"] < 1
    assert len(cat.digest) == 64 and cat.rules


def test_asset_sampling_respects_rules_weights_and_ranges():
    cat = load_catalogue()
    picks = assets.sample_assets_batch(9, np.arange(6000), cat)
    assert picks[123] == assets.sample_assets(9, 123, cat)
    tags = {c: {a["id"]: set(a.get("tags", [])) for a in v["assets"]} for c, v in cat.classes.items()}
    n_headwear = 0
    for p in picks:
        assert set(p) == set(NAMES) and p["skin"] is not None and p["iris"] is not None
        if p["headwear"]:
            n_headwear += 1
            assert p["hair"] is None or not (tags["hair"][p["hair"]["id"]] & {"long_hair", "voluminous_hair", "updo"})
        if p["beard"] and p["garment"]:
            assert not ("long_beard" in tags["beard"][p["beard"]["id"]] and
                        "high_collar" in tags["garment"][p["garment"]["id"]])
        if p["beard"] and p["hair"]:
            assert p["beard"]["params"]["colour"] == p["hair"]["params"]["colour"]
        sk = p["skin"]["params"]
        assert "melanin" not in sk and 0.005 <= sk["haemoglobin"] <= 0.05  # melanin: synth.plan.skin
        assert isinstance(sk["detail_variant"], int) and 0 <= sk["detail_variant"] <= 63
    glasses = np.mean([p["glasses"] is not None for p in picks])
    assert abs(glasses - cat.classes["glasses"]["presence"]) < 0.03
    assert 0 < n_headwear < 0.08 * 6000
    off = assets.sample_assets_batch(9, np.arange(50), cat, disabled=("hair", "glasses"))
    assert all(p["hair"] is None and p["glasses"] is None for p in off)


@pytest.mark.parametrize("text, what", [
    ('class = "hair"\n[[assets]]\nid = "x"\nclass = "hair"\ngenerator = "procedural:x"\n', "licence"),
    ('class = "hair"\n[[assets]]\nid = "x"\nclass = "hair"\ngenerator = "ftp:x"\nlicence = "MIT"\n', "generator"),
    ('class = "hair"\n[[assets]]\nid = "x"\nclass = "hair"\ngenerator = "procedural:x"\nlicence = "MIT"\n'
     '[assets.parameters]\nlength_m = { range = [2, 1] }\n', "range"),
    ('class = "beard"\n[[assets]]\nid = "x"\nclass = "beard"\ngenerator = "procedural:x"\nlicence = "MIT"\n',
     "class"),
])
def test_bad_catalogues_are_refused(tmp_path, text, what):
    (tmp_path / "hair.toml").write_text(text)
    with pytest.raises(SynthError) as e:
        load_catalogue(tmp_path)
    assert what in str(e.value) and "hair.toml" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.slow
def test_default_model_plan(tmp_path):
    """Plan figures on the embedded default model (built and cached on first use)."""

    pytest.importorskip("scipy")
    try:
        from synth.model.default import default_model_path

        default_model_path()
    except SynthError as e:  # pragma: no cover - the data package is missing
        pytest.skip(str(e))
    header, summ = planner.run_plan(load_config(), 300, tmp_path / "p", seed=7)
    assert summ["presets_unavailable_in_model"] == [] and summ["cameras"]["restarts"] == 0
    assert summ["cameras"]["smallest_pairwise_angle_deg"] >= 25.0
