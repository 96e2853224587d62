"""The images a face is fitted to, and their landmarks.

Two kinds of input (``synth prior fit IMAGES...``):

- **synth frames**: ``KEY.exr`` with ``KEY.json`` beside it. The colour is the EXR's
  premultiplied linear RGB (colour over black) and the alpha is the foreground mask; the JSON
  gives the landmarks (``--landmarks json``) and the indices that ``synth prior eval`` uses. Its
  camera is never an input (evaluation only).
- **photos**: PNG or JPEG (sRGB, decoded to linear). The mask is the PNG's alpha channel if it
  has one, else mediapipe's selfie segmentation (``--landmarks mediapipe``), else the whole
  image (reported as such).

All images must have one size: they are taken as photos of one camera with shared intrinsics
(the focal length is fitted once for all of them). Every check happens before anything is
fitted or written; each failure is one :class:`SynthError` line naming the file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prior.fit.landmarks_fit import MIN_LANDMARKS, Observations
from synth.dataset.preview import linear_to_srgb, srgb_to_linear
from synth.errors import SynthError

PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg")
FRAME_SUFFIX = ".exr"
SOURCES = ("auto", "json", "mediapipe")


@dataclass
class InputImage:
    path: Path
    target: np.ndarray  # (H, W, 3) float32 linear colour multiplied by the mask (over black)
    mask: np.ndarray | None  # (H, W) float32 in [0, 1]; None = not known yet (photo without alpha)
    frame: object | None = None  # synth.dataset.reader.Frame for synth frames

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
        if self.frame is not None:
            f = self.frame
            out.update(key=f.key, identity_index=f.identity_index, expression_index=f.expression_index,
                       view_index=f.view_index)
        return out


def _read_photo(p: Path) -> InputImage:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(p) as im:
            im.load()
            has_alpha = im.mode in ("RGBA", "LA") or (im.mode == "P" and "transparency" in im.info)
            rgba = np.asarray(im.convert("RGBA"), np.float32) / 255.0
    except (UnidentifiedImageError, OSError, ValueError) as e:
        raise SynthError(f"unreadable image ({type(e).__name__})", str(p),
                         "pass PNG or JPEG photos, or synth frame EXRs with their JSON") from None
    mask = rgba[..., 3].copy() if has_alpha else None
    colour = srgb_to_linear(rgba[..., :3]).astype(np.float32)
    return InputImage(p, colour * (1.0 if mask is None else mask[..., None]), mask)


def _read_frame(p: Path) -> InputImage:
    from synth.dataset.reader import read_frame

    if not p.with_suffix(".json").is_file():
        raise SynthError("synth frame has no JSON beside it", str(p.with_suffix(".json")),
                         "keep KEY.json next to KEY.exr (as synth render writes them)")
    f = read_frame(p.with_suffix(".json"))
    return InputImage(p, np.ascontiguousarray(f.rgba[..., :3], np.float32), np.clip(f.alpha, 0, 1).astype(np.float32),
                      frame=f)


def read_inputs(paths) -> list[InputImage]:
    """Decode every image (see the module docstring); one size for all."""
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
            img = _read_photo(p)
        else:
            raise SynthError(f"unsupported image type '{p.suffix}'", str(p),
                             "pass PNG or JPEG photos, or synth frame EXRs with their JSON")
        if not np.isfinite(img.target).all():
            raise SynthError("image holds NaN or Inf values", str(p), "pass a clean image")
        out.append(img)
    sizes = {im.size for im in out}
    if len(sizes) > 1:
        listing = ", ".join(f"{im.path.name} {im.size[0]}x{im.size[1]}" for im in out)
        raise SynthError(f"images differ in size ({listing})", "synth prior fit",
                         "pass images of one size: they are fitted as photos of one camera with shared "
                         "intrinsics (crop or resize them)")
    return out


def resolve_source(inputs: list[InputImage], source: str) -> str:
    """``auto`` -> ``json`` when every input is a synth frame, else ``mediapipe``."""
    if source not in SOURCES:
        raise SynthError(f"unknown landmark source '{source}'", "--landmarks", "use json or mediapipe")
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

        obs = frame_observations([im.frame for im in inputs], noise_px=noise_px, sigma_px=sigma_px, seed=seed)
    else:
        from prior.fit.landmark_sources import mediapipe_observations

        try:
            obs, masks = mediapipe_observations([im.srgb8() for im in inputs], model)
        except SynthError as e:
            if e.where and e.where.startswith("image ") and e.where[6:].isdigit():
                raise SynthError(e.what, str(inputs[int(e.where[6:])].path), e.fix) from None
            raise
        for im, m in zip(inputs, masks):
            if im.mask is None:
                im.mask = np.clip(np.asarray(m, np.float32), 0, 1)
                im.target = im.target * im.mask[..., None]
    _check_counts(inputs, obs)
    return obs
