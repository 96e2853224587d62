"""Where 2D landmarks come from: synth frames (their JSON) or a real-photo detector.

``json``: a synth frame's ``landmarks_2d`` (the exact projections of the model's ibug68
landmarks) and ``landmarks_visible``; optional Gaussian noise (``noise_px`` per axis, from
``seeds.generator(seed, FRAME, identity, expression, view)`` of the frame's own indices) and
a sigma per point (``max(sigma_px, noise_px)``; hidden points unused, or with ``hidden_sigma_px``).
The frame's camera is for evaluation only: K is passed on only when asked (``known_intrinsics``).

``mediapipe``: the optional ``synth-faces[fit]`` extra, ``mediapipe==0.10.21`` (the last wheel that
bundles its face-mesh and selfie-segmentation models). Its 478 refined face-mesh points are
mapped to model surface points by the correspondence in ``prior/fit/data/`` (docs/fitting.md:
how it was derived and what is missing); the selfie segmentation gives foreground masks.
Up to :data:`MAX_FACES` faces are looked for in each photo: the largest is fitted (its size, the
longer side of its points' bounding box, at least :data:`MIN_FACE_PX`), unless another is at least
:data:`SIMILAR_FACE_RATIO` times as large, which is refused as ambiguous. The face mesh finds
faces with mediapipe's short-range detector, which sees the photo at 128 x 128 and misses faces
under about a tenth of its width; when it finds none, the full-range detector looks for faces,
and the face mesh runs again on a square crop :data:`CROP_FACTOR` times each face's box.
The foreground mask is the selfie segmentation's, restricted to the fitted face's person
(:func:`person_mask`).

``dlib``: the optional ``synth-faces[judge]`` extra (``dlib-bin``, and ``face_recognition_models``
for the weights): dlib's HOG face detector (the photo as it is and upsampled once, twice if neither
finds a face; detector scores from 0) and its 68-point shape predictor, whose points are iBUG's 68
(the ``ibug68`` landmark set of the head model): no correspondence is needed. The face to fit is
chosen by :func:`choose_face`'s rule with the detector's confidence (score at least
:data:`DLIB_MIN_SCORE`): the largest face, unless it is not a confident one and a confident face of
similar size exists; only confident faces make a photo ambiguous; at least :data:`DLIB_MIN_FACE_PX`.
The predictor was trained on iBUG 300-W, whose images are licensed for research only: prefer
``mediapipe`` where that matters (docs/fitting.md). Each point's sigma is :data:`DLIB_SIGMA_FACE` of
the face's size (its points' bounding box), twice that on the jaw (iBUG's jaw is the face's outline,
which the model's fixed jaw points follow only near the front), at least ``min_sigma_px``. The
foreground mask is mediapipe's (as above) when the fit extra is installed, else none.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from prior.fit.landmarks_fit import Observations
from synth import seeds
from synth.errors import SynthError
from synth.model.meshutil import barycentric_points

MEDIAPIPE_VERSION = "0.10.21"
CORRESPONDENCE_DIR = Path(__file__).resolve().parent / "data"
#: mediapipe's points at the two sides of the face: their distance is the image's scale
FACE_SIDES = (234, 454)

#: mediapipe's ``x * W`` has pixel centres at integers, synth's at +0.5 (docs/conventions.md):
#: mediapipe points are shifted by this many pixels (measured by resampling: benchmarks/realism/judge.py)
MP_PIXEL_OFFSET = 0.5
#: faces looked for per photo; the largest is fitted
MAX_FACES = 4
#: smallest face (longer side of the detected points' bounding box, pixels) that is fitted
MIN_FACE_PX = 64
#: a second face at least this fraction of the largest one's size makes a photo ambiguous
SIMILAR_FACE_RATIO = 0.8
#: the segmentation value from which a pixel belongs to a person's region (:func:`person_mask`)
PERSON_THRESHOLD = 0.5
#: pixels the person's region is grown by, so that the segmentation's soft edge stays in the mask
PERSON_EDGE_PX = 3
#: side of the crop around a face found by the full-range detector, in units of its box's longer side
CROP_FACTOR = 2.0
#: dlib's upsampling steps (the last only when the others find no face); the detector score from
#: which a face is confident enough to make a photo ambiguous (the astronaut's mission patch scores
#: 0.12, a face turned 60 degrees -0.15 to 0.2, frontal faces 0.5 and more); and the smallest face,
#: the longer side of its 68 points' box (brows to chin: about three quarters of what mediapipe's
#: points span, forehead included, so MIN_FACE_PX's face)
DLIB_UPSAMPLE = (0, 1, 2)
DLIB_MIN_SCORE = 0.2
DLIB_MIN_FACE_PX = 48
#: a dlib point's sigma as a fraction of the face's size (×2 on the jaw); its pixel coordinates
#: are pixel indices, synth's pixel centres are at +0.5
DLIB_SIGMA_FACE, DLIB_JAW_SIGMA_FACTOR, DLIB_PIXEL_OFFSET = 0.012, 2.0, 0.5
DLIB_WEIGHTS = "shape_predictor_68_face_landmarks.dat"


# --------------------------------------------------------------------------- synth frames


def read_frames(paths) -> list:
    """Frames (:class:`synth.dataset.reader.Frame`) from paths to their ``.json`` or ``.exr``."""
    from synth.dataset.reader import read_frame

    return [read_frame(Path(p).with_suffix(".json")) for p in paths]


def frame_observations(frames, *, noise_px: float = 0.0, sigma_px: float = 1.0, seed: int = 0,
                       hidden_sigma_px: float | None = None, known_intrinsics: bool = False) -> Observations:
    """Observations (ibug68) from synth frames' JSON. All frames must have one image size."""
    if not frames:
        raise SynthError("no frames given", "landmarks", "pass at least one frame")
    if noise_px < 0 or sigma_px <= 0:
        raise SynthError(f"noise {noise_px} px and sigma {sigma_px} px must be >= 0 and > 0", "landmarks",
                         "pass sensible pixel values")
    sizes = {(f.width, f.height) for f in frames}
    if len(sizes) > 1:
        raise SynthError(f"images differ in size: {sorted(sizes)}", "landmarks",
                         "fit images of one size (one camera, shared intrinsics)")
    means, sigmas, Ks = [], [], []
    for f in frames:
        where = f"frame {f.key}"
        try:
            lm = np.asarray(f.meta["landmarks_2d"], np.float64)
            vis = np.asarray(f.meta["landmarks_visible"], bool)
        except KeyError as e:
            raise SynthError(f"frame JSON has no {e}", where, "use frames rendered by synth") from None
        if lm.ndim != 2 or lm.shape[1] != 2 or vis.shape != lm.shape[:1]:
            raise SynthError(f"landmarks_2d {lm.shape} / landmarks_visible {vis.shape} are malformed", where,
                             "use frames rendered by synth")
        if noise_px > 0:
            g = seeds.generator(seed, seeds.Stream.FRAME, f.identity_index, f.expression_index, f.view_index)
            lm = lm + noise_px * g.standard_normal(lm.shape)
        s = max(sigma_px, noise_px)
        hidden = np.inf if hidden_sigma_px is None else hidden_sigma_px
        means.append(lm)
        sigmas.append(np.where(vis, s, hidden))
        Ks.append(f.K)
    (W, H), = sizes
    return Observations(np.stack(means), np.stack(sigmas), W, H, np.stack(Ks) if known_intrinsics else None,
                        landmark_set="ibug68")


# --------------------------------------------------------------------------- mediapipe


def require_mediapipe():
    """The mediapipe module, or one SynthError line saying how to install it (for the CLI)."""
    fix = f"install the fit extra: pip install 'synth-faces[fit]' (mediapipe=={MEDIAPIPE_VERSION}; docs/fitting.md)"
    try:
        import mediapipe
    except ImportError:
        raise SynthError("the mediapipe landmark detector is not installed", "--landmarks mediapipe", fix) from None
    version = getattr(mediapipe, "__version__", "?")
    if version != MEDIAPIPE_VERSION:
        raise SynthError(f"mediapipe {version} is installed; only {MEDIAPIPE_VERSION} bundles the face-mesh and "
                         "selfie-segmentation models (later releases download them)", "--landmarks mediapipe", fix)
    return mediapipe


#: how far (m) a correspondence's surface points may lie from where they were on the rest shape it
#: was derived on: builds of the same model on other CPUs differ in the last float32 bits only
CORRESPONDENCE_TOLERANCE_M = 1e-5


def model_key(model) -> str:
    """Identifies a head model's name and topology, what a correspondence file is named by. Its rest
    shape is checked by :func:`load_correspondence` against the file's ``template_points`` within
    :data:`CORRESPONDENCE_TOLERANCE_M`. The default model is one shipped file, so its key is the same
    on every machine (docs/default-model.md)."""
    import hashlib

    h = hashlib.sha256(str(model.name).encode())
    h.update(np.ascontiguousarray(model.triangles, np.int32).tobytes())
    return h.hexdigest()[:16]


def load_correspondence(model) -> dict:
    """The mediapipe -> model correspondence for this model: ``index`` (P,) mediapipe point
    indices, ``triangles`` (P,), ``bary`` (P, 3), ``sigma_face`` (P,: the point's RMS residual
    on the derivation renders in units of the face width) and the file's metadata. One SynthError
    line if there is none for the model's topology, or if it was derived on another rest shape."""
    key = model_key(model)
    path = CORRESPONDENCE_DIR / f"mediapipe-{key}.json"
    fix = "use --landmarks json, or derive one (docs/fitting.md)"
    if not path.is_file():
        raise SynthError(f"no mediapipe landmark correspondence for head model '{model.name}' ({key})",
                         "--landmarks mediapipe", fix)
    d = json.loads(path.read_text())
    pts = d["points"]
    out = {**d, "index": np.array([p["mediapipe"] for p in pts], np.int64),
           "triangles": np.array([p["triangle"] for p in pts], np.int64),
           "bary": np.array([p["bary"] for p in pts], np.float64),
           "sigma_face": np.array([p["sigma_face"] for p in pts], np.float64)}
    if "template_points" not in d:
        raise SynthError(f"the mediapipe landmark correspondence {path.name} has no template_points (format "
                         f"{d.get('format_version')}; 2 is read)", "--landmarks mediapipe", fix)
    on_template = barycentric_points(np.asarray(model.template, np.float64), model.triangles, out["triangles"], out["bary"])
    off = np.linalg.norm(on_template - np.asarray(d["template_points"]), axis=1)
    if off.max() > CORRESPONDENCE_TOLERANCE_M:
        raise SynthError(f"the mediapipe landmark correspondence {path.name} was derived on another rest shape of head "
                         f"model '{model.name}' (its points up to {1000.0 * off.max():.3f} mm away)",
                         "--landmarks mediapipe", fix)
    return out


@contextlib.contextmanager
def quiet_native_stderr():
    """mediapipe's C++ code (absl, TensorFlow Lite) writes log lines straight to file descriptor 2;
    while it runs they go to a temporary file, so that an error stays one line."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def choose_face(faces: list[np.ndarray], where: str, *, min_px: float = MIN_FACE_PX,
                confident: list[bool] | None = None) -> tuple[int, list[float]]:
    """Index of the face to fit among detected point sets (each (K, 2) pixels) and every face's
    size (longer side of its bounding box), or one SynthError line (module docstring). With
    ``confident`` (per face: the detector is sure of it), a face the detector is not sure of gives
    way to a sure one of similar size, and never makes the photo ambiguous."""
    fix = "use photos with one clearly visible face"
    if not faces:
        raise SynthError("no face found", where, fix)
    sizes = [float(np.max(f.max(0) - f.min(0))) for f in faces]
    order = sorted(range(len(faces)), key=lambda i: (-sizes[i], i))
    best = order[0]
    if confident is not None and not confident[best]:
        sure = [i for i in order if confident[i] and sizes[i] >= SIMILAR_FACE_RATIO * sizes[best]]
        best = sure[0] if sure else best
    rivals = [i for i in order if i != best and (confident is None or confident[i])]
    if rivals and sizes[rivals[0]] >= SIMILAR_FACE_RATIO * sizes[best]:
        raise SynthError(f"{len(faces)} faces of similar size ({sizes[best]:.0f} and {sizes[rivals[0]]:.0f} px)",
                         where, "crop the photo to the face to fit (the largest face is fitted when it is clearly "
                         "the largest)")
    if sizes[best] < min_px:
        raise SynthError(f"the face is {sizes[best]:.0f} px across, the fit needs at least {min_px:.0f} px",
                         where, "use a photo where the face is larger (closer, or of a higher resolution)")
    return best, sizes


def _mesh_points(result, x0: float, y0: float, w: int, h: int) -> list[np.ndarray]:
    """(478, 2) pixel positions of each face of a face-mesh result on a crop at (x0, y0) of size w x h."""
    return [np.array([[p.x * w + x0 + MP_PIXEL_OFFSET, p.y * h + y0 + MP_PIXEL_OFFSET] for p in f.landmark])
            for f in (result.multi_face_landmarks or [])]


def detect_faces(face_mesh, face_detection, im: np.ndarray) -> list[np.ndarray]:
    """Every face's mesh points in a photo (module docstring: the face mesh on the whole photo,
    else on crops around the faces the full-range detector finds; a face found twice is kept once)."""
    H, W = im.shape[:2]
    faces = _mesh_points(face_mesh.process(im), 0, 0, W, H)
    if faces:
        return faces
    for d in face_detection.process(im).detections or []:
        b = d.location_data.relative_bounding_box
        cx, cy = (b.xmin + 0.5 * b.width) * W, (b.ymin + 0.5 * b.height) * H
        half = 0.5 * CROP_FACTOR * max(b.width * W, b.height * H)
        x0, y0 = max(0, int(np.floor(cx - half))), max(0, int(np.floor(cy - half)))
        x1, y1 = min(W, int(np.ceil(cx + half))), min(H, int(np.ceil(cy + half)))
        if x1 - x0 < 8 or y1 - y0 < 8:
            continue
        for f in _mesh_points(face_mesh.process(np.ascontiguousarray(im[y0:y1, x0:x1])), x0, y0, x1 - x0, y1 - y0):
            c = f.mean(0)
            if not any(np.all((g.min(0) <= c) & (c <= g.max(0))) for g in faces):
                faces.append(f)
    return faces


def person_mask(mask: np.ndarray, faces: list[np.ndarray], best: int) -> np.ndarray:
    """The selfie segmentation's ``mask`` (H, W) restricted to the person whose face is ``faces[best]``
    (each face (478, 2) pixels): the connected regions of ``mask >= PERSON_THRESHOLD`` (8-connected)
    that reach into that face's bounding box, less the pixels nearer another detected face's
    centre than this one's (two people touching), grown by :data:`PERSON_EDGE_PX` pixels to keep the
    soft edge; the mask's own values inside. Where no region reaches the face the mask is kept."""
    from scipy import ndimage

    m = np.asarray(mask, np.float32)
    H, W = m.shape
    labels, _ = ndimage.label(m >= PERSON_THRESHOLD, structure=np.ones((3, 3), bool))
    lo = np.clip(np.floor(faces[best].min(0)).astype(int), 0, [W - 1, H - 1])
    hi = np.clip(np.ceil(faces[best].max(0)).astype(int) + 1, 1, [W, H])
    touching = np.unique(labels[lo[1]:hi[1], lo[0]:hi[0]])
    touching = touching[touching > 0]
    if len(touching) == 0:
        return m
    keep = np.isin(labels, touching)
    if len(faces) > 1:
        yy, xx = np.nonzero(keep)
        centres = np.array([0.5 * (f.min(0) + f.max(0)) for f in faces])
        d2 = (xx[:, None] + 0.5 - centres[:, 0]) ** 2 + (yy[:, None] + 0.5 - centres[:, 1]) ** 2
        keep[yy, xx] = np.argmin(d2, axis=1) == best  # ties go to the lower face index
    keep = ndimage.binary_dilation(keep, iterations=PERSON_EDGE_PX)
    return np.where(keep, m, 0.0).astype(np.float32)


def mediapipe_observations(images, model, *, min_sigma_px: float = 1.0) -> tuple[Observations, list[np.ndarray],
                                                                                 list[dict]]:
    """Observations from RGB photos ((H, W, 3) uint8, sRGB) by mediapipe's face mesh, the
    photos' foreground masks by its selfie segmentation ((H, W) float32 in [0, 1]), and per photo
    what was found: ``faces`` (how many) and ``face_px`` (the fitted one's size)."""
    mp = require_mediapipe()
    sizes = {np.asarray(im).shape for im in images}
    if len(sizes) != 1 or len(next(iter(sizes))) != 3:
        raise SynthError(f"images must be RGB of one size, got {sorted(sizes)}", "--landmarks mediapipe",
                         "resize or crop the photos to one size")
    H, W, _ = next(iter(sizes))
    points, masks, found = [], [], []
    with quiet_native_stderr(), \
            mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=MAX_FACES,
                                            refine_landmarks=True) as fm, \
            mp.solutions.face_detection.FaceDetection(model_selection=1) as fd, \
            mp.solutions.selfie_segmentation.SelfieSegmentation(model_selection=0) as seg:
        for i, im in enumerate(images):
            im = np.ascontiguousarray(im, np.uint8)
            faces = detect_faces(fm, fd, im)
            best, sizes = choose_face(faces, f"image {i}")
            points.append(faces[best])
            found.append({"faces": len(faces), "face_px": round(sizes[best], 1)})
            masks.append(person_mask(np.asarray(seg.process(im).segmentation_mask, np.float32), faces, best))
    corr = load_correspondence(model)  # after the photos' checks: a photo without a face is named first
    obs = mediapipe_points_observations(np.asarray(points), W, H, corr, min_sigma_px=min_sigma_px)
    return obs, masks, found


def mediapipe_points_observations(points, width: int, height: int, corr: dict, *,
                                  min_sigma_px: float = 1.0) -> Observations:
    """Observations from detected face-mesh points (N, 478, 2) in pixels and a correspondence
    (:func:`load_correspondence`). Each mapped point's sigma is its residual on the derivation
    renders (``sigma_face``) times the detected face width (distance of points ``FACE_SIDES``),
    and at least ``min_sigma_px``."""
    pts = np.asarray(points, np.float64)
    face_px = np.linalg.norm(pts[:, FACE_SIDES[1]] - pts[:, FACE_SIDES[0]], axis=-1)  # (N,)
    sigma = np.maximum(min_sigma_px, corr["sigma_face"][None] * face_px[:, None])
    return Observations(pts[:, corr["index"]], sigma, width, height, None, landmark_set="mediapipe",
                        landmark_def=(corr["triangles"], corr["bary"]))


# --------------------------------------------------------------------------- dlib


def require_dlib():
    """(the dlib module, the 68-point predictor's weights file), or one SynthError line saying how
    to install them. The weights are found without importing face_recognition_models (its
    ``__init__`` needs pkg_resources, which an environment need not have)."""
    fix = "install the judge extra: pip install 'synth-faces[judge]' (dlib-bin, face_recognition_models)"
    try:
        import dlib
    except ImportError:
        raise SynthError("the dlib landmark detector is not installed", "--landmarks dlib", fix) from None
    spec = importlib.util.find_spec("face_recognition_models")
    locations = list(spec.submodule_search_locations or []) if spec is not None else []
    path = Path(locations[0]) / "models" / DLIB_WEIGHTS if locations else None
    if path is None or not path.is_file():
        raise SynthError(f"dlib's 68-point landmark weights ({DLIB_WEIGHTS}) are not installed", "--landmarks dlib",
                         fix)
    return dlib, path


def dlib_faces(detector, predictor, im: np.ndarray) -> tuple[list[np.ndarray], list[float]]:
    """Every face dlib finds in a photo (module docstring: the photo as it is and upsampled once,
    twice only if neither finds one; a face found again, its box's centre inside one already
    kept, counts once, with the higher score): its 68 points ((68, 2) pixels, synth's convention)
    and the detector's score, in the order found."""
    boxes: list[tuple[float, float, float, float]] = []
    dets, scores = [], []
    for up in DLIB_UPSAMPLE:
        if up == DLIB_UPSAMPLE[-1] and dets:
            break
        found, sc, _ = detector.run(im, up, 0.0)
        for d, score in zip(found, sc):
            b = (d.left(), d.top(), d.right(), d.bottom())
            cx, cy = 0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])
            same = [k for k, o in enumerate(boxes) if o[0] <= cx <= o[2] and o[1] <= cy <= o[3]]
            if same:
                if score > scores[same[0]]:
                    dets[same[0]], scores[same[0]], boxes[same[0]] = d, float(score), b
                continue
            dets.append(d)
            scores.append(float(score))
            boxes.append(b)
    out = []
    for d in dets:
        shape = predictor(im, d)
        out.append(np.array([[shape.part(k).x, shape.part(k).y] for k in range(68)], np.float64) + DLIB_PIXEL_OFFSET)
    return out, scores


def dlib_observations(images, *, min_sigma_px: float = 1.0) -> tuple[Observations, list[np.ndarray | None],
                                                                    list[dict]]:
    """Observations (ibug68) from RGB photos ((H, W, 3) uint8) by dlib (module docstring), the
    photos' foreground masks (mediapipe's selfie segmentation restricted to the fitted face's
    person; None where the fit extra is not installed) and per photo what was found."""
    dlib, weights = require_dlib()
    sizes = {np.asarray(im).shape for im in images}
    if len(sizes) != 1 or len(next(iter(sizes))) != 3:
        raise SynthError(f"images must be RGB of one size, got {sorted(sizes)}", "--landmarks dlib",
                         "resize or crop the photos to one size")
    H, W, _ = next(iter(sizes))
    detector, predictor = dlib.get_frontal_face_detector(), dlib.shape_predictor(str(weights))
    per_image = []
    for i, im in enumerate(images):
        im = np.ascontiguousarray(im, np.uint8)
        faces, scores = dlib_faces(detector, predictor, im)
        best, face_sizes = choose_face(faces, f"image {i}", min_px=DLIB_MIN_FACE_PX,
                                       confident=[sc >= DLIB_MIN_SCORE for sc in scores])
        per_image.append((im, faces, best, face_sizes[best]))
    try:
        mp = require_mediapipe()
    except SynthError:
        mp = None
    masks: list[np.ndarray | None] = [None] * len(images)
    if mp is not None:
        with quiet_native_stderr(), mp.solutions.selfie_segmentation.SelfieSegmentation(model_selection=0) as seg:
            masks = [person_mask(np.asarray(seg.process(im).segmentation_mask, np.float32), faces, best)
                     for im, faces, best, _ in per_image]
    pts = np.stack([faces[best] for _, faces, best, _ in per_image])
    size = np.array([px for *_, px in per_image])
    sigma = np.maximum(min_sigma_px, DLIB_SIGMA_FACE * size[:, None] * np.where(np.arange(68) < 17,
                                                                               DLIB_JAW_SIGMA_FACTOR, 1.0)[None])
    found = [{"faces": len(faces), "face_px": round(float(px), 1)} for _, faces, _, px in per_image]
    return Observations(pts, sigma, W, H, None, landmark_set="ibug68"), masks, found
