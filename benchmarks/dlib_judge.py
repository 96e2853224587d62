"""Run dlib's face detector and face-recognition ResNet on images; write one JSON (no synth imports).

Runs with the judge extra (``dlib-bin`` and ``face_recognition_models``; numpy and pillow besides),
in any Python that has them, e.g. a throwaway venv, so the project's environment stays untouched::

    PY benchmarks/dlib_judge.py OUT.json IMAGE_OR_DIR [IMAGE_OR_DIR ...]

A directory stands for its ``*.png`` files. Per image: ``faces``, every face dlib's HOG frontal
detector finds (upsampled once, so faces down to about 40 px wide), largest first, each with
``box`` ([left, top, right, bottom] pixels), ``score`` (the detector's) and ``embedding`` (the
128-D descriptor of dlib_face_recognition_resnet_model_v1, aligned on the 5-point landmarks of
shape_predictor_5_face_landmarks, no jittering: deterministic). Two faces are the same person by
dlib's rule when the Euclidean distance of their embeddings is below 0.6 (99.38 % on LFW).
``python -m benchmarks.identity_diversity`` writes the PNGs, calls this script as a subprocess and
reads the JSON.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

UPSAMPLE = 1  #: detector pyramid upsamplings


def images_of(args: list[str]) -> list[Path]:
    out = []
    for a in args:
        p = Path(a)
        out.extend(sorted(p.glob("*.png")) if p.is_dir() else [p])
    return out


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print("usage: dlib_judge.py OUT.json IMAGE_OR_DIR [IMAGE_OR_DIR ...]", file=sys.stderr)
        return 2
    import importlib.util

    import dlib
    import numpy as np
    from PIL import Image

    # the weights' files, found without importing face_recognition_models (its __init__ needs
    # pkg_resources, i.e. setuptools, which an environment need not have)
    spec = importlib.util.find_spec("face_recognition_models")
    if spec is None or not spec.submodule_search_locations:
        print("face_recognition_models is not installed (pip install '.[judge]')", file=sys.stderr)
        return 2
    models = Path(list(spec.submodule_search_locations)[0]) / "models"
    detector = dlib.get_frontal_face_detector()
    shape = dlib.shape_predictor(str(models / "shape_predictor_5_face_landmarks.dat"))
    net = dlib.face_recognition_model_v1(str(models / "dlib_face_recognition_resnet_model_v1.dat"))
    out = {}
    for path in images_of(argv[1:]):
        img = np.ascontiguousarray(np.asarray(Image.open(path).convert("RGB")))
        dets, scores, _ = detector.run(img, UPSAMPLE, 0.0)
        faces = []
        for d, s in zip(dets, scores):
            emb = net.compute_face_descriptor(img, shape(img, d), 0)
            faces.append({"box": [d.left(), d.top(), d.right(), d.bottom()], "score": float(s),
                          "embedding": [float(x) for x in emb]})
        faces.sort(key=lambda f: -(f["box"][2] - f["box"][0]) * (f["box"][3] - f["box"][1]))
        out[path.name] = {"size": list(img.shape[1::-1]), "faces": faces}
    Path(argv[0]).write_text(json.dumps({"judge": f"dlib {dlib.__version__} face_recognition_model_v1",
                                         "threshold": 0.6, "images": out}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
