"""synth prior fit / render FIT / eval as a user runs them (subprocesses): the whole chain on a tiny
toy-model dataset, and bad input (one line, exit 2, nothing written)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.prior import face_scene as fs
from tests.prior.scene import TINY
from tests.prior.test_cli import one_line_error, synth

pytest.importorskip("OpenEXR")
SETS = [a for s in TINY for a in ("--set", s)]
FIT_SETS = ["--set", "inversion.steps=3", "--set", "inversion.patches=1", "--set", "finetune.rays_per_step=128",
            "--set", "finetune.warmup_steps=1", "--steps", "4"]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    root = tmp_path_factory.mktemp("fit")
    model = fs.write_model(root / "toy.npz")
    train = fs.make_dataset(root / "train", model, identities=(0, 1, 2), expressions=2, views=6, size=16)
    r = synth("prior", "train", train, "--out", root / "run", "--steps", 6, *SETS)
    assert r.returncode == 0, r.stderr
    test = fs.make_dataset(root / "test", model, identities=(7,), expressions=1, views=6, size=32,
                           angles=fs.INPUT_ANGLES)
    inputs = [next((test / "shards").glob(f"*/id000007_ex00_v{v:02d}.exr")) for v in range(3)]
    return root, model, root / "run", test, inputs


@pytest.fixture(scope="module")
def fitted(world):
    root, model, run, test, inputs = world
    r = synth("prior", "fit", *inputs, "--prior", run, "--out", root / "fit", "--model", model, *FIT_SETS)
    assert r.returncode == 0, r.stderr
    return root / "fit"


def test_fit_writes_codes_cameras_weights_and_report(world, fitted):
    info = json.loads((fitted / "fit.json").read_text())
    assert info["pretrained"] is True and info["landmark_source"] == "json"
    assert [r["view_index"] for r in info["inputs"]] == [0, 1, 2]
    C = fs.IDENTITY_DIMS + len(fs.MODEL.expression_names) + 9
    assert np.asarray(info["codes"]).shape == (3, C) and len(info["cameras"]) == 3
    assert info["head_model"]["name"] == fs.MODEL.name and info["prior"]["head_model"]["name"] == fs.MODEL.name
    # per-image expressions, one shared identity code
    codes = np.asarray(info["codes"])
    assert np.allclose(codes[:, :fs.IDENTITY_DIMS], codes[0, :fs.IDENTITY_DIMS])
    # the JSON's cameras are not inputs: the fitted ones differ from them (fitted focal length, own frame)
    true_K = json.loads(world[4][0].with_suffix(".json").read_text())["camera"]["K"]
    assert info["cameras"][0]["K"] != true_K
    rep = json.loads((fitted / "report.json").read_text())
    assert len(rep["inversion"]) == 3 and rep["finetune"][-1]["step"] == 4 and max(rep["landmarks"]["rmse_px"]) < 1
    assert "Fit of 3 image(s)" in (fitted / "report.md").read_text()
    # the inversion is judged on the whole downscaled inputs (each step's loss is that of its random patches)
    assert len(rep["inversion_whole_l1"]) == 2 and all(np.isfinite(rep["inversion_whole_l1"]))
    assert "L1 over the whole input(s)" in (fitted / "report.md").read_text()
    # the landmarks the fit saw and the fitted model's, and each image's face region
    assert len(info["landmarks_2d"]) == 3 and np.asarray(info["model_landmarks_2d"]).shape[:2] == (3, 68)
    assert all(n > 0 for n in info["face_pixels"])
    from safetensors.torch import load_file

    t = load_file(str(fitted / "weights.safetensors"))
    assert t["latent"].shape == (4,) and any(k.startswith("model.nerf.") for k in t)


def test_render_orbit_and_cameras(world, fitted, tmp_path):
    from PIL import Image

    r = synth("prior", "render", fitted, "--orbit", 2, "--size", 12, "-o", tmp_path / "orbit")
    assert r.returncode == 0, r.stderr
    cams = json.loads((tmp_path / "orbit" / "cameras.json").read_text())
    assert [v["key"] for v in cams["views"]] == ["orbit000", "orbit001"]
    assert sum(cams["views"][0]["expression_weights"]) == pytest.approx(1.0)
    for kind in ("colour", "opacity", "normals"):
        assert Image.open(tmp_path / "orbit" / f"orbit001_{kind}.png").size == (12, 12)
    assert (tmp_path / "orbit" / "orbit001_depth.exr").is_file()
    r = synth("prior", "render", fitted, "--cameras", tmp_path / "orbit" / "cameras.json", "-o", tmp_path / "again")
    assert r.returncode == 0, r.stderr
    for k in ("orbit000", "orbit001"):
        a = np.asarray(Image.open(tmp_path / "orbit" / f"{k}_colour.png"))
        assert np.array_equal(a, np.asarray(Image.open(tmp_path / "again" / f"{k}_colour.png")))


def test_render_framed_on_the_head_or_as_the_input(world, fitted, tmp_path):
    """The default framing looks at the fitted face from the frontal input camera's distance over
    +-40 degrees (the face centre projects to the image centre); ``--frame input`` is the photo's own
    framing orbiting the full circle, as before."""
    from prior.fit.novel import frontal_index
    from synth.conventions import invert_rigid

    fit = json.loads((fitted / "fit.json").read_text())
    face = np.asarray(fit["face_centre"])
    c2w_in = np.asarray([c["camera_to_world"] for c in fit["cameras"]])
    i = frontal_index(c2w_in, face)
    r = synth("prior", "render", fitted, "--orbit", 3, "--size", 10, "--span", 60, "-o", tmp_path / "head")
    assert r.returncode == 0, r.stderr
    views = json.loads((tmp_path / "head" / "cameras.json").read_text())["views"]
    az = []
    for v in views:
        K, w2c = np.asarray(v["K"]), invert_rigid(np.asarray(v["camera_to_world"]))
        p = K @ (w2c[:3, :3] @ face + w2c[:3, 3])
        assert p[:2] / p[2] == pytest.approx([5.0, 5.0], abs=1e-9)  # the face at the image centre
        d = np.asarray(v["camera_to_world"])[:3, 3] - face
        assert np.linalg.norm(d) == pytest.approx(np.linalg.norm(c2w_in[i][:3, 3] - face))
        assert K[0, 0] == pytest.approx(10 * np.linalg.norm(d) / 0.5)  # 0.5 m across at the face
        az.append(np.degrees(np.arctan2(d[0], -d[1])))
    d0 = c2w_in[i][:3, 3] - face
    az0 = np.degrees(np.arctan2(d0[0], -d0[1]))
    assert np.asarray(az) == pytest.approx([az0 - 30, az0, az0 + 30], abs=1e-6)
    r = synth("prior", "render", fitted, "--orbit", 2, "--size", 10, "--frame", "input", "-o", tmp_path / "input")
    assert r.returncode == 0, r.stderr
    first = json.loads((tmp_path / "input" / "cameras.json").read_text())["views"][0]
    assert np.asarray(first["camera_to_world"]) == pytest.approx(c2w_in[frontal_index(c2w_in, fit["bounds"]["centre"])])


def test_eval_frontal_held_out_views(world, fitted, tmp_path):
    test = world[3]
    r = synth("prior", "eval", fitted, "--gt", test, "--json", "--save", tmp_path / "ev")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    # inputs 0-2 are not held out; view 5 (azimuth 150) is behind the head
    assert [v["view"] for v in res["views"]] == [3, 4]
    for v in res["views"]:
        assert np.isfinite([v["psnr"], v["ssim"], v["lpips"]]).all() and 0 < v["lpips"] < 1 and -1 <= v["ssim"] <= 1
    assert res["mean"]["psnr"] == pytest.approx(np.mean([v["psnr"] for v in res["views"]]))
    assert 0.5 < res["alignment"]["scale"] < 2
    assert (tmp_path / "ev" / "id000007_ex00_v03_gt.png").is_file()
    r = synth("prior", "eval", fitted, "--gt", test, "--views", "0,5")
    assert r.returncode == 0, r.stderr
    assert "id000007_ex00_v00 (input)" in r.stdout and "id000007_ex00_v05" in r.stdout and "**mean of 2**" in r.stdout


def test_no_pretraining_fits_a_random_field(world, fitted, tmp_path):
    root, model, run, test, inputs = world
    r = synth("prior", "fit", *inputs, "--prior", run, "--out", tmp_path / "fit0", "--model", model,
              "--no-pretraining", *FIT_SETS)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "fit0" / "fit.json").read_text())["pretrained"] is False
    assert "randomly initialised" in (tmp_path / "fit0" / "report.md").read_text()
    from safetensors.torch import load_file

    a, b = load_file(str(fitted / "weights.safetensors")), load_file(str(tmp_path / "fit0" / "weights.safetensors"))
    assert not np.allclose(a["model.nerf.density.weight"].numpy(), b["model.nerf.density.weight"].numpy())


def _edited_frame(src: Path, dst_dir: Path, edit) -> Path:
    dst_dir.mkdir(parents=True, exist_ok=True)
    shutil.copy(src, dst_dir / src.name)
    meta = json.loads(src.with_suffix(".json").read_text())
    edit(meta)
    (dst_dir / src.with_suffix(".json").name).write_text(json.dumps(meta))
    return dst_dir / src.name


CASES = ["no_face", "photo_no_face", "few_landmarks", "unreadable", "other_dims", "other_model", "exists", "no_json",
         "suffix", "json_photo", "no_mediapipe", "bad_set", "no_prior"]


@pytest.mark.parametrize("case", CASES)
def test_bad_input_is_one_line_and_writes_nothing(world, fitted, tmp_path, case):
    root, model, run, test, inputs = world
    out = tmp_path / "fit"
    images, extra, path_first = list(inputs), ["--model", model], None

    def hide(keep):
        def edit(meta):
            meta["landmarks_visible"] = [i < keep for i in range(68)]
        return edit

    if case == "no_face":
        images[1] = _edited_frame(inputs[1], tmp_path / "nf", hide(0))
    elif case == "few_landmarks":
        images[2] = _edited_frame(inputs[2], tmp_path / "fl", hide(3))
    elif case == "unreadable":
        images[0] = tmp_path / "broken.png"
        images[0].write_bytes(b"\x89PNG\r\n\x1a\n not really")
    elif case == "other_dims":
        extra = []  # the embedded default model: 48 identity dims, the prior's toy has 6
    elif case == "other_model":
        from tests.support.toy_model import write_toy_model

        extra = ["--model", write_toy_model(tmp_path / "other.npz", name="other-toy", identity_dims=fs.IDENTITY_DIMS)]
    elif case == "exists":
        out = fitted
    elif case == "no_json":
        (tmp_path / "nj").mkdir()
        images[0] = Path(shutil.copy(inputs[0], tmp_path / "nj" / inputs[0].name))
    elif case == "suffix":
        images[0] = tmp_path / "face.bmp"
        images[0].write_bytes(b"BM")
    elif case in ("json_photo", "no_mediapipe", "photo_no_face"):
        from PIL import Image

        photo = tmp_path / "face.png"
        Image.new("RGB", (96, 96), (200, 150, 120)).save(photo)
        images[0] = photo
        if case == "json_photo":
            extra += ["--landmarks", "json"]
        elif case == "no_mediapipe":  # a stand-in package that fails to import, as if not installed
            path_first = tmp_path / "hide"
            (path_first / "mediapipe").mkdir(parents=True)
            (path_first / "mediapipe" / "__init__.py").write_text("raise ImportError('hidden')\n")
        else:
            pytest.importorskip("mediapipe", reason="the synth-faces[fit] extra (mediapipe) is not installed")
    elif case == "bad_set":
        extra += ["--set", "finetune.stepz=3"]
    else:
        run = tmp_path / "nothing"
    before = sorted(p.name for p in tmp_path.iterdir())
    msg = one_line_error(synth("prior", "fit", *images, "--prior", run, "--out", out, *extra, *FIT_SETS,
                               path_first=path_first))
    expect = {"no_face": "no face in the image", "photo_no_face": "no face found",
              "few_landmarks": "only 3 landmarks are visible", "unreadable": "unreadable image",
              "other_dims": "identity 6",
              "other_model": "not 'other-toy'", "exists": "fit output exists", "no_json": "has no JSON beside it",
              "suffix": "unsupported image type", "json_photo": "needs synth frames",
              "no_mediapipe": "mediapipe landmark detector is not installed", "bad_set": "finetune.steps",
              "no_prior": "no prior checkpoint"}[case]
    assert expect in msg
    if case != "exists":
        assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == before
    if case in ("no_face", "photo_no_face", "few_landmarks", "unreadable", "no_json"):
        named = images[{"no_face": 1, "few_landmarks": 2}.get(case, 0)]
        assert str(named.with_suffix("")) in msg  # the line names the file (or its missing JSON)


def test_render_and_eval_errors(world, fitted, tmp_path):
    root, model, run, test, inputs = world
    assert "not a fit directory" in one_line_error(synth("prior", "eval", tmp_path, "--gt", test))
    assert "select a training identity" in one_line_error(
        synth("prior", "render", fitted, "--identity", 0, "-o", tmp_path / "v"))
    assert "needs --identity and --expression" in one_line_error(synth("prior", "render", run, "-o", tmp_path / "v"))
    for args, says in ((("--span", 400), "outside 0-360"), (("--frame", "side"), "unknown framing"),
                       (("--frame", "input", "--span", 90), "drop --span")):
        assert says in one_line_error(synth("prior", "render", fitted, *args, "-o", tmp_path / "v"))
    assert "render a fit, not a prior run" in one_line_error(
        synth("prior", "render", run, "-i", 0, "-e", 0, "--span", 90, "-o", tmp_path / "v"))
    bad = tmp_path / "cams.json"
    bad.write_text('{"views": [{"K": [1, 2]}]}')
    assert "cameras file is malformed" in one_line_error(
        synth("prior", "render", fitted, "--cameras", bad, "-o", tmp_path / "v"))
    assert "no frame of identity 7" in one_line_error(synth("prior", "eval", fitted, "--gt", root / "train"))
    assert "bad view list" in one_line_error(synth("prior", "eval", fitted, "--gt", test, "--views", "a,b"))
    assert "not in the ground truth" in one_line_error(synth("prior", "eval", fitted, "--gt", test, "--views", "9"))
    assert not (tmp_path / "v").exists()
