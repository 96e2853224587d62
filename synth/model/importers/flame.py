"""Import a user's own FLAME 2020 / 2023 model (``generic_model.pkl``, ``flame2023.pkl``).

FLAME is licensed by the Max Planck Institute for Intelligent Systems for non-commercial
research; synth ships no FLAME data. The user passes their own download:

    import_flame(Path("generic_model.pkl"), Path("landmark_embedding.npy"))

The pickle is read with :mod:`synth.model.importers.safe_pickle` (only arrays, chumpy and
scipy.sparse wrappers of arrays; nothing in the file is executed). FLAME is in metres, Y
up, face toward +Z; synth is Z up, face toward -Y: (x, y, z) -> (x, -z, y).

* ``shapedirs`` (V, 3, 400): the first 300 components are identity, the rest expression;
  each is stored as a unit direction with its norm as scale, so codes are FLAME's own
  (about N(0, 1)); identity prior N(0, I).
* Joints: FLAME's kinematic tree (global -> neck -> jaw, eyes) maps to synth's names as
  global -> "neck" (the root), neck -> "head", jaw -> "jaw", and the eye joint on +X ->
  "eye_l", on -X -> "eye_r". ``joint_identity_basis`` = J_regressor @ identity shapedirs.
* ``weights`` are FLAME's LBS weights. ``posedirs`` (pose-corrective blend shapes) are
  dropped: synth's head model is plain LBS.
* Landmarks: FLAME ships the 68-point embedding separately (``landmark_embedding.npy``
  of DECA/RingNet, or ``flame_static_embedding.pkl`` + dynamic contour); it is required.
* Regions come from geometry rules (docs/importers.md); an optional ``FLAME_masks.pkl``
  supplies the ears and is kept as ``flame_*`` regions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.errors import ModelFormatError, SynthError
from synth.geometry.normals import normalize
from synth.io import sha256_file
from synth.model import meshutil as mu
from synth.model.format import HeadModelData
from synth.model.importers import regions as rg
from synth.model.importers.assemble import imported_model
from synth.model.importers.derived import derived_regions
from synth.model.importers.safe_pickle import load_npy_object, load_pickle, to_plain

IMPORTER_VERSION = 1
FLAME_SHAPE_COMPONENTS = 300
JOINT_NAMES = ["neck", "head", "jaw", "eye_l", "eye_r"]
_FIX = "pass the original FLAME 2020/2023 model file (generic_model.pkl or flame2023.pkl)"

LICENSE_TEXT = (
    "FLAME model supplied by the user. FLAME is (c) Max Planck Institute for Intelligent Systems and is "
    "licensed for non-commercial scientific research only (https://flame.is.tue.mpg.de/modellicense.html). "
    "This file is derived from FLAME: whoever uses it must hold their own FLAME licence; it is for the "
    "licence holder's own use and must not be redistributed or used commercially."
)


def to_synth(p: np.ndarray) -> np.ndarray:
    """FLAME (m, Y up, face +Z) -> synth (m, Z up, face -Y) on the last axis."""
    p = np.asarray(p, np.float64)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def _array(d: dict, key: str, where: str, ndim: int, kind: str = "f") -> np.ndarray:
    if key not in d:
        raise ModelFormatError(f"FLAME key '{key}' missing", where, _FIX)
    a = d[key]
    if hasattr(a, "toarray"):
        a = a.toarray()
    a = np.asarray(a)
    if a.ndim != ndim or a.dtype.kind not in ("fiu" if kind == "f" else "iu"):
        raise ModelFormatError(f"FLAME key '{key}' has shape {a.shape} / dtype {a.dtype}", where, _FIX)
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise ModelFormatError(f"FLAME key '{key}' contains NaN or Inf", where, _FIX)
    return a


def load_landmark_embedding(path: Path, n_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """68 iBUG landmarks as (face index (68,), barycentric (68, 3)) from FLAME/DECA files."""
    where = str(path)
    if not Path(path).is_file():
        raise SynthError("landmark embedding not found", where, "check the --landmarks path")
    d = to_plain(load_npy_object(path), where)
    if not isinstance(d, dict):
        raise ModelFormatError("landmark embedding is not a dict of arrays", where,
                               "pass FLAME's landmark_embedding.npy or flame_static_embedding.pkl")

    def get(*keys):
        for k in keys:
            if k in d:
                return np.asarray(d[k])
        return None

    fi, bc = get("full_lmk_faces_idx"), get("full_lmk_bary_coords")
    if fi is None or fi.size != 68:
        fi, bc = get("lmk_face_idx", "static_lmk_faces_idx"), get("lmk_b_coords", "static_lmk_bary_coords")
        if fi is None or bc is None:
            raise ModelFormatError("no landmark face indices (lmk_face_idx / full_lmk_faces_idx)", where,
                                   "pass FLAME's landmark_embedding.npy")
        fi, bc = fi.reshape(-1), bc.reshape(-1, 3)
        if fi.size == 51:  # static embedding without the jaw contour: take the frontal dynamic contour
            dfi, dbc = get("dynamic_lmk_faces_idx"), get("dynamic_lmk_bary_coords")
            if dfi is None or dbc is None or dfi.ndim != 2 or dfi.shape[1] != 17:
                raise ModelFormatError("embedding has 51 points and no 17-point jaw contour", where,
                                       "pass a 68-point embedding such as DECA's landmark_embedding.npy")
            mid = dfi.shape[0] // 2  # yaw bins from -39 to +39 degrees: the middle one is frontal
            fi = np.concatenate([dfi[mid], fi])
            bc = np.concatenate([dbc[mid].reshape(17, 3), bc])
    fi, bc = fi.reshape(-1).astype(np.int64), np.asarray(bc, np.float64).reshape(-1, 3)
    if fi.size != 68 or bc.shape != (68, 3):
        raise ModelFormatError(f"expected 68 landmarks, found {fi.size}", where, "pass a 68-point embedding")
    if fi.min() < 0 or fi.max() >= n_faces or not np.all(np.isfinite(bc)) or np.any(bc.sum(1) <= 0):
        raise ModelFormatError("landmark embedding does not match this FLAME mesh", where,
                               "use the embedding that ships with this FLAME version")
    return fi.astype(np.int32), (bc / bc.sum(1, keepdims=True)).astype(np.float32)


def _load_masks(path: Path | None, n: int) -> dict[str, np.ndarray]:
    if path is None:
        return {}
    d = to_plain(load_pickle(path), str(path))
    if not isinstance(d, dict):
        raise ModelFormatError("FLAME masks file is not a dict of index arrays", str(path), "pass FLAME_masks.pkl")
    out = {}
    for k, a in d.items():
        a = np.asarray(a).reshape(-1)
        if a.dtype.kind not in "iu" or (a.size and (a.min() < 0 or a.max() >= n)):
            raise ModelFormatError(f"mask '{k}' is not a vertex index array of this mesh", str(path),
                                   "pass the FLAME_masks.pkl of this FLAME version")
        out[str(k)] = np.unique(a).astype(np.int32)
    return out


def import_flame(model_file: str | Path, landmark_embedding: str | Path | None = None,
                 identity_dims: int = 300, expression_dims: int = 100, *, masks: str | Path | None = None,
                 shape_components: int = FLAME_SHAPE_COMPONENTS) -> HeadModelData:
    """Convert a FLAME pickle (+ its 68-point landmark embedding) into a :class:`HeadModelData`."""
    model_file = Path(model_file)
    where = str(model_file)
    if not model_file.is_file():
        raise ModelFormatError("FLAME model file not found", where, "check the path")
    if landmark_embedding is None:
        raise SynthError("FLAME keeps its 68 landmarks in a separate file", where,
                         "pass --landmarks landmark_embedding.npy (from your FLAME / DECA download)")
    d = to_plain(load_pickle(model_file), where)
    if not isinstance(d, dict):
        raise ModelFormatError("not a FLAME model (the pickle is not a dict)", where, _FIX)

    vt = _array(d, "v_template", where, 2)
    f = _array(d, "f", where, 2, "i").astype(np.int64)
    sd = _array(d, "shapedirs", where, 3)
    jreg = _array(d, "J_regressor", where, 2)
    kin = _array(d, "kintree_table", where, 2, "i").astype(np.int64)
    w = _array(d, "weights", where, 2)
    n = vt.shape[0]
    if vt.shape[1] != 3 or f.shape[1] != 3 or f.min() < 0 or f.max() >= n:
        raise ModelFormatError("v_template / f are not a triangle mesh", where, _FIX)
    if sd.shape[:2] != (n, 3) or jreg.shape[1] != n or w.shape != (n, jreg.shape[0]) or kin.shape != (2, 5) \
            or jreg.shape[0] != 5:
        raise ModelFormatError(f"inconsistent FLAME arrays (v_template {vt.shape}, shapedirs {sd.shape}, "
                               f"J_regressor {jreg.shape}, weights {w.shape}, kintree_table {kin.shape})", where, _FIX)
    n_shape = min(shape_components, sd.shape[2])
    n_expr = sd.shape[2] - n_shape
    if not 1 <= identity_dims <= n_shape:
        raise ModelFormatError(f"identity_dims={identity_dims}, but the file has {n_shape} shape components", where,
                               f"choose 1..{n_shape}")
    if not 0 <= expression_dims <= n_expr:
        raise ModelFormatError(f"expression_dims={expression_dims}, but the file has {n_expr} expression components",
                               where, f"choose 0..{n_expr}")

    # ---- geometry and bases, in synth axes
    v = to_synth(vt)
    tri_idx, tri_bary = load_landmark_embedding(Path(landmark_embedding), len(f))
    lm = mu.barycentric_points(v, f, tri_idx, tri_bary)
    if lm[30, 1] > lm[:, 1].mean():
        raise ModelFormatError("the nose tip does not point toward +Z in the file", where, _FIX)
    comps = to_synth(np.moveaxis(sd, 2, 0))  # (N, V, 3)
    idc = comps[:identity_dims]
    exc = comps[n_shape:n_shape + expression_dims]
    id_scale = np.linalg.norm(idc.reshape(len(idc), -1), axis=1)
    ex_scale = np.linalg.norm(exc.reshape(len(exc), -1), axis=1)
    if np.any(id_scale <= 0) or np.any(ex_scale <= 0):
        raise ModelFormatError("a shapedirs component is all zeros", where, _FIX)
    id_dirs = idc / id_scale[:, None, None]
    ex_dirs = exc / ex_scale[:, None, None]

    # ---- joints: FLAME order global, neck, jaw, eye, eye -> neck, head, jaw, eye_l, eye_r
    parents = np.where(kin[0] >= 5, -1, kin[0])  # root stored as 2**32-1
    if parents.tolist() != [-1, 0, 1, 1, 1]:
        raise ModelFormatError(f"unexpected FLAME kinematic tree {kin[0].tolist()}", where, _FIX)
    j_flame = jreg @ v
    perm = [0, 1, 2, 3, 4] if j_flame[3, 0] >= j_flame[4, 0] else [0, 1, 2, 4, 3]
    joints = j_flame[perm]
    jb = np.einsum("jv,kvc->kjc", jreg, id_dirs)[:, perm]
    weights = np.clip(w[:, perm], 0.0, None)
    s = weights.sum(1, keepdims=True)
    weights = np.where(s > 0, weights / np.where(s > 0, s, 1.0), np.eye(5)[1])

    # ---- regions
    user_masks = _load_masks(Path(masks) if masks is not None else None, n)
    eye_l = np.nonzero(weights[:, 3] > 0.5)[0]
    eye_r = np.nonzero(weights[:, 4] > 0.5)[0]
    skin = np.setdiff1d(np.arange(n), np.union1d(eye_l, eye_r))
    if "left_ear" in user_masks and "right_ear" in user_masks:
        ears = np.union1d(user_masks["left_ear"], user_masks["right_ear"])
    else:
        ears = rg.ear_flaps(v, f, skin, lm)
    an = rg.anatomy(v, lm, ears)
    regions = rg.skin_regions(v, skin, ears, an)
    regions.update(_eye_regions(v, f, skin, eye_l, eye_r, joints))
    regions["teeth"] = np.zeros(0, np.int32)  # FLAME has no teeth
    regions["mouth_interior"] = _mouth_interior(v, skin, an)
    for k in ("face", "lips", "beard"):  # the mouth bag is skin in FLAME: keep it out of the surface regions
        regions[k] = np.setdiff1d(regions[k], regions["mouth_interior"]).astype(np.int32)
    regions = derived_regions(v, regions, lm, float(joints[0, 2]))
    for k, a in user_masks.items():
        regions[f"flame_{k}"] = a

    landmarks = {"ibug68": (tri_idx, tri_bary)}
    if len(regions["face"]):
        start = int(regions["face"][np.argmin(np.linalg.norm(v[regions["face"]] - lm[30], axis=1))])
        landmarks["dense"] = rg.dense_landmarks(v, f, regions["face"], start, 600)
    return imported_model(
        "flame", (v, f), (id_dirs, id_scale), (ex_dirs, ex_scale, [f"exp{i:03d}" for i in range(expression_dims)]),
        (JOINT_NAMES, [-1, 0, 1, 1, 1], joints, jb), weights, regions, landmarks, LICENSE_TEXT,
        provenance={
            "source": "FLAME (MPI-IS), user-supplied", "source_file": model_file.name,
            "source_sha256": sha256_file(model_file), "landmark_file": Path(landmark_embedding).name,
            "masks_file": Path(masks).name if masks is not None else None,
            "importer": "synth.model.importers.flame", "importer_version": IMPORTER_VERSION,
            "vertices": n, "triangles": int(len(f)), "identity_dims": identity_dims,
            "expression_dims": expression_dims, "shape_components_in_file": n_shape,
            "expression_components_in_file": n_expr,
        },
        extra={"dropped": ["posedirs (pose-corrective blend shapes)"],
               "joint_map": {"neck": "global", "head": "neck", "jaw": "jaw",
                             "eye_l": f"eye joint {perm[3]}", "eye_r": f"eye joint {perm[4]}"},
               "identity_prior": "N(0, I): FLAME shape coefficients"},
    )


def _eye_regions(v, f, skin, eye_l, eye_r, joints) -> dict[str, np.ndarray]:
    """eye_l/eye_r from the eye-joint skin weights; iris = eyeball vertices within 30 degrees
    of the forward direction (-Y) seen from the eyeball centre, sclera the rest; eyelash
    lines = skin boundary loops within 2 eyeball radii of an eye centre (the lid margins)."""
    out = {"eye_l": eye_l.astype(np.int32), "eye_r": eye_r.astype(np.int32),
           "eyes": np.union1d(eye_l, eye_r).astype(np.int32)}
    iris, radii = [], []
    for ids, j in ((eye_l, 3), (eye_r, 4)):
        if len(ids) < 4:
            continue
        c, r = mu.fit_sphere(v[ids])
        radii.append((joints[j], r))
        u = normalize(v[ids] - c)
        iris.append(ids[-u[:, 1] > np.cos(np.radians(30.0))])
    out["iris"] = np.sort(np.concatenate(iris)).astype(np.int32) if iris else np.zeros(0, np.int32)
    out["sclera"] = np.setdiff1d(out["eyes"], out["iris"]).astype(np.int32)
    is_skin = np.zeros(len(v), bool)
    is_skin[skin] = True
    lines = []
    for loop in mu.boundary_loops(f[is_skin[f].all(1)]):
        c = v[loop].mean(0)
        if any(np.linalg.norm(c - jc) < 2.0 * r for jc, r in radii):
            lines.append(loop)
    out["eyelash_lines"] = np.unique(np.concatenate(lines)).astype(np.int32) if lines else np.zeros(0, np.int32)
    return out


def _mouth_interior(v, skin, an) -> np.ndarray:
    """Skin inside the inner lip contour (60-67) seen from the front, or within the mouth
    slit (0.9 x the mouth half-width, +-0.1 x eye distance around the inner lip height),
    and 2 mm to 0.35 x eye distance behind the inner lip landmarks: the lip roll and mouth
    bag of FLAME's closed mouth."""
    poly = an.lm[60:68][:, [0, 2]]
    sv = v[skin]
    inside = mu.point_in_polygon(sv[:, [0, 2]], poly)
    # widen by the mouth-corner landmarks: the inner contour of a closed mouth is a slit
    half = an.mouth_half_width
    zc = float(an.lm[60:68, 2].mean())
    slit = (np.abs(sv[:, 0]) < 0.9 * half) & (np.abs(sv[:, 2] - zc) < 0.1 * an.eye_dist)
    y_lip = float(an.lm[60:68, 1].mean())
    behind = (sv[:, 1] > y_lip + 0.002) & (sv[:, 1] < y_lip + 0.35 * an.eye_dist)
    return np.sort(skin[(inside | slit) & behind]).astype(np.int32)
