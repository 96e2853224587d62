"""The foreground mask of a photo next to the photo: docs/fitting_mask.png.

    .venv/bin/python benchmarks/photo_mask.py [-o docs/fitting_mask.png] [--tile 192]

scikit-image's astronaut (public domain) goes the way ``synth prior fit PHOTO --landmarks mediapipe``
takes it (:func:`prior.fit.inputs.read_inputs`, :func:`prior.fit.inputs.observations`): the mask
is the fit's, mediapipe's selfie segmentation restricted to the fitted face's person. Three tiles:
the photo with the detected face-mesh points, the mask (white = 1), the photo multiplied by the
mask over grey. Prints the mask's mean over a few named boxes (hair, face, shoulders, background).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from prior.fit.inputs import observations, read_inputs  # noqa: E402
from synth.model.default import load_default_model  # noqa: E402

#: boxes (x0, y0, x1, y1) of the 512 x 512 astronaut, by eye: what the mask should keep and drop
BOXES = {"hair": (170, 25, 290, 60), "face": (190, 80, 250, 160), "shoulders": (60, 420, 160, 500),
         "background (flag)": (440, 20, 500, 120)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("docs/fitting_mask.png"))
    ap.add_argument("--tile", type=int, default=192)
    args = ap.parse_args(argv)
    from PIL import Image, ImageDraw
    from skimage import data

    photo = data.astronaut()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "astronaut.png"
        Image.fromarray(photo).save(path)
        inputs = read_inputs([path], 2048)
        obs = observations(inputs, "mediapipe", load_default_model())
    mask = inputs[0].mask
    for name, (x0, y0, x1, y1) in BOXES.items():
        print(f"{name}: mask mean {mask[y0:y1, x0:x1].mean():.3f}")
    H, W = mask.shape
    s = args.tile / W
    shown = Image.fromarray(photo)
    draw = ImageDraw.Draw(shown)
    for x, y in obs.mean[0]:
        draw.ellipse((x - 1.5, y - 1.5, x + 1.5, y + 1.5), fill=(0, 255, 0))
    grey = np.full_like(photo, 128)
    cut = (mask[..., None] * photo + (1 - mask[..., None]) * grey + 0.5).astype(np.uint8)
    tiles = [shown, Image.fromarray((mask * 255 + 0.5).astype(np.uint8)).convert("RGB"), Image.fromarray(cut)]
    sheet = Image.new("RGB", (3 * args.tile, round(H * s)))
    for i, t in enumerate(tiles):
        sheet.paste(t.resize((args.tile, round(H * s)), Image.Resampling.LANCZOS), (i * args.tile, 0))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(args.out, optimize=True)
    print(f"wrote {args.out} ({sheet.width} x {sheet.height})")


if __name__ == "__main__":
    main()
