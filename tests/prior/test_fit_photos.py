"""The photos people take (prior.fit.photos, prior.fit.inputs): EXIF orientation and focal length,
pixel formats (grey, CMYK, 16-bit), huge photos, images of different sizes in one fit, and the
faces mediapipe finds (several, small, none)."""

from __future__ import annotations

import struct
import tracemalloc
import zlib

import numpy as np
import pytest
from PIL import Image
from PIL.TiffImagePlugin import IFDRational

from prior.fit.inputs import read_inputs, to_canvas
from prior.fit.landmark_sources import MIN_FACE_PX, choose_face, person_mask
from prior.fit.photos import FULL_FRAME_DIAGONAL_MM, read_photo
from synth.appearance.srgb import srgb_to_linear
from synth.errors import SynthError

skd = pytest.importorskip("skimage.data", reason="scikit-image (test extra) provides the photo")


@pytest.fixture(scope="module")
def astronaut() -> np.ndarray:
    return skd.astronaut()  # 512 x 512 RGB, one face (public domain)


def _linear(rgb8: np.ndarray) -> np.ndarray:
    return srgb_to_linear(np.asarray(rgb8, np.float64) / 255.0)


def _save_jpeg(path, img: Image.Image, orientation: int | None = None, ifd: dict | None = None, **kw):
    exif = Image.Exif()
    if orientation is not None:
        exif[0x0112] = orientation
    if ifd:
        exif.get_ifd(0x8769).update(ifd)
    img.save(path, exif=exif.tobytes(), quality=95, **kw)
    return path


def _png16(path, a: np.ndarray):
    """A 16-bit PNG (grey (H, W) or RGB (H, W, 3)) written by hand: Pillow writes 16-bit grey only."""
    a = np.asarray(a, np.uint16)
    H, W = a.shape[:2]
    colour_type = 0 if a.ndim == 2 else 2
    raw = b"".join(b"\x00" + a[y].astype(">u2").tobytes() for y in range(H))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 16, colour_type, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
    return path


# --------------------------------------------------------------------------- EXIF


@pytest.mark.parametrize("orientation,stored", [(6, Image.Transpose.ROTATE_90), (8, Image.Transpose.ROTATE_270),
                                                (3, Image.Transpose.ROTATE_180)])
def test_exif_orientation_is_applied(astronaut, tmp_path, orientation, stored):
    """A phone photo stored sideways with its orientation tag reads upright."""
    src = Image.fromarray(astronaut[:, :384])  # not square: a wrong rotation changes the size
    p = _save_jpeg(tmp_path / "side.jpg", src.transpose(stored), orientation=orientation)
    ph = read_photo(p, 2048)
    assert ph.orientation == orientation and ph.colour.shape == (512, 384, 3) and ph.source_size == (384, 512)
    err = np.abs(ph.colour - _linear(astronaut[:, :384])).mean()
    assert err < 0.01, err
    plain = read_photo(_save_jpeg(tmp_path / "plain.jpg", src.transpose(stored)), 2048)  # no tag: as stored
    assert plain.orientation == 1 and plain.colour.shape[1::-1] == src.transpose(stored).size


def test_exif_focal_length(astronaut, tmp_path):
    img = Image.fromarray(astronaut[:, :384])
    ph = read_photo(_save_jpeg(tmp_path / "f35.jpg", img, ifd={0xA405: 26}), 2048)
    assert ph.focal_px == pytest.approx(26 * np.hypot(384, 512) / FULL_FRAME_DIAGONAL_MM)
    # focal length in mm and the focal plane's resolution (pixels per cm) of a 1,536 px wide original
    ifd = {0x920A: IFDRational(42, 10), 0xA20E: IFDRational(1000, 1), 0xA210: 3, 0xA002: 1536}
    ph = read_photo(_save_jpeg(tmp_path / "fmm.jpg", img, ifd=ifd), 2048)
    assert ph.focal_px == pytest.approx(4.2 * 100 * 384 / 1536)
    # stored sideways: the plane resolution is of the stored width (512 here, upright 384)
    ph = read_photo(_save_jpeg(tmp_path / "fside.jpg", img.transpose(Image.Transpose.ROTATE_90), orientation=6,
                               ifd={**ifd, 0xA002: 2048}), 2048)
    assert ph.focal_px == pytest.approx(4.2 * 100 * 512 / 2048)
    assert read_photo(_save_jpeg(tmp_path / "none.jpg", img), 2048).focal_px is None
    # downscaled while decoded: the focal length in the decoded pixels
    ph = read_photo(_save_jpeg(tmp_path / "small.jpg", img, ifd={0xA405: 26}), 256)
    assert ph.colour.shape[:2] == (256, 192) and ph.focal_px == pytest.approx(0.5 * 26 * 640 / FULL_FRAME_DIAGONAL_MM)


def test_exif_focal_is_the_initial_focal(astronaut, tmp_path):
    """The pipeline's initial focal lengths: EXIF (canvas pixels), the median for an image without."""
    from prior.fit.pipeline import exif_focal_init

    img = Image.fromarray(astronaut)
    a = _save_jpeg(tmp_path / "a.jpg", img, ifd={0xA405: 26})
    b = _save_jpeg(tmp_path / "b.jpg", img.resize((256, 256)), ifd={0xA405: 52})  # placed at scale 2
    c = _save_jpeg(tmp_path / "c.jpg", img)
    inputs = read_inputs([a, b, c], 2048)
    f = 26 * np.hypot(512, 512) / FULL_FRAME_DIAGONAL_MM
    np.testing.assert_allclose(exif_focal_init(inputs), [f, 2 * f, 1.5 * f])
    assert exif_focal_init(read_inputs([c], 2048)) is None


def test_initial_focal_reaches_the_landmark_fit():
    from prior.fit.landmarks_fit import FitOptions, Observations, _Problem
    from prior.fit.synthetic import make_scene
    from synth.conventions import project
    from synth.model.head import HeadModel
    from tests.support.toy_model import make_toy_model

    m = make_toy_model()
    sc = make_scene(m, 3, 2, resolution=128)
    hm = HeadModel(m, np.float64)
    X = hm.landmarks(sc.identity, sc.expression, sc.joint_rotations)
    pts = np.stack([project(sc.K[v], sc.world_to_camera[v], np.asarray(X, np.float64).reshape(-1, 3))[0]
                    for v in range(2)])
    obs = Observations(pts, np.ones(pts.shape[:2]), 128, 128, focal_init=[300.0, 450.0])
    prob = _Problem(m, obs, FitOptions(), None, None)
    np.testing.assert_allclose(prob.K0[:, 0, 0].numpy(), [300.0, 450.0])
    with pytest.raises(SynthError, match="must be positive"):
        Observations(pts, np.ones(pts.shape[:2]), 128, 128, focal_init=[300.0, 0.0])


# --------------------------------------------------------------------------- pixel formats


def test_sixteen_bit_png(tmp_path):
    ramp = np.tile(np.linspace(0, 65535, 64).round().astype(np.uint16), (16, 1))
    grey = read_photo(_png16(tmp_path / "g16.png", ramp), 2048)
    assert grey.mode.startswith("I")
    np.testing.assert_allclose(grey.colour[..., 1], srgb_to_linear(ramp / 65535.0), atol=1e-6)
    rgb = np.stack([ramp, 65535 - ramp, np.full_like(ramp, 30000)], axis=2)
    ph = read_photo(_png16(tmp_path / "rgb16.png", rgb), 2048)
    np.testing.assert_allclose(ph.colour, srgb_to_linear(rgb / 65535.0), atol=6e-3)  # read at 8 bits


def test_grey_and_cmyk_jpeg(astronaut, tmp_path):
    img = Image.fromarray(astronaut)
    ref = read_photo(_save_jpeg(tmp_path / "rgb.jpg", img), 2048).colour
    grey = read_photo(_save_jpeg(tmp_path / "grey.jpg", img.convert("L")), 2048)
    assert grey.mode == "L" and grey.colour.shape == (512, 512, 3)
    np.testing.assert_array_equal(grey.colour[..., 0], grey.colour[..., 2])
    cmyk = read_photo(_save_jpeg(tmp_path / "cmyk.jpg", img.convert("CMYK")), 2048)
    assert cmyk.mode == "CMYK"
    assert np.abs(cmyk.colour - ref).mean() < 0.02  # Pillow's CMYK <-> RGB round trip


# --------------------------------------------------------------------------- sizes


def test_huge_jpeg_is_downscaled_while_decoded(astronaut, tmp_path):
    """8,000 x 6,000: decoded by the JPEG's DCT scaling, never as floats at full size (that alone
    would be 576 MB of float32 RGB)."""
    big = Image.fromarray(astronaut).resize((8000, 6000), Image.Resampling.BILINEAR)
    p = tmp_path / "huge.jpg"
    big.save(p, quality=80)
    del big
    tracemalloc.start()
    try:
        ph = read_photo(p, 2048)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert ph.colour.shape == (1536, 2048, 3) and ph.source_size == (8000, 6000)
    assert ph.scale == pytest.approx(2048 / 8000)
    assert peak < 200e6, peak
    small = np.asarray(Image.fromarray(astronaut).resize((2048, 1536), Image.Resampling.BILINEAR))
    assert np.abs(ph.colour - _linear(small)).mean() < 0.02


def test_large_png_is_downscaled(astronaut, tmp_path):
    p = tmp_path / "big.png"
    Image.fromarray(astronaut).resize((1000, 700)).save(p)
    ph = read_photo(p, 256)
    assert ph.colour.shape == (179, 256, 3) and ph.alpha is None
    ref = np.asarray(Image.fromarray(astronaut).resize((256, 179), Image.Resampling.BOX))
    assert np.abs(ph.colour - _linear(ref)).mean() < 0.02


def test_images_of_different_sizes_share_one_canvas(astronaut, tmp_path):
    """The first image's size is the canvas; another is scaled to fit inside it, centred, and
    its border lies outside the mask."""
    rgba = np.concatenate([astronaut, np.full((512, 512, 1), 255, np.uint8)], axis=2)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    Image.fromarray(rgba[:, :384]).save(a)  # 384 x 512 (portrait)
    Image.fromarray(rgba[::2, ::2]).save(b)  # 256 x 256: placed at scale 1.5, 384 x 384, 64 px down
    ia, ib = read_inputs([a, b], 2048)
    assert ia.size == ib.size == (384, 512)
    assert ib.scale == (1.5, 1.5) and ib.offset == (0, 64) and ib.content == (384, 384)
    assert ib.mask[:64].max() == 0 and ib.mask[448:].max() == 0 and ib.mask[70:440].min() > 0.99
    assert np.abs(ib.target[64:448] - _linear(np.asarray(Image.fromarray(astronaut).resize((384, 384))))).mean() < 0.02
    np.testing.assert_allclose(to_canvas(ib, [[0.0, 0.0], [256.0, 256.0]]), [[0, 64], [384, 448]])
    rec = ib.record()
    assert rec["scale"] == [1.5, 1.5] and rec["offset"] == [0, 64] and rec["source_size"] == [256, 256]


def test_frames_of_different_sizes_keep_their_landmarks(tmp_path):
    """JSON landmarks of a frame placed on another frame's canvas move with its pixels."""
    pytest.importorskip("OpenEXR")
    from prior.fit.inputs import observations
    from synth.dataset.shards import open_dataset
    from tests.support import fake_frames as ff

    paths = []
    for size in (32, 16):
        root = tmp_path / f"d{size}"
        ds = open_dataset(root, "f" * 64, ff.plan(n_shards=1, n_expr=1, n_views=1))
        ff.render_dataset(ds, size=size)
        paths.append(sorted((root / "shards" / "shard_000000").glob("*.exr"))[0])
    inputs = read_inputs(paths, 2048)
    assert inputs[1].scale == (2.0, 2.0) and inputs[1].offset == (0, 0)
    obs = observations(inputs, "json", None)
    np.testing.assert_allclose(obs.mean[1], 2.0 * np.asarray(inputs[1].frame.meta["landmarks_2d"]))
    np.testing.assert_allclose(obs.mean[0], np.asarray(inputs[0].frame.meta["landmarks_2d"]))
    assert list(obs.width) == [32, 32]


# --------------------------------------------------------------------------- faces


def _face(x0, y0, size):
    t = np.linspace(0, 1, 478)
    return np.stack([x0 + size * t, y0 + 0.8 * size * t[::-1]], 1)


def test_choose_face():
    assert choose_face([_face(0, 0, 100)], "p") == (0, [100.0])
    assert choose_face([_face(0, 0, 70), _face(200, 0, 120)], "p")[0] == 1  # the largest
    with pytest.raises(SynthError, match="2 faces of similar size") as e:
        choose_face([_face(0, 0, 100), _face(200, 0, 90)], "p")
    assert "crop the photo" in str(e.value)
    with pytest.raises(SynthError, match=f"the face is 50 px across, the fit needs at least {MIN_FACE_PX} px"):
        choose_face([_face(0, 0, 50)], "p")
    with pytest.raises(SynthError, match="no face found"):
        choose_face([], "p")
    # dlib: a weak detection of similar size (the astronaut's mission patch) does not make it ambiguous
    assert choose_face([_face(0, 0, 100), _face(200, 0, 90)], "p", confident=[True, False])[0] == 0
    # the largest detection is a weak one (the mission patch's points span 95 px, the face's 92): the
    # sure face of similar size is fitted; a weak largest face without a sure rival is kept (einstein)
    assert choose_face([_face(0, 0, 92), _face(200, 0, 95)], "p", confident=[True, False])[0] == 0
    assert choose_face([_face(0, 0, 53), _face(200, 0, 87)], "p", confident=[True, False])[0] == 1
    with pytest.raises(SynthError, match="similar size"):
        choose_face([_face(0, 0, 92), _face(200, 0, 95), _face(400, 0, 90)], "p", confident=[True, False, True])
    assert choose_face([_face(0, 0, 50)], "p", min_px=48)[0] == 0


def _box_face(x0, y0, x1, y1) -> np.ndarray:
    return np.array([[x0, y0], [x1, y1]] * 239, np.float64)


def test_person_mask_keeps_the_chosen_face_person():
    """Two people apart: the other one's region goes; two people touching: the pixels nearer the
    other face go; the soft edge of the kept region stays; no region at the face keeps the mask."""
    m = np.zeros((100, 200), np.float32)
    m[10:100, 10:70] = 1.0   # person A: face box 20..60 x 15..50
    m[10:100, 120:190] = 1.0  # person B
    m[10:100, 9] = 0.3  # A's soft edge
    faces = [_box_face(20, 15, 60, 50), _box_face(130, 15, 180, 50)]
    a = person_mask(m, faces, 0)
    assert a[:, 100:].max() == 0 and np.array_equal(a[:, :100], m[:, :100])
    b = person_mask(m, faces, 1)
    assert b[:, :100].max() == 0 and np.array_equal(b[:, 100:], m[:, 100:])
    joined = m.copy()
    joined[60:100, 60:130] = 1.0  # shoulders touching
    a = person_mask(joined, faces, 0)
    assert a[:, :90].sum() == joined[:, :90].sum() and a[:, 110:].max() == 0
    assert np.array_equal(person_mask(m, [_box_face(80, 0, 110, 5)], 0), m)  # no region reaches the face


def test_mediapipe_on_photos_people_take(astronaut, tmp_path, default_model):
    """Sideways, grey, CMYK and huge photos through read_inputs + mediapipe on one canvas; of two
    faces the clearly larger one is fitted; a small face and two similar faces are refused with one
    line naming the file."""
    pytest.importorskip("mediapipe", reason="the synth-faces[fit] extra (mediapipe) is not installed: make setup")
    from prior.fit.inputs import observations

    img = Image.fromarray(astronaut)
    crop = astronaut[:320, 100:420]  # the face about 92 x 106 px
    files = [_save_jpeg(tmp_path / "side.jpg", img.transpose(Image.Transpose.ROTATE_90), orientation=6),
             _save_jpeg(tmp_path / "grey.jpg", img.convert("L")),
             _save_jpeg(tmp_path / "cmyk.jpg", img.convert("CMYK")),
             _save_jpeg(tmp_path / "half.jpg", Image.fromarray(crop[:, 40:280]))]  # 240 x 320: placed at 1.6
    big = tmp_path / "big.jpg"
    img.resize((4096, 4096), Image.Resampling.BILINEAR).save(big, quality=90)
    files.append(big)
    inputs = read_inputs(files, 1024)
    obs = observations(inputs, "mediapipe", default_model)
    assert obs.mean.shape[0] == 5 and all(im.mask is not None for im in inputs)
    assert [im.detection["faces"] for im in inputs] == [1] * 5
    centre = obs.mean.mean(1)
    for i in (0, 1, 2, 4):  # the same face at the same place on the 512 x 512 canvas
        assert np.abs(centre[i] - centre[1]).max() < 5, centre
    # half.jpg: x 140..380 of the astronaut, 1.6 times as large and centred (64 px right)
    np.testing.assert_allclose(centre[3], (centre[1] - (140, 0)) * 1.6 + (64, 0), atol=8)
    assert inputs[3].mask[:, :64].max() == 0 and inputs[3].mask[:, 448:].max() == 0
    assert inputs[4].record()["decode_scale"] == 0.25
    # two faces: the one on the left is 1.6 times as large
    near = np.asarray(Image.fromarray(astronaut[24:224, 125:325]).resize((320, 320), Image.Resampling.LANCZOS))
    Image.fromarray(np.concatenate([near, crop], 1)).save(tmp_path / "two.png")
    two = read_inputs([tmp_path / "two.png"], 2048)
    obs = observations(two, "mediapipe", default_model)
    assert two[0].detection["faces"] == 2 and two[0].detection["face_px"] > 150 and obs.mean[0, :, 0].max() < 320
    # the mask is the fitted (left) person's: the segmentation covers both, the mask the left one only
    assert two[0].mask[:, :300].mean() > 0.3 and two[0].mask[:, 360:].max() == 0
    for name, arr, match in (("small.png", astronaut[::3, ::3], "the face is"),
                             ("twins.png", np.concatenate([crop, crop], 1), "2 faces of similar size")):
        Image.fromarray(np.ascontiguousarray(arr)).save(tmp_path / name)
        with pytest.raises(SynthError, match=match) as e:
            observations(read_inputs([tmp_path / name], 2048), "mediapipe", default_model)
        assert str(tmp_path / name) in str(e.value) and "\n" not in str(e.value)


def test_a_small_face_in_a_large_photo_is_found(astronaut, tmp_path, default_model):
    """A face under a tenth of the photo's width (92 of 1,400 px): the face mesh's own detector
    misses it, the full-range detector finds it and the face mesh runs on a crop around it."""
    pytest.importorskip("mediapipe", reason="the synth-faces[fit] extra (mediapipe) is not installed: make setup")
    import mediapipe as mp

    from prior.fit.inputs import observations
    from prior.fit.landmark_sources import MAX_FACES, quiet_native_stderr

    canvas = np.full((1400, 1400, 3), 40, np.uint8)
    canvas[888:1400, 444:956] = astronaut
    with quiet_native_stderr(), mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=MAX_FACES,
                                                                refine_landmarks=True) as fm:
        assert not fm.process(canvas).multi_face_landmarks  # what the fallback is for
    Image.fromarray(canvas).save(tmp_path / "far.png")
    inputs = read_inputs([tmp_path / "far.png"], 2048)
    alone = observations(read_inputs([_save_jpeg(tmp_path / "a.jpg", Image.fromarray(astronaut))], 2048), "mediapipe",
                         default_model)
    obs = observations(inputs, "mediapipe", default_model)
    assert inputs[0].detection["faces"] == 1
    shift = np.abs(obs.mean[0] - (alone.mean[0] + (444, 888)))
    assert np.median(shift) < 3.0, np.median(shift)


@pytest.mark.slow
def test_synth_prior_train_and_fit_a_photo(astronaut, tmp_path, default_model, monkeypatch):
    """One environment: ``synth prior train`` (TensorBoard events written) and ``synth prior fit
    PHOTO --landmarks mediapipe`` (a sideways JPEG with an EXIF focal length) on a tiny prior trained
    on toy renders labelled with the default model's codes and name."""
    pytest.importorskip("mediapipe", reason="the synth-faces[fit] extra (mediapipe) is not installed: make setup")
    pytest.importorskip("OpenEXR")
    import json

    from synth.model.default import default_model_path
    from synth.model.head import HeadModel
    from tests.prior import face_scene as fs
    from tests.prior.scene import TINY
    from tests.prior.test_cli import synth

    for name, value in (("MODEL", default_model), ("HEAD", HeadModel(default_model, np.float64)),
                        ("IDENTITY_DIMS", default_model.identity_dims)):
        monkeypatch.setattr(fs, name, value)
    train = fs.make_dataset(tmp_path / "train", default_model_path(), identities=(0, 1), expressions=1, views=4)
    sets = [a for s in TINY for a in ("--set", s)]
    r = synth("prior", "train", train, "--out", tmp_path / "run", "--steps", 4, *sets)
    assert r.returncode == 0, r.stderr
    assert list((tmp_path / "run" / "tb").glob("events.out.tfevents.*"))
    photo = _save_jpeg(tmp_path / "me.jpg", Image.fromarray(astronaut).transpose(Image.Transpose.ROTATE_90),
                       orientation=6, ifd={0xA405: 50})
    r = synth("prior", "fit", photo, "--prior", tmp_path / "run", "--out", tmp_path / "fit", "--landmarks", "mediapipe",
              "--set", "inversion.steps=2", "--set", "inversion.patches=1", "--set", "finetune.rays_per_step=128",
              "--set", "finetune.warmup_steps=1", "--steps", 3)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    info = json.loads((tmp_path / "fit" / "fit.json").read_text())
    rec = info["inputs"][0]
    assert rec["orientation"] == 6 and rec["faces"] == 1 and info["masks"] == ["segmentation"]
    assert rec["exif_focal_px"] == pytest.approx(50 * np.hypot(512, 512) / FULL_FRAME_DIAGONAL_MM)
    assert "initial focal length from EXIF" in r.stdout
    assert json.loads((tmp_path / "fit" / "report.json").read_text())["landmarks"]["converged"]


def test_dlib_landmarks_on_a_real_photo(astronaut, tmp_path, default_model):
    """``--landmarks dlib`` (the judge extra): dlib's 68 points on the astronaut are iBUG's, so
    where mediapipe marks the same place (eye and mouth corners, chin) the two detectors agree
    within 6 % of the inter-ocular distance; the landmark fit to them converges with the model's
    ibug68 points; the mask is the selfie segmentation's; a photo without a face is one line."""
    pytest.importorskip("dlib", reason="the synth-faces[judge] extra (dlib) is not installed: make setup")
    pytest.importorskip("mediapipe", reason="the synth-faces[fit] extra (mediapipe) is not installed: make setup")
    from prior.fit import config as fit_config
    from prior.fit.inputs import observations
    from prior.fit.landmark_sources import load_correspondence
    from prior.fit.pipeline import landmark_fit

    path = _save_jpeg(tmp_path / "a.jpg", Image.fromarray(astronaut))
    inputs = read_inputs([path], 1024)
    obs = observations(inputs, "dlib", default_model)
    assert obs.landmark_set == "ibug68" and obs.mean.shape == (1, 68, 2) and np.isfinite(obs.sigma).all()
    # the mission patch is found too (upsampled, score 0.12: not a confident face), the face is fitted
    assert inputs[0].detection["faces"] in (1, 2) and inputs[0].mask_source == "segmentation"
    assert obs.sigma[0, :17].min() > obs.sigma[0, 17:].max()  # the outline is trusted less
    mp_in = read_inputs([path], 1024)
    mp = observations(mp_in, "mediapipe", default_model)
    corr = load_correspondence(default_model)
    detected = np.full((478, 2), np.nan)
    detected[corr["index"]] = mp.mean[0]
    same = [(33, 36), (263, 45), (61, 48), (291, 54), (152, 8), (133, 39), (362, 42)]  # (mediapipe, ibug68)
    io = np.linalg.norm(obs.mean[0, 36] - obs.mean[0, 45])
    gap = [np.linalg.norm(detected[m] - obs.mean[0, i]) / io for m, i in same if np.isfinite(detected[m]).all()]
    assert len(gap) >= 5 and np.mean(gap) < 0.06, gap
    cfg = fit_config.load("small")
    obs2, fit = landmark_fit(read_inputs([path], 1024), "dlib", default_model, cfg, log=lambda s: None)
    assert fit.converged and fit.rmse_px[0] < 4.0, fit.rmse_px
    Image.fromarray(np.full((256, 256, 3), 128, np.uint8)).save(tmp_path / "grey.png")
    with pytest.raises(SynthError, match="no face found") as e:
        observations(read_inputs([tmp_path / "grey.png"], 1024), "dlib", default_model)
    assert str(tmp_path / "grey.png") in str(e.value) and "\n" not in str(e.value)


def test_dlib_not_installed_is_one_line(monkeypatch):
    pytest.importorskip("dlib", reason="the synth-faces[judge] extra (dlib) is not installed: make setup")
    import importlib.util

    from prior.fit.landmark_sources import require_dlib

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "face_recognition_models" else real(name, *a))
    with pytest.raises(SynthError, match="landmark weights") as e:
        require_dlib()
    assert "synth-faces[judge]" in str(e.value) and "\n" not in str(e.value)
