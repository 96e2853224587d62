"""Decoding the photos people take (PNG or JPEG) into linear colour for a fit.

- **Orientation**: the EXIF orientation tag (a phone photo stored sideways) is applied, so the
  face is upright as a viewer shows it.
- **Pixel formats**: 8-bit grey, palette, RGB(A) and CMYK JPEG (Pillow's CMYK -> RGB; an ICC
  profile is not applied, every photo is read as sRGB); 16-bit grey PNG is scaled from 0..65535
  (Pillow would clip it to 0..255); 16-bit RGB(A) PNG is read at 8 bits by Pillow.
- **Size**: a photo whose longer side exceeds ``max_side`` is downscaled while it is decoded: a
  JPEG by its DCT at 1/2, 1/4 or 1/8, then to ``max_side`` by Pillow (Lanczos on the 8-bit sRGB
  values, alpha premultiplied), so an 8,000 x 6,000 photo never exists as floats at full size and
  every later stage (landmarks, masks, fine-tuning) sees the downscaled image.
- **Focal length**: from EXIF, in the decoded image's pixels: the 35 mm equivalent
  (``FocalLengthIn35mmFilm``, taken over the diagonal: f_px = f35 * diagonal_px / 43.27 mm), else
  ``FocalLength`` in mm times ``FocalPlaneXResolution`` (pixels per unit of the image as taken,
  ``PixelXDimension`` wide). It is the fit's initial focal length, not a fixed one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from synth.appearance.srgb import srgb_to_linear
from synth.errors import SynthError

TAG_ORIENTATION = 0x0112
IFD_EXIF = 0x8769
TAG_FOCAL_MM = 0x920A
TAG_FOCAL_35MM = 0xA405
TAG_PLANE_X_RES = 0xA20E
TAG_PLANE_RES_UNIT = 0xA210
TAG_PIXEL_X_DIM = 0xA002
#: FocalPlaneResolutionUnit -> millimetres per unit (EXIF 2.3: 2 inch, 3 cm, 4 mm, 5 um)
PLANE_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}
FULL_FRAME_DIAGONAL_MM = float(np.hypot(36.0, 24.0))
SIXTEEN_BIT_GREY = ("I;16", "I;16L", "I;16B", "I;16N", "I")
SRGB8_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)


@dataclass
class Photo:
    colour: np.ndarray  # (H, W, 3) float32 linear, straight (not multiplied by alpha)
    alpha: np.ndarray | None  # (H, W) float32 in [0, 1], or None when the file has none
    source_size: tuple[int, int]  # (width, height) upright, before downscaling
    scale: float  # decoded pixels per source pixel (1, or less when downscaled)
    orientation: int  # the EXIF orientation applied (1: none)
    focal_px: float | None  # EXIF focal length in decoded pixels, or None
    mode: str  # Pillow's mode of the file (RGB, L, CMYK, I;16, ...)


def _positive(v) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return f if np.isfinite(f) and f > 0 else None


def exif_focal_px(exif, width: int, height: int) -> float | None:
    """The EXIF focal length in pixels of an upright ``width`` x ``height`` image (see the module
    docstring), or None when EXIF does not give one."""
    ifd = exif.get_ifd(IFD_EXIF) if exif is not None else {}
    f35 = _positive(ifd.get(TAG_FOCAL_35MM))
    if f35 is not None:
        return f35 * float(np.hypot(width, height)) / FULL_FRAME_DIAGONAL_MM
    f_mm, res = _positive(ifd.get(TAG_FOCAL_MM)), _positive(ifd.get(TAG_PLANE_X_RES))
    unit_mm = PLANE_UNIT_MM.get(int(ifd.get(TAG_PLANE_RES_UNIT, 2) or 2))
    if f_mm is None or res is None or unit_mm is None:
        return None
    f = f_mm * res / unit_mm
    taken_w = _positive(ifd.get(TAG_PIXEL_X_DIM))
    if taken_w is not None:  # the resolution is of the image as taken (stored orientation)
        stored_w = width if int(exif.get(TAG_ORIENTATION, 1) or 1) < 5 else height
        f *= stored_w / taken_w
    return f


def _fit_size(width: int, height: int, max_side: int) -> tuple[int, int]:
    s = min(1.0, max_side / max(width, height))
    return max(1, round(width * s)), max(1, round(height * s))


def read_photo(path, max_side: int) -> Photo:
    """Decode a PNG or JPEG (module docstring); one SynthError line if it cannot be read."""
    from PIL import Image, ImageOps, UnidentifiedImageError

    p = Path(path)
    fix = "pass PNG or JPEG photos, or synth frame EXRs with their JSON"
    try:
        with Image.open(p) as im:
            mode = im.mode
            exif = im.getexif()
            orientation = int(exif.get(TAG_ORIENTATION, 1) or 1)
            if orientation not in range(1, 9):
                orientation = 1
            sw, sh = im.size if orientation < 5 else im.size[::-1]
            want = _fit_size(sw, sh, max_side)
            if want != (sw, sh):
                k = sw / want[0]  # the decoder's own reductions first (JPEG: DCT scaling)
                im.draft(None, (int(np.ceil(im.size[0] / k)), int(np.ceil(im.size[1] / k))))
            im.load()
            im = ImageOps.exif_transpose(im)
            if mode in SIXTEEN_BIT_GREY:
                grey = Image.fromarray(np.asarray(im, np.float32) / 65535.0, mode="F")
                if grey.size != want:
                    grey = grey.resize(want, Image.Resampling.LANCZOS, reducing_gap=3.0)
                colour = srgb_to_linear(np.clip(np.asarray(grey), 0.0, 1.0)).astype(np.float32)
                colour, alpha = np.repeat(colour[..., None], 3, axis=2), None
            else:
                has_alpha = im.mode in ("RGBA", "LA", "RGBa", "La", "PA") or \
                    (im.mode == "P" and "transparency" in im.info)
                im = im.convert("RGBA" if has_alpha else "RGB")
                if im.size != want:
                    im = im.resize(want, Image.Resampling.LANCZOS, reducing_gap=3.0)
                rgba = np.asarray(im)
                colour = SRGB8_TO_LINEAR[rgba[..., :3]]  # a table: no float64 copy of the photo
                alpha = rgba[..., 3].astype(np.float32) / 255.0 if has_alpha else None
    except Image.DecompressionBombError as e:
        raise SynthError(f"image too large to decode safely ({e})", str(p), "downscale the photo") from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as e:
        raise SynthError(f"unreadable image ({type(e).__name__})", str(p), fix) from None
    scale = want[0] / sw
    focal = exif_focal_px(exif, sw, sh)
    return Photo(np.asarray(colour, np.float32), alpha, (sw, sh), scale, orientation,
                 None if focal is None else focal * scale, mode)
