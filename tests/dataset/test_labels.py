"""Landmark visibility from the rendered depth and alpha (synth.dataset.labels)."""

from __future__ import annotations

import numpy as np

from synth.dataset.labels import visibility


def scene():
    """6 x 8 pixels: a surface at z = 1 in columns 0-1, a step back to z = 1.5 in columns 2-3,
    background (alpha 0, depth 0) in columns 4-7."""
    depth = np.zeros((6, 8))
    depth[:, :2] = 1.0
    depth[:, 2:4] = 1.5
    alpha = (depth > 0).astype(float)
    return depth, alpha


def test_cases():
    depth, alpha = scene()
    uv = np.array([[0.5, 0.5], [0.5, 2.5], [0.5, 3.5], [5.5, 1.5], [8.0, 1.0], [-0.1, 1.0], [0.5, 4.5],
                   [2.5, 1.5], [3.5, 1.5], [3.5, 5.99]])
    z = np.array([1.0, 1.009, 1.02, 1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.5])
    vis = visibility(uv, z, depth, alpha)
    # on the surface; within 1 % of z; 2 cm behind it (occluded); over background; outside (u = W);
    # outside (u < 0); behind the camera; at the step, matched by the neighbouring column;
    # two columns from the step (no match); on the far surface in the last row
    assert vis.tolist() == [True, True, False, False, False, False, False, True, False, True]
    assert visibility(uv[7:8], z[7:8], depth, alpha, neighbourhood=0).tolist() == [False]


def test_tolerances():
    depth, alpha = scene()
    uv = np.array([[0.5, 0.5]] * 4)
    z = np.array([1.0035, 1.0045, 1.0, 1.0])
    depth_near = depth.copy()
    assert visibility(uv[:2], z[:2], depth_near, alpha, rel_tol=0.0).tolist() == [True, False]  # abs 4 mm
    depth_nan = depth.copy()
    depth_nan[:2, :2] = np.nan  # no finite depth around the pixel: not visible
    assert visibility(uv[2:3], z[2:3], depth_nan, alpha).tolist() == [False]
    alpha_half = alpha.copy()
    alpha_half[0, 0] = 0.5  # coverage must exceed one half at the landmark's own pixel
    assert visibility(uv[3:4], z[3:4], depth, alpha_half).tolist() == [False]
