"""A small, valid head model for tests: an ellipsoid head (~650 vertices) with 8 identity
and 6 ARKit-named expression components, the 5 required joints, every required region,
ibug68 landmarks on the front of the face (eyes where eyes belong) and a 2-component GMM
prior. Deterministic; passes ``validate_model``. Reuse it anywhere a model is needed. Also
:func:`random_model`, a smaller random one for the format and evaluation tests.

    from tests.support.toy_model import make_toy_model, random_model, write_toy_model
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.model.importers.derived import derived_regions
from synth.model.format import REQUIRED_REGIONS, HeadModelData, validate_model, write_model

EXPRESSION_NAMES = ["jawOpen", "mouthSmileLeft", "mouthSmileRight", "browInnerUp", "eyeBlinkLeft",
                    "eyeBlinkRight"]
JOINTS = ["neck", "head", "jaw", "eye_l", "eye_r"]
PARENTS = [-1, 0, 1, 1, 1]
AXES = np.array([0.075, 0.095, 0.115])  # half width (x), depth (y), height (z), metres


def _ellipsoid(n_lat: int, n_lon: int) -> tuple[np.ndarray, np.ndarray]:
    """UV-sphere scaled to AXES: poles + rings; the face (-Y) is at longitude 0."""
    verts = [[0.0, 0.0, 1.0]]
    for i in range(1, n_lat):
        th = np.pi * i / n_lat  # from the top
        for j in range(n_lon):
            ph = 2.0 * np.pi * j / n_lon
            verts.append([np.sin(th) * np.sin(ph), -np.sin(th) * np.cos(ph), np.cos(th)])
    verts.append([0.0, 0.0, -1.0])
    v = np.array(verts) * AXES
    tris = []
    ring = lambda i, j: 1 + (i - 1) * n_lon + (j % n_lon)  # noqa: E731
    for j in range(n_lon):
        tris.append([0, ring(1, j), ring(1, j + 1)])
    for i in range(1, n_lat - 1):
        for j in range(n_lon):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            tris += [[a, c, b], [b, c, d]]
    last = len(verts) - 1
    for j in range(n_lon):
        tris.append([last, ring(n_lat - 1, j + 1), ring(n_lat - 1, j)])
    return v.astype(np.float64), np.array(tris, np.int64)


def _ibug68_layout() -> np.ndarray:
    """(68, 2) frontal (x, z) positions in metres, subject's left = +x, roughly anthropometric."""
    pts = []
    for t in np.linspace(-1, 1, 17):  # 0-16 jaw line, from the subject's right
        pts.append([0.065 * t, -0.035 - 0.05 * (1 - t * t) ** 0.7])
    for t in np.linspace(-1, -0.2, 5):  # 17-21 right brow
        pts.append([0.055 * t, 0.045 + 0.008 * (1 - (t + 0.6) ** 2 * 4)])
    for t in np.linspace(0.2, 1, 5):  # 22-26 left brow
        pts.append([0.055 * t, 0.045 + 0.008 * (1 - (t - 0.6) ** 2 * 4)])
    for z in np.linspace(0.03, -0.005, 4):  # 27-30 nose bridge
        pts.append([0.0, z])
    for x in np.linspace(-0.015, 0.015, 5):  # 31-35 nostrils
        pts.append([x, -0.012])
    for cx in (-0.032, 0.032):  # 36-41 right eye, 42-47 left eye (outer corner first on each side)
        for k, t in enumerate([-1, -0.35, 0.35, 1, 0.35, -0.35]):
            dz = 0.0 if k in (0, 3) else (0.005 if k in (1, 2) else -0.005)
            pts.append([cx + 0.013 * t, 0.028 + dz])
    for t in np.linspace(-1, 1, 7):  # 48-54 upper outer lip
        pts.append([0.025 * t, -0.035 + 0.006 * (1 - t * t)])
    for t in np.linspace(1, -1, 7)[1:-1]:  # 55-59 lower outer lip
        pts.append([0.025 * t, -0.035 - 0.009 * (1 - t * t)])
    for t in np.linspace(-1, 1, 5)[:-1] * 0.7:  # 60-63 inner lip top
        pts.append([0.02 * t, -0.035 + 0.002])
    for t in np.linspace(1, -1, 5)[:-1] * 0.7:  # 64-67 inner lip bottom
        pts.append([0.02 * t, -0.035 - 0.002])
    return np.array(pts[:68])


def make_toy_model(name: str = "toy-ellipsoid", identity_dims: int = 8) -> HeadModelData:
    rng = np.random.default_rng(12345)
    v, tris = _ellipsoid(22, 30)
    V = v.shape[0]
    n = v / AXES  # unit sphere directions ~ normals
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    front = y < -0.2

    # identity: smooth displacements along the normal (low-order polynomials), unit max
    polys = [x * x, y * y, z, z * z, x * z, y * z, z ** 3, x * x * z, y, x * x * y]
    k = 2
    while len(polys) < identity_dims:  # more smooth monomials for larger identity spaces
        polys += [x ** k * z, y ** k * z, z ** (k + 2), x ** (k + 1) * y]
        k += 1
    polys = polys[:identity_dims]
    id_basis = np.stack([p[:, None] * n for p in polys]).astype(np.float32)
    id_basis /= np.abs(id_basis).max(axis=(1, 2), keepdims=True)
    id_scale = np.linspace(0.008, 0.002, identity_dims).astype(np.float32)

    # joints (rest) and how they follow identity
    joint_rest = np.array([[0.0, 0.02, -0.13], [0.0, 0.01, -0.06], [0.0, -0.01, -0.02],
                           [0.032, -0.07, 0.028], [-0.032, -0.07, 0.028]], np.float32)
    joint_id = (rng.normal(0.0, 0.2, (identity_dims, len(JOINTS), 3))).astype(np.float32)

    # expressions: local displacements (metres per unit of code, scale 1)
    chin = np.clip(-(z + 0.3) / 0.5, 0, 1) * front
    brow = np.exp(-((x / 0.6) ** 2 + ((z - 0.4) / 0.15) ** 2)) * front
    eye_l = np.exp(-(((x - 0.42) / 0.15) ** 2 + ((z - 0.24) / 0.1) ** 2)) * front
    eye_r = np.exp(-(((x + 0.42) / 0.15) ** 2 + ((z - 0.24) / 0.1) ** 2)) * front
    corner_l = np.exp(-(((x - 0.3) / 0.15) ** 2 + ((z + 0.3) / 0.12) ** 2)) * front
    corner_r = np.exp(-(((x + 0.3) / 0.15) ** 2 + ((z + 0.3) / 0.12) ** 2)) * front
    up, out = np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
    ex = np.stack([
        -0.02 * chin[:, None] * up + 0.005 * chin[:, None] * np.array([0, 1.0, 0]),  # jawOpen
        0.006 * corner_l[:, None] * (up + out),  # mouthSmileLeft
        0.006 * corner_r[:, None] * (up - out),  # mouthSmileRight
        0.006 * brow[:, None] * up,  # browInnerUp
        -0.006 * eye_l[:, None] * up,  # eyeBlinkLeft
        -0.006 * eye_r[:, None] * up,  # eyeBlinkRight
    ]).astype(np.float32)

    # skinning: neck at the bottom, jaw below the mouth line in front, eyes near the eyes, rest head
    w = np.zeros((V, len(JOINTS)))
    w[:, 1] = 1.0
    neck = np.clip((-z - 0.7) / 0.3, 0, 1)
    w[:, 0], w[:, 1] = neck, 1 - neck
    jaw = np.clip(chin * 2.0, 0, 1) * (1 - neck)
    w[:, 2] = jaw
    w[:, 1] -= jaw
    for j, e in ((3, eye_l), (4, eye_r)):
        s = np.where(e > 0.6, 1.0, 0.0) * w[:, 1]
        w[:, j] = s
        w[:, 1] -= s
    w = np.clip(w, 0, None)
    w /= w.sum(1, keepdims=True)

    # regions
    idx = np.arange(V)
    regions = {
        "face": idx[front & (z > -0.8) & (z < 0.6)], "scalp": idx[(z > 0.3) & ~front],
        "ears": idx[np.abs(x) > 0.9], "eyes": idx[(eye_l > 0.6) | (eye_r > 0.6)],
        "teeth": idx[(mouth_t := np.exp(-((x / 0.2) ** 2 + ((z + 0.3) / 0.06) ** 2)) * front) > 0.5],
        "mouth_interior": idx[mouth_t > 0.3], "eyelash_lines": idx[(eye_l > 0.3) | (eye_r > 0.3)],
        "neck": idx[z < -0.85], "brow": idx[brow > 0.5], "lips": idx[(mouth_t > 0.3) & (mouth_t <= 0.5)],
        "beard": idx[front & (z < -0.4) & (z > -0.85)],
    }
    regions["eye_l"], regions["eye_r"] = idx[eye_l > 0.6], idx[eye_r > 0.6]
    regions["iris"] = regions["sclera"] = regions["eyes"]  # one vertex per eye: coarse
    for s, e in (("l", eye_l), ("r", eye_r)):  # the toy's lid lines: a ring around each eye, split at its centre
        ring = idx[(e > 0.15) & (e <= 0.6)]
        regions[f"eyelid_{s}_upper"] = ring[z[ring] >= np.median(z[ring])]
        regions[f"eyelid_{s}_lower"] = ring[z[ring] < np.median(z[ring])]
    for r in REQUIRED_REGIONS:
        if regions[r].size == 0:
            regions[r] = idx[:3]
    regions = {k: np.asarray(val, np.int32) for k, val in regions.items()}

    # ibug68: each landmark sits on the front vertex nearest its frontal layout position
    lay = _ibug68_layout()
    cand = idx[front]
    d = (v[cand][None, :, 0] - lay[:, None, 0]) ** 2 + (v[cand][None, :, 2] - lay[:, None, 1]) ** 2
    lm_v = cand[np.argmin(d, axis=1)]
    tri_of = np.full(V, -1)
    for t_i, t in enumerate(tris):
        for c in t:
            if tri_of[c] < 0:
                tri_of[c] = t_i
    lm_tri = tri_of[lm_v]
    bary = np.zeros((68, 3), np.float32)
    for k in range(68):
        bary[k, list(tris[lm_tri[k]]).index(lm_v[k])] = 1.0

    # the regions the asset classes read, derived as the importers derive them
    regions = {k: np.asarray(val, np.int32) for k, val in derived_regions(v, regions, v[lm_v], joint_rest[0, 2]).items()}

    # prior: two components, correlated, in code units
    D = identity_dims
    A = rng.normal(0, 0.3, (D, D))
    c1 = np.eye(D) * 0.8 + 0.1 * (A @ A.T) / D
    B = rng.normal(0, 0.3, (D, D))
    c2 = np.eye(D) * 0.6 + 0.1 * (B @ B.T) / D
    means = np.stack([np.full(D, 0.4), np.full(D, -0.4)]) * np.array([1, -1] * (D // 2) + [1] * (D % 2))

    m = HeadModelData(
        name=name, template=v.astype(np.float32), triangles=tris.astype(np.int32),
        identity_basis=id_basis, identity_scale=id_scale, expression_basis=ex,
        expression_scale=np.ones(len(EXPRESSION_NAMES), np.float32), expression_names=list(EXPRESSION_NAMES),
        joint_names=list(JOINTS), joint_parents=np.array(PARENTS, np.int32), joint_rest=joint_rest,
        joint_identity_basis=joint_id * 0.01, skin_weights=w.astype(np.float32), regions=regions,
        landmarks={"ibug68": (lm_tri.astype(np.int32), bary)}, prior_weights=np.array([0.6, 0.4]),
        prior_means=means, prior_covs=np.stack([c1, c2]), license="CC0-1.0 (synthetic test model)",
        provenance={"source": "tests/support/toy_model.py"},
    )
    validate_model(m)
    return m


def write_toy_model(path: str | Path, **kw) -> Path:
    return write_model(make_toy_model(**kw), path)


def random_model(V=300, Ki=6, Ke=5, seed=0) -> HeadModelData:
    """A small random model (strip of triangles, random bases and weights, 68 random
    landmarks, 2-component prior): fast, and independent of any data source."""
    rng = np.random.default_rng(seed)
    template = rng.normal(size=(V, 3)).astype(np.float32) * 0.1
    T = V - 2
    tris = np.stack([np.arange(T), np.arange(T) + 1, np.arange(T) + 2], 1).astype(np.int32)
    ib = rng.normal(size=(Ki, V, 3))
    ib /= np.linalg.norm(ib.reshape(Ki, -1), axis=1)[:, None, None]
    eb = rng.normal(size=(Ke, V, 3)) * 0.01
    w = rng.uniform(size=(V, 5)) ** 4
    w /= w.sum(1, keepdims=True)
    w[:20] = 0
    w[:20, 3] = 1.0  # fully rigid to eye_l
    jr = np.array([[0, 0, -0.1], [0, 0, 0], [0, -0.02, -0.05], [0.03, -0.08, 0.03], [-0.03, -0.08, 0.03]], np.float32)
    lm_tri = rng.integers(0, T, size=68).astype(np.int32)
    bary = rng.dirichlet([1, 1, 1], size=68).astype(np.float32)
    return HeadModelData(
        name="random", template=template, triangles=tris,
        identity_basis=ib.astype(np.float32), identity_scale=np.linspace(0.02, 0.005, Ki).astype(np.float32),
        expression_basis=eb.astype(np.float32), expression_scale=np.ones(Ke, np.float32),
        expression_names=[f"e{i}" for i in range(Ke)], joint_names=list(JOINTS),
        joint_parents=np.array(PARENTS, np.int32), joint_rest=jr,
        joint_identity_basis=(rng.normal(size=(Ki, 5, 3)) * 0.1).astype(np.float32),
        skin_weights=w.astype(np.float32),
        regions={"face": np.arange(50, 100, dtype=np.int32), "eyes": np.arange(20, dtype=np.int32)},
        landmarks={"ibug68": (lm_tri, bary)},
        prior_weights=np.array([0.3, 0.7]), prior_means=rng.normal(size=(2, Ki)) * 0.3,
        prior_covs=np.stack([np.eye(Ki) * 0.5, np.eye(Ki) * 0.8]),
        license="test licence", provenance={"source": "random"},
    )
