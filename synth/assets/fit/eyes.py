"""Polar coordinates on the eyeballs for the iris shader (numpy; the rig is
``blender_scripts/assets/iris.py``).

For each eyeball, with its centre fitted to the rest-pose sclera and its forward axis from
the centre to the iris centroid, a vertex gets ``(rho cos phi, rho sin phi, rho)``: ``rho``
is the angle from the forward axis divided by the limbus angle (0 at the pupil centre, 1 at
the limbus) and ``phi`` the angle around the axis (mirrored on the left eye so that nasal
and temporal sides match). Vertices off the eyeballs get 9 (far outside the iris).
"""

from __future__ import annotations

import numpy as np


def _sphere_centre(P):
    """Algebraic least-squares sphere centre, uncentred. ``synth.model.meshutil.fit_sphere``
    (centred first, better conditioned) differs by up to 1e-4 in the coordinates, which would
    change every rendered iris; this one is kept so the data stay as they are."""
    A = np.c_[2 * P, np.ones(len(P))]
    b = (P ** 2).sum(1)
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    return x[:3]


def _eye_frame(data, V: np.ndarray, side: str):
    """(eye vertex indices, centre, forward, u, w, limbus angle, sclera radius) of one eye, or None."""
    eye = data.regions.get(f"eye_{side}")
    sclera = data.regions.get(f"sclera_{side}", eye)
    iris = data.regions.get(f"iris_{side}")
    if eye is None or sclera is None:
        return None
    eye = np.asarray(eye, np.int64)
    sc = V[np.asarray(sclera, np.int64)]
    c = _sphere_centre(sc)
    if iris is not None:
        f = V[np.asarray(iris, np.int64)].mean(0) - c
    else:
        f = np.array([0.0, -1.0, 0.0])
    f /= np.linalg.norm(f)
    u = np.cross(f, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    w = np.cross(u, f)
    if iris is not None:
        qi = V[np.asarray(iris, np.int64)] - c
        qi /= np.linalg.norm(qi, axis=1, keepdims=True)
        lim = float(np.arccos(np.clip(qi @ f, -1, 1)).max())
    else:
        lim = 0.5
    return eye, c, f, u, w, lim, float(np.linalg.norm(sc - c, axis=1).mean())


def eye_coordinates(data, rest: np.ndarray) -> tuple[np.ndarray, dict]:
    """(V, 3) coordinates (see the module docstring) and, per eye ("l", "r"), the fitted
    centre, forward axis and limbus angle (radians) for the frame JSON."""
    V = np.asarray(rest, np.float64)
    out = np.full((len(V), 3), 9.0)
    info = {}
    for side, s in (("l", 1.0), ("r", -1.0)):
        fr = _eye_frame(data, V, side)
        if fr is None:
            continue
        eye, c, f, u, w, lim, _ = fr
        q = V[eye] - c
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        theta = np.arccos(np.clip(q @ f, -1, 1))
        rho = theta / lim
        phi = np.arctan2(q @ w, s * (q @ u))
        out[eye] = np.c_[rho * np.cos(phi), rho * np.sin(phi), rho]
        info[side] = {"centre": c.round(6).tolist(), "forward": f.round(5).tolist(), "limbus_rad": round(lim, 5)}
    return out, info


#: attribute names of :func:`eye_frames`, in order
FRAME_ATTRIBUTES = ("eye_centre", "eye_fwd", "eye_u", "eye_w", "eye_plane")


def eye_frames(data, vertices: np.ndarray) -> dict[str, np.ndarray]:
    """Per-vertex frame of the eye a vertex belongs to, for the cornea's refraction in the iris
    shader (``blender_scripts/assets/iris.py``), from the *current* vertices (so it turns with
    the gaze): ``eye_centre``, ``eye_fwd`` (optical axis), ``eye_u`` / ``eye_w`` (the iris
    plane's axes; ``eye_u`` mirrored on the right eye as ``phi`` is in :func:`eye_coordinates`)
    and ``eye_plane`` = (limbus radius, distance from the centre to the iris plane, 0) in metres:
    the iris lies in the limbus plane, behind the corneal dome that the mesh's iris region forms.
    Vertices off the eyes get zeros."""
    V = np.asarray(vertices, np.float64)
    out = {k: np.zeros((len(V), 3)) for k in FRAME_ATTRIBUTES}
    for side, s in (("l", 1.0), ("r", -1.0)):
        fr = _eye_frame(data, V, side)
        if fr is None:
            continue
        eye, c, f, u, w, lim, R = fr
        for k, v in zip(FRAME_ATTRIBUTES, (c, f, s * u, w, (R * np.sin(lim), R * np.cos(lim), 0.0))):
            out[k][eye] = v
    return out


#: ibug68 indices of the medial canthi (en; 39: the subject's right eye, 42: the left)
MEDIAL_CANTHI = (39, 42)


def medial_canthi(data, vertices: np.ndarray) -> np.ndarray:
    """(V, 3) per-vertex position of the medial canthus (ibug68 point 39 / 42 on the *current*
    vertices, so it follows the lids) of the eye a vertex belongs to, projected along its
    direction from the eye's centre onto the eyeball's sphere (the canthus stands up to 3 mm in
    front of the eyeball, ``synth.model.eyelids.LACRIMAL_GAP_M``; the caruncle lies on the globe
    behind it), for the caruncle in the iris shader (``blender_scripts/assets/iris.py``). Each
    eye takes the canthus nearer its centre. Vertices off the eyes, and every vertex of a model
    without ibug68 landmarks, get zeros: metres away from any eye, so the shader paints no
    caruncle there."""
    from synth.model.meshutil import barycentric_points

    V = np.asarray(vertices, np.float64)
    out = np.zeros((len(V), 3))
    lm = data.landmarks.get("ibug68")
    if lm is None:
        return out
    tri, bary = lm
    idx = list(MEDIAL_CANTHI)
    P = barycentric_points(V, np.asarray(data.triangles), np.asarray(tri)[idx], np.asarray(bary)[idx])
    for side in ("l", "r"):
        fr = _eye_frame(data, V, side)
        if fr is None:
            continue
        eye, c, *_, radius = fr
        q = P[int(np.argmin(np.linalg.norm(P - c, axis=1)))] - c
        out[eye] = c + q * (radius / np.linalg.norm(q))
    return out


#: angular sectors around the eye axis in which the lid margin vertex is picked
MARGIN_SECTORS = 36


def lid_margin(data, vertices: np.ndarray, lid: str = "lower") -> np.ndarray:
    """(V,) float mask, 1 on the margin of each eye's ``lid`` ("lower"/"upper"): in every angular
    sector around the eye's axis, the lid vertex closest to the axis (the edge of the opening).
    The skin-detail rig puts the wet tear meniscus there."""
    V = np.asarray(vertices, np.float64)
    out = np.zeros(len(V))
    for side in ("l", "r"):
        fr = _eye_frame(data, V, side)
        ids = data.regions.get(f"eyelid_{side}_{lid}")
        if fr is None or ids is None:
            continue
        ids = np.asarray(ids, np.int64)
        _, c, f, u, w, _, _ = fr
        q = V[ids] - c
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        theta = np.arccos(np.clip(q @ f, -1, 1))
        sector = np.floor((np.arctan2(q @ w, q @ u) + np.pi) / (2 * np.pi) * MARGIN_SECTORS).astype(np.int64)
        order = np.lexsort((theta, sector))
        first = np.r_[True, sector[order][1:] != sector[order][:-1]]
        out[ids[order[first]]] = 1.0
    return out
