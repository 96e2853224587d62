"""Run mediapipe's face detector and face mesh on PNGs; write one JSON (no synth imports).

Runs in its own environment (mediapipe==0.10.21 needs protobuf<5, so it is never installed in
the project's venv; numpy and pillow suffice besides)::

    python3.11 -m venv MPENV && MPENV/bin/pip install mediapipe==0.10.21 numpy pillow
    MPENV/bin/python benchmarks/mediapipe_judge.py PNG_DIR OUT.json

``benchmarks/realism.py judge`` writes the PNGs, calls this script as a subprocess and reads
the JSON: per image, ``detected`` (face detection, short-range model, confidence >= 0.5),
``score``, ``mesh`` (the 478 refined face-mesh points in pixels, or null) and ``mesh_mirrored``
(the same on the left-right mirrored image, in the mirrored image's pixels, or null: the judge's
self-consistency). Pixels are mediapipe's ``x * W``, ``y * H``: pixel centres at integers (the
judge adds 0.5 px to reach synth's convention, benchmarks/realism_judge.py).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def main(png_dir: str, out: str) -> None:
    import mediapipe as mp
    import numpy as np
    from PIL import Image

    res = {}
    with mp.solutions.face_detection.FaceDetection(model_selection=0, min_detection_confidence=0.5) as fd, \
            mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=1, refine_landmarks=True,
                                            min_detection_confidence=0.5) as fm:
        for p in sorted(Path(png_dir).glob("*.png")):
            img = np.ascontiguousarray(np.asarray(Image.open(p).convert("RGB")))
            H, W = img.shape[:2]
            det = fd.process(img).detections
            mesh, mirrored = (fm.process(np.ascontiguousarray(im)).multi_face_landmarks for im in (img, img[:, ::-1]))
            res[p.stem] = {"detected": bool(det), "score": float(det[0].score[0]) if det else 0.0,
                           "mesh": [[q.x * W, q.y * H] for q in mesh[0].landmark] if mesh else None,
                           "mesh_mirrored": [[q.x * W, q.y * H] for q in mirrored[0].landmark] if mirrored else None}
    Path(out).write_text(json.dumps({"mediapipe": mp.__version__, "images": res}))


if __name__ == "__main__":
    main(*sys.argv[1:3])
