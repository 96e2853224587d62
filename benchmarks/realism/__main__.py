"""Realism measurements (issue 13, part A). Prints Markdown tables for docs/realism.md.

    .venv/bin/python -m benchmarks.realism skin [--identities 200 --seed 0] [--frames DATASET ...]
    .venv/bin/python -m benchmarks.realism framing DATASET [DATASET ...]
    .venv/bin/python -m benchmarks.realism body-end DATASET [DATASET ...]
    .venv/bin/python -m benchmarks.realism shoulders [--identities 40 --seed 0 --garments tshirt_crew ...]
        [--hair long_straight ... --hair-identities 6]
    .venv/bin/python -m benchmarks.realism hair [--identities 12 --seed 0 --style braids]
    .venv/bin/python -m benchmarks.realism hats [--identities 3 --seed 0 --resolution 256]
    .venv/bin/python -m benchmarks.realism judge DATASET [--mp-python PY] [--max-azimuth 45]
        [--detections MP.json]
    .venv/bin/python -m benchmarks.realism jaw DATASET [--detections MP.json]
    .venv/bin/python -m benchmarks.realism mapping [--relax convex 1e-2 1e-3 ...] [--dataset D --detections MP.json]
    .venv/bin/python -m benchmarks.realism timing DATASET [DATASET ...]
    .venv/bin/python -m benchmarks.realism fringe REFERENCE DATASET [DATASET ...]

skin: the ITA histogram (six categories) and the CIELAB range of the skin albedo of the planned
  identities (``synth.appearance.skin.skin_albedo``, what the worker gives the shader); with
  ``--frames``, the same figures for the mean skin-class pixel of each rendered frame whose camera
  is within 30 degrees of frontal (uniform environment), next to its albedo.
framing: the fraction of frames in which head classes touch the left, right or top image
  border: eyes, mouth, teeth, hair, beard, brows, lashes, glasses, headwear anywhere on those
  borders, or skin on the top row or on the side columns above the chin (ibug68 point 8; skin
  below it is neck and bust).
body-end: the fraction of frames in which the body ends inside the image: no skin or clothing
  pixel on the bottom row while the frame shows skin or clothing (the bust's lower end floating
  in the frame; a portrait's body leaves through the bottom border), overall and by camera
  elevation.
shoulders: the body's breadth over the head's for planned identities (neutral) and garments: the
  widest extent side to side of the dressed body at the deltoids (garment, the torso below it, the bust's bare
  arms), over the breadth of the scalp; next to bideltoid over head breadth of measured adults
  (Pheasant's tables); and hair (--hair styles, tshirt_crew) within the sleeves' reach of the
  upper arms as groomed and after synth.assets.fit.arms.ArmKeepOut.
hair: strands in front of the inner face (synth.assets.fit.occlusion) for the planned hair of
  identities that have hair, seen from cameras at azimuth 0, +-30, +-45 (elevation 0); with
  --style S, of the first --identities planned identities whose hair is S.
scalp: skin seen between hair strands above the brows, its luminance over the face skin's
  and the hair's, by hair colour (docs/realism.md, "The scalp under the hair").
hats: hair under a beanie or cap, groomed without and with the hat: strands, share of hair points
  beyond the hat's cut plane (through its crown), groom seconds.
judge: mediapipe 0.10.21 (the fit extra; benchmarks/mediapipe_judge.py, in a subprocess) on the frames
  whose camera azimuth is within --max-azimuth, composited over mid grey: face-detection
  rate, face-mesh rate, and the error of its points (shifted by +0.5 px to synth's pixel
  convention) against the frame's ``landmarks_2d``, in units of the inter-ocular distance
  (outer eye corners, ibug 36-45): 68-point NME with and without the jaw, per region and by
  azimuth (its mesh mapped to ibug68, benchmarks/realism/judge.py), the issue's direct 7-point
  error (eye corners, nose tip, mouth corners) and mediapipe against itself on the mirrored
  image. --detections caches mediapipe's output.
mapping: the judge's mediapipe -> ibug68 mapping for each ridge --relax (or convex): its error on
  held-out model samples and, given a dataset and the judge's cached detections, on those frames.
timing: Cycles seconds per frame (the worker's frame events).
fringe: datasets against a reference of the same plan rendered with more samples: RMS error of
  the composite over grey and of the alpha on the reference's fringe pixels (0.02 < alpha <
  0.98), and of the whole composite (median over frames).
plot-skin OUT --inputs A.json B.json --labels before after: ITA histogram and L*-b* plot.
sheet OUT DATASET ...: the most frontal frame of the first identities, one row per dataset.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import assets, eyes, frames, judge, skin
from .common import CATS, _png, planned_options


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.realism", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = planned_options(sub.add_parser("skin"), 200)
    p.add_argument("--frames", nargs="*", default=[])
    p = sub.add_parser("framing")
    p.add_argument("datasets", nargs="+")
    p = sub.add_parser("body-end")
    p.add_argument("datasets", nargs="+")
    planned_options(sub.add_parser("hats"), 3, 256)
    p = planned_options(sub.add_parser("shoulders"), 40)
    p.add_argument("--garments", nargs="+", default=["tshirt_crew", "tank_top", "jacket_blazer", "coat"])
    p.add_argument("--hair", nargs="*", default=["long_straight", "long_curly", "braids", "ponytail", "medium_wavy"])
    p.add_argument("--hair-identities", type=int, default=6)
    p = sub.add_parser("scalp")
    p.add_argument("dataset")
    planned_options(sub.add_parser("hair-mix"), 10000)
    p = planned_options(sub.add_parser("hair"), 12)
    p.add_argument("--style", default=None, help="only identities planned with this hair style")
    planned_options(sub.add_parser("drape"), 4, 256)
    p = planned_options(sub.add_parser("beard"), 8, 256)
    p.add_argument("--reach", type=float, default=0.3)
    p = sub.add_parser("judge")
    p.add_argument("dataset")
    p.add_argument("--mp-python", default=sys.executable, help="a Python with mediapipe==0.10.21 (default: this one)")
    p.add_argument("--max-azimuth", type=float, default=45.0)
    p.add_argument("--detections", help="mediapipe's JSON: read it if it exists (no mediapipe run), else write it")
    p = sub.add_parser("jaw")
    p.add_argument("dataset")
    p.add_argument("--detections", help="mediapipe's JSON written by judge --detections")
    p.add_argument("--max-azimuth", type=float, default=45.0)
    planned_options(sub.add_parser("eyes"), 200)
    p = sub.add_parser("mapping")
    p.add_argument("--relax", nargs="+", default=["convex", "1e-2", "3e-3", "1e-3", "3e-4", "1e-4"])
    p.add_argument("--dataset")
    p.add_argument("--detections")
    p = sub.add_parser("timing")
    p.add_argument("datasets", nargs="+")
    p = sub.add_parser("fringe")
    p.add_argument("reference")
    p.add_argument("datasets", nargs="+")
    p = sub.add_parser("plot-skin")
    p.add_argument("out")
    p.add_argument("--inputs", nargs="+", required=True, help="JSON files written by 'skin --json'")
    p.add_argument("--labels", nargs="+", required=True)
    p = sub.add_parser("sheet")
    p.add_argument("out")
    p.add_argument("datasets", nargs="+")
    p.add_argument("--identities", type=int, default=8)
    p.add_argument("--columns", type=int, default=0, help="tiles per row (0: one row per dataset)")
    for q in sub.choices.values():
        q.add_argument("--json", help="also write the figures to this JSON file")
    args = ap.parse_args(argv)

    commands = {
        "skin": skin.skin, "plot-skin": skin.plot_skin,
        "framing": frames.framing, "body-end": frames.body_end, "timing": frames.timing, "fringe": frames.fringe,
        "sheet": frames.sheet, "scalp": frames.scalp,
        "hats": assets.hats, "hair": assets.hair, "hair-mix": assets.hair_mix, "shoulders": assets.shoulders, "drape": assets.drape_table,
        "beard": assets.beard_table,
        "eyes": eyes.eyes,
        "judge": lambda a: judge.judge(a, _png, CATS), "jaw": judge.jaw_table, "mapping": judge.mapping_table,
    }
    res = commands[args.cmd](args)
    if args.json:
        Path(args.json).write_text(json.dumps(res))


if __name__ == "__main__":
    main()
