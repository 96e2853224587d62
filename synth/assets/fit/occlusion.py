"""Strands in front of the face: points of hair that lie between a camera and the inner face.

Penetration into the head is handled by the strand push-out (``strands.push_out_strands``);
this measures the other failure: strands that hang in front of the eyes, nose, mouth or
cheeks, where no hairstyle of the catalogue should put them (a fringe over the forehead is
fine, so the forehead is not part of the inner face).

A strand point ``p`` occludes the inner face from a camera at ``c`` when the ray from ``c``
through ``p`` meets an inner-face triangle beyond ``p`` (ray parameter > 1 + eps: the point is
in front of the surface, not inside or behind it). Only the inner-face triangles are tested
(the other parts of the head are not in front of the face from the views this is meant for,
within about 60 degrees of frontal), with brute-force ray casting
(:func:`synth.geometry.raycast.first_hits`) on the points whose direction from the camera
falls inside the cone around the face.
"""

from __future__ import annotations

import numpy as np

from synth.geometry.raycast import first_hits

#: ibug68 brow points: the inner face lies below the highest of them
BROWS = tuple(range(17, 27))


def inner_face_triangles(data, vertices: np.ndarray, landmarks68: np.ndarray | None = None,
                         centre_only: bool = False) -> np.ndarray:
    """Triangles of the model's ``face`` region (all corners in it) below the brows (every corner
    lower than the highest ibug68 brow point, world Z up); with ``centre_only``, only those
    between the outer eye corners (ibug 36 and 45, along X): the eyes, nose and mouth."""
    face = np.zeros(len(vertices), bool)
    face[np.asarray(data.regions["face"], np.int64)] = True
    tri = np.asarray(data.triangles, np.int64)
    keep = face[tri].all(axis=1)
    if landmarks68 is not None:
        top = float(np.asarray(landmarks68)[list(BROWS), 2].max())
        keep &= (np.asarray(vertices)[tri][..., 2] < top).all(axis=1)
        if centre_only:
            lo, hi = sorted((float(landmarks68[36][0]), float(landmarks68[45][0])))
            x = np.asarray(vertices)[tri][..., 0]
            keep &= ((x > lo) & (x < hi)).all(axis=1)
    return tri[keep]


def occluding_points(strands: np.ndarray, camera_centre, vertices: np.ndarray, face_triangles: np.ndarray,
                     eps: float = 1e-6) -> np.ndarray:
    """(N, P) bool: strand points between the camera and the face triangles (see the module doc)."""
    P = np.asarray(strands, np.float64)
    flat = P.reshape(-1, 3)
    c = np.asarray(camera_centre, np.float64)
    V = np.asarray(vertices, np.float64)
    out = np.zeros(len(flat), bool)
    if len(face_triangles) == 0 or len(flat) == 0:
        return out.reshape(P.shape[:-1])
    # cone around the face seen from the camera: cheap rejection before the ray casts
    fv = V[np.unique(face_triangles)]
    axis = fv.mean(axis=0) - c
    axis /= np.linalg.norm(axis)
    u_face = (fv - c) / np.linalg.norm(fv - c, axis=1, keepdims=True)
    cos_cone = float((u_face @ axis).min())
    d = flat - c
    dist = np.linalg.norm(d, axis=1)
    cand = np.nonzero((d @ axis) > cos_cone * dist)[0]
    if cand.size:
        tri, _, t = first_hits(np.broadcast_to(c, (cand.size, 3)), d[cand], V, face_triangles, t_min=1.0 + eps)
        out[cand] = tri >= 0
    return out.reshape(P.shape[:-1])


def strands_in_front_of_face(strands: np.ndarray, camera_centres, vertices: np.ndarray,
                             face_triangles: np.ndarray) -> dict:
    """Per camera: strands with any point in front of the inner face, and their points.
    Returns ``{"strands": (C,) int, "points": (C,) int, "strand_fraction": (C,) float}``."""
    C = np.atleast_2d(np.asarray(camera_centres, np.float64))
    n_str = len(strands)
    s, p = np.zeros(len(C), np.int64), np.zeros(len(C), np.int64)
    for k, c in enumerate(C):
        occ = occluding_points(strands, c, vertices, face_triangles)
        s[k], p[k] = int(occ.any(axis=1).sum()), int(occ.sum())
    return {"strands": s, "points": p, "strand_fraction": s / max(n_str, 1)}
