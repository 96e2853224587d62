"""The images a face is fitted to, and their landmarks.

Two kinds of input (``synth prior fit IMAGES...``):

- **synth frames**: ``KEY.exr`` with ``KEY.json`` beside it. The colour is the EXR's
  premultiplied linear RGB (colour over black) and the alpha is the foreground mask; the JSON
  gives the landmarks (``--landmarks json``) and the indices that ``synth prior eval`` uses. Its
  camera is never an input (evaluation only).
- **photos**: PNG or JPEG (sRGB, decoded to linear by :mod:`prior.fit.photos`: EXIF orientation
  applied, grey, CMYK and 16-bit files read, larger than ``fit.max_side_px`` downscaled while
  decoded, the EXIF focal length kept). The mask is the PNG's alpha channel if it has one, else
  mediapipe's selfie segmentation (``--landmarks mediapipe``), else the whole image (reported
  as such).

The fit works on one canvas, the first image's (decoded) size: the fitted cameras share one
focal length (a shared scale of each image's initial focal length). An image of another size
is scaled uniformly to fit inside the canvas and centred on it (its ``scale`` and ``offset``,
canvas = decoded * scale + offset, are kept in ``fit.json``); the border it leaves is outside
the mask. Every check happens before anything is fitted or written; each failure is one
:class:`SynthError` line naming the file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prior.fit.landmarks_fit import MIN_LANDMARKS, Observations
from synth.appearance.srgb import linear_to_srgb
from synth.errors import SynthError

PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg")
FRAME_SUFFIX = ".exr"
SOURCES = ("auto", "json", "mediapipe", "dlib")


@dataclass
class InputImage:
    path: Path
    target: np.ndarray  # (H, W, 3) float32 linear colour multiplied by the mask (over black)
    mask: np.ndarray | None  # (H, W) float32 in [0, 1]; None = not known yet (photo without alpha)
    frame: object | None = None  # synth.dataset.reader.Frame for synth frames
    photo: dict | None = None  # what decoding did (prior.fit.photos.Photo without its pixels)
    scale: tuple[float, float] = (1.0, 1.0)  # canvas pixels per decoded pixel in x and y (equal but for rounding)
    offset: tuple[int, int] = (0, 0)  # where the decoded image's top-left corner lies on the canvas
    content: tuple[int, int] | None = None  # (width, height) of the image on the canvas; None = all of it
    detection: dict | None = None  # faces found by the landmark detector (photos)
    focal_px: float | None = None  # EXIF focal length in canvas pixels (the fit's initial focal)
    mask_source: str = "none"  # "alpha" (the frame's or the PNG's), "segmentation" (mediapipe) or "none"

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return int(self.target.shape[1]), int(self.target.shape[0])

    def srgb8(self) -> np.ndarray:
        """(H, W, 3) uint8 sRGB of the colour over black (for detectors and figures)."""
        return (linear_to_srgb(self.target) * 255 + 0.5).astype(np.uint8)

    def record(self) -> dict:
        """What the fit's report keeps about this input (never its camera)."""
        out = {"path": str(self.path), "width": self.size[0], "height": self.size[1],
               "kind": "frame" if self.frame is not None else "photo"}
        if self.content is not None:
            out.update(scale=list(self.scale), offset=list(self.offset), content_size=list(self.content))
        if self.photo is not None:
            out.update(self.photo)
        if self.detection is not None:
            out.update(self.detection)
        if self.frame is not None:
            f = self.frame
            out.update(key=f.key, identity_index=f.identity_index, expression_index=f.expression_index,
                       view_index=f.view_index)
        return out


def _read_photo(p: Path, max_side: int) -> InputImage:
    from prior.fit.photos import read_photo

    ph = read_photo(p, max_side)
    rec = {"source_size": list(ph.source_size), "decode_scale": ph.scale, "orientation": ph.orientation,
           "pixel_format": ph.mode, "exif_focal_px": ph.focal_px}
    target = ph.colour * (1.0 if ph.alpha is None else ph.alpha[..., None])
    return InputImage(p, target, ph.alpha, photo=rec, focal_px=ph.focal_px,
                      mask_source="none" if ph.alpha is None else "alpha")


def _read_frame(p: Path) -> InputImage:
    from synth.dataset.reader import read_frame

    if not p.with_suffix(".json").is_file():
        raise SynthError("synth frame has no JSON beside it", str(p.with_suffix(".json")),
                         "keep KEY.json next to KEY.exr (as synth render writes them)")
    f = read_frame(p.with_suffix(".json"))
    return InputImage(p, np.ascontiguousarray(f.rgba[..., :3], np.float32), np.clip(f.alpha, 0, 1).astype(np.float32),
                      frame=f, mask_source="alpha")


def _place(im: InputImage, width: int, height: int) -> None:
    """Scale ``im`` uniformly to fit inside a ``width`` x ``height`` canvas, centred (module docstring)."""
    from prior.fit.views import resample

    w, h = im.size
    s = min(width / w, height / h)
    cw, ch = min(width, max(1, round(w * s))), min(height, max(1, round(h * s)))
    ox, oy = (width - cw) // 2, (height - ch) // 2
    planes = [im.target] + ([] if im.mask is None else [im.mask[..., None]])
    small = resample(np.concatenate(planes, axis=2)[None], cw, ch)[0]
    canvas = np.zeros((height, width, small.shape[2]), np.float32)
    canvas[oy:oy + ch, ox:ox + cw] = small
    im.target = np.ascontiguousarray(canvas[..., :3])
    im.mask = None if im.mask is None else np.clip(canvas[..., 3], 0.0, 1.0)
    im.scale, im.offset, im.content = (cw / w, ch / h), (ox, oy), (cw, ch)
    if im.focal_px is not None:
        im.focal_px *= s


def content_mask(im: InputImage) -> np.ndarray:
    """(H, W) float32: 1 where the image lies on the canvas, 0 on the border placing left."""
    H, W = im.target.shape[:2]
    out = np.zeros((H, W), np.float32)
    (ox, oy), (cw, ch) = im.offset, im.content or (W, H)
    out[oy:oy + ch, ox:ox + cw] = 1.0
    return out


def to_canvas(im: InputImage, points: np.ndarray) -> np.ndarray:
    """Pixel positions (..., 2) in the decoded image -> on the canvas."""
    return np.asarray(points, np.float64) * im.scale + im.offset


def read_inputs(paths, max_side: int) -> list[InputImage]:
    """Decode every image (see the module docstring; photos at most ``max_side`` pixels on their
    longer side: the fit config's ``fit.max_side_px``) onto the first one's canvas."""
    if not paths:
        raise SynthError("no images given", "synth prior fit", "pass 1 to 3 (or more) images of one face")
    out = []
    for raw in paths:
        p = Path(raw)
        if not p.is_file():
            raise SynthError("image not found", str(p), "check the path")
        suffix = p.suffix.lower()
        if suffix == FRAME_SUFFIX:
            img = _read_frame(p)
        elif suffix in PHOTO_SUFFIXES:
            img = _read_photo(p, max_side)
        else:
            raise SynthError(f"unsupported image type '{p.suffix}'", str(p),
                             "pass PNG or JPEG photos, or synth frame EXRs with their JSON")
        if not np.isfinite(img.target).all():
            raise SynthError("image holds NaN or Inf values", str(p), "pass a clean image")
        out.append(img)
    W, H = out[0].size
    for im in out[1:]:
        if im.size != (W, H):
            _place(im, W, H)
    return out


def resolve_source(inputs: list[InputImage], source: str) -> str:
    """``auto`` -> ``json`` when every input is a synth frame, else ``mediapipe``."""
    if source not in SOURCES:
        raise SynthError(f"unknown landmark source '{source}'", "--landmarks", "use json, mediapipe or dlib")
    if source == "auto":
        return "json" if all(im.frame is not None for im in inputs) else "mediapipe"
    if source == "json":
        photos = [im for im in inputs if im.frame is None]
        if photos:
            raise SynthError("--landmarks json needs synth frames (KEY.exr with KEY.json)", str(photos[0].path),
                             "use --landmarks mediapipe for photos")
    return source


def _check_counts(inputs: list[InputImage], obs: Observations) -> None:
    """No visible landmark = no face; fewer than the fit needs = a clear line naming the image."""
    for im, n in zip(inputs, obs.used.sum(1).tolist()):
        if n == 0:
            raise SynthError("no face in the image: no landmark is visible", str(im.path),
                             "use images with one clearly visible face")
        if n < MIN_LANDMARKS:
            raise SynthError(f"only {n} landmarks are visible, the fit needs at least {MIN_LANDMARKS}",
                             str(im.path), "use views where more of the face is visible")


def observations(inputs: list[InputImage], source: str, model, *, sigma_px: float = 1.0, noise_px: float = 0.0,
                 seed: int = 0) -> Observations:
    """Landmarks of every input from ``source`` (json or mediapipe); photos without a mask get
    mediapipe's foreground segmentation."""
    if source == "json":
        from prior.fit.landmark_sources import frame_observations

        per = [frame_observations([im.frame], noise_px=noise_px, sigma_px=sigma_px, seed=seed) for im in inputs]
        W, H = inputs[0].size
        obs = Observations(np.stack([to_canvas(im, o.mean[0]) for im, o in zip(inputs, per)]),
                           np.concatenate([o.sigma for o in per]), W, H, landmark_set=per[0].landmark_set)
    else:
        from prior.fit.landmark_sources import dlib_observations, mediapipe_observations

        try:
            if source == "dlib":
                obs, masks, found = dlib_observations([im.srgb8() for im in inputs])
            else:
                obs, masks, found = mediapipe_observations([im.srgb8() for im in inputs], model)
        except SynthError as e:
            if e.where and e.where.startswith("image ") and e.where[6:].isdigit():
                raise SynthError(e.what, str(inputs[int(e.where[6:])].path), e.fix) from None
            raise
        for im, m, d in zip(inputs, masks, found):
            im.detection = d
            if im.mask is None and m is not None:
                im.mask = np.clip(np.asarray(m, np.float32), 0, 1) * content_mask(im)
                im.target = im.target * im.mask[..., None]
                im.mask_source = "segmentation"
    _check_counts(inputs, obs)
    return obs
