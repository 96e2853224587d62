"""Test meshes with known trouble spots."""

from __future__ import annotations

import numpy as np
import trimesh


def bumpy_sphere_with_degenerates(seed: int = 0):
    """An icosphere with noisy radii, plus a zero-area triangle with a repeated corner, a
    zero-area triangle with collinear corners, a vertex used only by those, and an isolated
    vertex (the last one)."""
    rng = np.random.default_rng(seed)
    s = trimesh.creation.icosphere(subdivisions=2)
    v = s.vertices * (1.0 + 0.15 * rng.random(len(s.vertices)))[:, None]
    f = s.faces
    n = len(v)
    extra = np.array([[3.0, 0.0, 0.0], [4.0, 0.0, 0.0], [5.0, 0.0, 0.0], [9.0, 9.0, 9.0]])
    v = np.concatenate([v, extra])
    f = np.concatenate([f, [[0, 1, 1], [n, n + 1, n + 2]]])
    return v, f
