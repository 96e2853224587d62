"""scripts/mediapipe_correspondence.py: the mirror partners of mediapipe's points, found from the
detections on an image and on its mirror image (pure numpy/scipy; mediapipe is never needed)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def C():
    spec = importlib.util.spec_from_file_location("mediapipe_correspondence",
                                                  ROOT / "scripts" / "mediapipe_correspondence.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _symmetric_face(rng, n_pairs=200, n_mid=78):
    """(P, 2) points of a left-right symmetric face about x = 0, and its partner permutation."""
    # points on jittered grids (a face mesh's points are a few per cent of the face apart)
    gx, gy = np.meshgrid(np.linspace(-1.0, -0.1, 10), np.linspace(-1.0, 1.0, n_pairs // 10))
    left = np.stack([gx.ravel(), gy.ravel()], 1) + rng.uniform(-0.02, 0.02, (n_pairs, 2))
    mid = np.stack([np.zeros(n_mid), np.linspace(-1.0, 1.0, n_mid) + rng.uniform(-0.005, 0.005, n_mid)], 1)
    pts = np.concatenate([left, left * (-1.0, 1.0), mid])
    pair = np.concatenate([np.arange(n_pairs) + n_pairs, np.arange(n_pairs), 2 * n_pairs + np.arange(n_mid)])
    perm = rng.permutation(len(pts))  # mediapipe's numbering is not ordered by side
    inv = np.argsort(perm)
    return pts[perm], inv[pair[perm]]


def test_mirror_pairs_recovers_a_known_pairing_under_noise(C):
    rng = np.random.default_rng(3)
    face, pair = _symmetric_face(rng)
    assert np.all(pair[pair] == np.arange(len(pair)))
    F, W = 8, 300.0
    det, mirrored = [], []
    for f in range(F):
        s, t = rng.uniform(60, 90), rng.uniform(120, 180, 2)
        img = face * s + t
        # a detector's error: mostly a shift of the whole face, a little per point
        noisy = lambda p: p + rng.normal(0, 0.03 * s, 2) + rng.normal(0, 0.003 * s, p.shape)  # noqa: E731
        det.append(noisy(img))
        # on the mirrored image (x -> W - x) mediapipe's point j sits on the mirror of its partner
        m = np.stack([W - img[pair, 0], img[pair, 1]], 1)
        back = noisy(m)
        back[:, 0] = W - back[:, 0]  # mapped back
        mirrored.append(back)
    got = C.mirror_pairs(np.asarray(det), np.asarray(mirrored))
    assert np.array_equal(got, pair)
    assert np.all(got[got] == np.arange(len(got)))  # an involution: partners of partners
