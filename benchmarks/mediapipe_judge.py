"""Run mediapipe's face detector and face mesh on PNGs; write one JSON (no synth imports).

Runs with mediapipe==0.10.21 (the fit extra, in the project's venv; numpy and pillow suffice
besides, so any environment with those three does)::

    .venv/bin/python benchmarks/mediapipe_judge.py PNG_DIR OUT.json

``python -m benchmarks.realism judge`` writes the PNGs, calls this script as a subprocess and reads
the JSON: per image, ``detected`` (face detection, short-range model, confidence >= 0.5),
``score``, ``mesh`` (the 478 refined face-mesh points in pixels, or null) and ``mesh_mirrored``
(the same on the left-right mirrored image, in the mirrored image's pixels, or null: the judge's
self-consistency) and ``presence`` ([low, high]: the bracket of the face landmark model's face
presence score on the grid ``PRESENCE_GRID``; the face mesh is found when that score reaches its
threshold, which the legacy solution sets from ``min_tracking_confidence``, 0.5 by default, also in
static mode; so ``mesh`` is null exactly when the score is below 0.5). Pixels are mediapipe's
``x * W``, ``y * H``: pixel centres at integers (the judge adds 0.5 px to reach synth's
convention, benchmarks/realism/judge.py).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


#: thresholds of the face presence score tried; a frame's score lies between the highest one at
#: which the face mesh is still found and the next one (0 and 1 at the ends)
PRESENCE_GRID = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995, 0.999)


def presence_brackets(mp, images: dict) -> dict:
    """{name: [low, high]}: the face presence score of each image bracketed on PRESENCE_GRID."""
    found = {k: [] for k in images}
    for t in PRESENCE_GRID:
        with mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=1, refine_landmarks=True,
                                            min_detection_confidence=0.5, min_tracking_confidence=t) as fm:
            for k, img in images.items():
                found[k].append(fm.process(img).multi_face_landmarks is not None)
    out = {}
    for k, f in found.items():
        out[k] = bracket(f)
        if out[k] is None:  # cannot happen for a fixed score; say so and keep going
            print(f"{k}: the face mesh is not monotone in its presence threshold ({f}); presence left null",
                  file=sys.stderr)
    return out


def bracket(found: list) -> list | None:
    """[low, high] of the presence score from whether the mesh was found at each PRESENCE_GRID
    threshold (found at the i lowest: low = the i-th, high = the next; 0 and 1 at the ends), or
    None if the found ones are not the lowest thresholds."""
    i = sum(bool(x) for x in found)
    if len(found) != len(PRESENCE_GRID) or list(map(bool, found)) != [True] * i + [False] * (len(found) - i):
        return None
    grid = (0.0,) + PRESENCE_GRID + (1.0,)
    return [grid[i], grid[i + 1]]


def main(png_dir: str, out: str) -> None:
    import mediapipe as mp
    import numpy as np
    from PIL import Image

    res, images = {}, {}
    with mp.solutions.face_detection.FaceDetection(model_selection=0, min_detection_confidence=0.5) as fd, \
            mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=1, refine_landmarks=True,
                                            min_detection_confidence=0.5) as fm:
        for p in sorted(Path(png_dir).glob("*.png")):
            img = images[p.stem] = np.ascontiguousarray(np.asarray(Image.open(p).convert("RGB")))
            H, W = img.shape[:2]
            det = fd.process(img).detections
            mesh, mirrored = (fm.process(np.ascontiguousarray(im)).multi_face_landmarks for im in (img, img[:, ::-1]))
            res[p.stem] = {"detected": bool(det), "score": float(det[0].score[0]) if det else 0.0,
                           "mesh": [[q.x * W, q.y * H] for q in mesh[0].landmark] if mesh else None,
                           "mesh_mirrored": [[q.x * W, q.y * H] for q in mirrored[0].landmark] if mirrored else None}
    for k, b in presence_brackets(mp, images).items():
        res[k]["presence"] = b
    Path(out).write_text(json.dumps({"mediapipe": mp.__version__, "images": res}))


if __name__ == "__main__":
    main(*sys.argv[1:3])
