"""The body under the clothes (prototype, issue 42 item 2): a bust from the same MakeHuman data as
the default head, posed with its arms hanging, shaped by the head's identity code.

What it is (docs/body-plan.md has the measurements and the plan to integrate it):

* **Mesh.** The hm08 base mesh's ``body`` polygons of the upper body: the torso above
  :data:`Z_CUT` (base mesh, about the waist) and each upper arm down to :data:`ELBOW_T` of the way
  from the shoulder joint to the elbow joint, minus the head model's own polygons that hold no
  shoulder vertex (its head and neck). What remains overlaps the head model on its shoulder
  polygons (``head_polys``), which the bust replaces: the head model's shoulders are in the A pose
  and must move with the arms (the deltoids' tops are inside its crop, ``CROP_MAX_ABS_X``).
* **Pose.** MakeHuman's base mesh stands in an A pose, upper arms about 48 degrees below the
  horizontal. The arms are lowered by linear blend skinning with the mpfb2 ``standard`` rig's
  skin weights (``weights.default.json``, the head model's): a rotation at the scapula joint
  (``shoulder01``, :data:`GIRDLE_SHARE` of the turn: the shoulder girdle drops with the arm) and
  the rest at the glenohumeral joint (``upperarm01``), both about the same axis, chosen on the
  template so that the upper arm ends :data:`ARM_HANG_DEG` out from the vertical in the frontal
  plane and :data:`ARM_FORWARD_DEG` forward. Every other bone stays. The joint centres are the
  rig's (mean of MakeHuman's joint cubes), so they follow every identity.
* **Identity.** The rotations are fixed (the template's), and LBS with fixed rotations about
  joints that are linear in the vertices is a linear map of (vertices, joints): the posed bust is
  ``template + sum_k code_k * scale_k * basis_k`` like the head. The unposed basis is the
  regression of the bust's offsets on the head's identity codes over the builder's own samples
  (the formula of the head model's joint basis); on the vertices the head model also has, it is
  the head's PCA basis itself. So one identity code evaluates head and bust, and the bust is
  the best linear prediction, from the head, of what MakeHuman's macros (sex, age, weight,
  muscle, height, proportions, ethnicity) make of the body. :func:`build_bust` also reports the
  share of the bust's variance over the samples that the head code explains.

Pure numpy, deterministic up to BLAS rounding (the same as the head model: a shipped file).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from synth.model.builders.makehuman.identity import (N_SAMPLES, SEED, identity_pca, macro_targets, modifier_files,
                                                     modifiers, sample_identity_weights)
from synth.model.builders.makehuman.mesh import build_mesh, triangulate
from synth.model.builders.makehuman.skinning import JOINT_NAMES
from synth.model.builders.makehuman.sources import hm08_mirror, read_base_obj, read_target, vertex_groups
from synth.model.builders.makehuman.targets import TargetSpace

#: the torso is kept above this height on the base mesh (m): about the waist (spine03's head is at 0.20)
Z_CUT = 0.22
#: each upper arm is kept to this fraction of the way from the shoulder joint to the elbow joint
ELBOW_T = 1.0
#: a vertex whose skin weights on the upper arm's bones (upperarm01 and everything below it) sum to
#: at least this is an arm vertex (cut at the elbow), else a torso vertex (cut at Z_CUT)
ARM_WEIGHT = 0.5
#: the posed upper arm (shoulder joint to elbow joint) this many degrees out from the vertical ...
ARM_HANG_DEG = 8.0
#: ... and this many forward (relaxed arms hang a little in front of the mid-axillary line)
ARM_FORWARD_DEG = 6.0
#: the share of the arm's turn made at the scapula joint (the girdle drops with the arm)
GIRDLE_SHARE = 0.2
#: bones rotated: the girdle's and the arm's (each side: name + ".L" / ".R")
GIRDLE_BONE = "shoulder01"
ARM_BONE = "upperarm01"
ELBOW_BONE = "lowerarm01"
SIDES = (("L", 1.0), ("R", -1.0))


@dataclass
class BustData:
    """The bust (see the module docstring). Rows of the arrays are bust vertices."""

    hm08: np.ndarray  # (Vb,) hm08 index of each bust vertex
    polys: list[np.ndarray]  # bust-local polygons
    triangles: np.ndarray  # (T, 3)
    head_rows: np.ndarray  # (Vb,) the same vertex in the head model (or -1)
    head_polys: np.ndarray  # (P,) bool: a polygon the head model also has (its shoulders)
    mirror: np.ndarray  # (Vb,) bust index of each vertex's mirror image
    rest_template: np.ndarray  # (Vb, 3) the identity mean, unposed (A pose)
    rest_basis: np.ndarray  # (K, Vb, 3) unposed identity basis (regression on the head codes)
    template: np.ndarray  # (Vb, 3) posed
    basis: np.ndarray  # (K, Vb, 3) posed
    scale: np.ndarray  # (K,) the head model's identity_scale (std of each code)
    weights: np.ndarray  # (Vb, 5) skin weight classes: still, girdle L, arm L, girdle R, arm R
    joints: dict[str, np.ndarray]  # name -> (3,) rest joint of the template
    joint_basis: dict[str, np.ndarray]  # name -> (K, 3) rest joint basis
    rotations: dict[str, np.ndarray]  # "girdle_L", "arm_L", ... -> (3, 3) world rotations
    info: dict = field(default_factory=dict)
    #: with ``build_bust(keep_samples=K)``: the builder's first K identity samples as MakeHuman makes
    #: them ("rest": (K, Vb, 3) unposed, "joints": name -> (K, 3)), their head codes ("codes"),
    #: and their macro values ("gender" 0 female .. 1 male, "weight" 0 .. 1, "muscle", "old": the
    #: share of the 'old' age target, 0 at 25 years .. 1 at 90)
    samples: dict | None = None
    #: with :func:`bake_clearance`: (K + 1,) the left arm's turn out of the torso (radians), intercept
    #: first, linear in the code (the right arm's: the mirrored code's); already in template and basis
    turn: np.ndarray | None = None
    #: the bust's open bottom edge (bust rows round the waist loop, in order) and each elbow's loop,
    #: closed by the last polygons of ``polys`` (side -> bust rows)
    bottom_loop: np.ndarray | None = None
    elbow_loops: dict[str, np.ndarray] | None = None
    #: hm08's texture coordinates of the bust's polygons (the elbow caps': one loop vertex's)
    uvs: np.ndarray | None = None  # (Ub, 2)
    poly_uvs: list[np.ndarray] | None = None  # indices into uvs, parallel to polys
    tri_uv: np.ndarray | None = None  # (T, 3), parallel to triangles

    def rest(self, code: np.ndarray) -> np.ndarray:
        c = np.asarray(code, np.float64) * self.scale
        return self.rest_template + np.tensordot(c, self.rest_basis, 1)

    def posed(self, code: np.ndarray) -> np.ndarray:
        """(Vb, 3) the posed bust of an identity code (the head model's code)."""
        c = np.asarray(code, np.float64) * self.scale
        return self.template + np.tensordot(c, self.basis, 1)

    def joint(self, name: str, code: np.ndarray) -> np.ndarray:
        c = np.asarray(code, np.float64) * self.scale
        return self.joints[name] + c @ self.joint_basis[name]

    def joints_of(self, code: np.ndarray) -> dict[str, np.ndarray]:
        """The rest joints of an identity code (name -> (3,))."""
        return {n: self.joint(n, code) for n in self.joints}

    def evaluate(self, code: np.ndarray) -> np.ndarray:
        """(Vb, 3) the posed bust of ``code`` with its arms cleared of the torso: the linear model
        itself once the clearance is baked (:func:`bake_clearance`), else :func:`clear_arms`."""
        if self.turn is not None:
            return self.posed(code)
        return clear_arms(self, self.posed(code), self.joints_of(code))[0]


def _rig(data: Path) -> tuple[dict, dict]:
    rig = json.loads((data / "mpfb2/rigs/standard/rig.default.json").read_text())
    wts = json.loads((data / "mpfb2/rigs/standard/weights.default.json").read_text())["weights"]
    return rig, wts


def descendants(rig: dict, bone: str) -> list[str]:
    """``bone`` and every bone below it in the rig."""
    out, todo = [], [bone]
    while todo:
        b = todo.pop()
        out.append(b)
        todo += sorted(k for k, v in rig.items() if v.get("parent") == b)
    return out


def joint_vertices(rig: dict, bone: str, groups: dict[str, np.ndarray], end: str = "head") -> np.ndarray:
    """hm08 vertices whose mean is the bone's head (or tail): MakeHuman's joint strategies."""
    h = rig[bone][end]
    if h["strategy"] == "CUBE":
        return np.asarray(groups[h["cube_name"]], np.int64)
    if h["strategy"] == "MEAN":
        return np.asarray(h["vertex_indices"], np.int64)
    if h["strategy"] == "VERTEX":
        return np.array([h["vertex_index"]], np.int64)
    raise ValueError(f"unknown joint strategy {h['strategy']!r} for {bone}")


def weight_classes(rig: dict, wts: dict, n: int) -> np.ndarray:
    """(n, 5) hm08 skin weights summed into the transform classes: still (every bone not below a
    rotated one), girdle L (shoulder01.L and its bones not below upperarm01.L), arm L, girdle R,
    arm R; rows normalised."""
    cls = {}
    for s, _ in SIDES:
        arm = set(descendants(rig, f"{ARM_BONE}.{s}"))
        for b in descendants(rig, f"{GIRDLE_BONE}.{s}"):
            cls[b] = (2 if b in arm else 1) + (0 if s == "L" else 2)
    W = np.zeros((n, 5))
    for bone, lst in sorted(wts.items()):
        if not lst:
            continue
        a = np.array(lst, float)
        np.add.at(W[:, cls.get(bone, 0)], a[:, 0].astype(np.int64), a[:, 1])
    s = W.sum(1)
    W[s <= 0, 0] = 1.0
    return W / W.sum(1, keepdims=True)


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix about unit ``axis`` by ``angle`` radians (Rodrigues)."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


def hang_rotations(shoulder: np.ndarray, elbow: np.ndarray, side: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(girdle rotation, arm rotation, total angle in degrees) turning the upper arm from
    ``shoulder`` -> ``elbow`` to hang :data:`ARM_HANG_DEG` out and :data:`ARM_FORWARD_DEG` forward."""
    d0 = elbow - shoulder
    d0 = d0 / np.linalg.norm(d0)
    out, fwd = np.radians(ARM_HANG_DEG), np.radians(ARM_FORWARD_DEG)
    d1 = np.array([side * np.sin(out), -np.sin(fwd), -np.cos(out) * np.cos(fwd)])
    d1 /= np.linalg.norm(d1)
    axis = np.cross(d0, d1)
    ang = float(np.arctan2(np.linalg.norm(axis), np.dot(d0, d1)))
    return rotation(axis, GIRDLE_SHARE * ang), rotation(axis, (1.0 - GIRDLE_SHARE) * ang), float(np.degrees(ang))


def pose(V: np.ndarray, joints: dict[str, np.ndarray], W: np.ndarray, rot: dict[str, np.ndarray]) -> np.ndarray:
    """Linear blend skinning of vertices ``V`` (..., Vb, 3) with weight classes ``W`` (Vb, 5):
    the girdle turns about its scapula joint, the arm about its shoulder joint after the girdle.
    Linear and homogeneous in (V, joints): posing an offset with its joint offsets gives the
    offset of the posed shape (the identity basis is posed this way)."""
    out = W[:, 0, None] * V
    for k, (s, _) in enumerate(SIDES):
        g, a = joints[f"{GIRDLE_BONE}.{s}"], joints[f"{ARM_BONE}.{s}"]
        R1, R2 = rot[f"girdle_{s}"], rot[f"arm_{s}"]
        Vg = V @ R1.T + (g - g @ R1.T)[..., None, :]  # R1 (x - g) + g
        Va = (V @ R2.T + (a - a @ R2.T)[..., None, :]) @ R1.T + (g - g @ R1.T)[..., None, :]
        out = out + W[:, 1 + 2 * k, None] * Vg + W[:, 2 + 2 * k, None] * Va
    return out


def _edge_loop(nbr: dict, edge_faces: dict, v0: int, v1: int, limit: int = 400) -> list[int] | None:
    """The quad mesh's edge loop through edge (v0, v1): at each valence-4 vertex the edge that shares
    no face with the incoming one. None if it meets a pole or does not close within ``limit``."""
    loop = [v0, v1]
    for _ in range(limit):
        a, b = loop[-2], loop[-1]
        if len(nbr[b]) != 4:
            return None
        fa = set(edge_faces[(min(a, b), max(a, b))])
        nxt = [c for c in sorted(nbr[b]) if c != a and not set(edge_faces[(min(b, c), max(b, c))]) & fa]
        if len(nxt) != 1:
            return None
        if nxt[0] == loop[0]:
            return loop
        loop.append(nxt[0])
    return None


@dataclass
class Cut:
    """The bust's cuts on hm08: the waist loop (:data:`Z_CUT`) and each elbow's (:data:`ELBOW_T`),
    hm08 vertex indices in order round the loop."""

    waist: list[int]
    elbow: dict[str, list[int]]


def select(obj, mesh, Wc: np.ndarray, rig: dict, groups: dict,
           mirror_hm: np.ndarray) -> tuple[np.ndarray, list[int], np.ndarray, Cut]:
    """(hm08 vertices, base-mesh polygon indices, polygon is the head model's, the cuts) of the bust:
    the hm08 ``body`` quads above the edge loop nearest :data:`Z_CUT` (round the waist) and each
    upper arm's above its edge loop nearest :data:`ELBOW_T` (round the elbow): clean, nearly planar
    cuts along one vertex loop each."""
    from collections import defaultdict

    P = obj.verts
    body = [i for i, g in enumerate(obj.groups) if g == "body"]
    edge_faces, nbr = defaultdict(list), defaultdict(set)
    for i in body:
        p = obj.polys[i]
        for a, b in zip(p.tolist(), np.roll(p, -1).tolist()):
            edge_faces[(min(a, b), max(a, b))].append(i)
            nbr[a].add(b)
            nbr[b].add(a)
    bv = np.array(sorted(nbr))

    def best_loop(starts, dir_ok, score):
        best = None
        for v0 in starts.tolist():
            for v1 in sorted(nbr[v0]):
                if not dir_ok(v0, v1):
                    continue
                loop = _edge_loop(nbr, edge_faces, v0, v1)
                if loop is not None and (best is None or score(loop) < score(best)):
                    best = loop
        if best is None:
            raise ValueError("no closed edge loop for the bust's cut")
        return best

    # the waist: loops through the front midline's vertices near Z_CUT, running sideways
    mid = bv[(np.abs(P[bv, 0]) < 1e-4) & (P[bv, 1] < 0) & (np.abs(P[bv, 2] - Z_CUT) < 0.03)]
    waist = best_loop(mid, lambda a, b: P[b, 0] - P[a, 0] > 0.5 * np.linalg.norm(P[b] - P[a]),
                      lambda lp: abs(P[lp, 2].mean() - Z_CUT))
    # the left elbow: loops round the arm near ELBOW_T; the right one is its mirror image
    sh = P[joint_vertices(rig, f"{ARM_BONE}.L", groups)].mean(0)
    el = P[joint_vertices(rig, f"{ELBOW_BONE}.L", groups)].mean(0)
    d = el - sh
    t = (P - sh) @ d / (d @ d)
    dn = d / np.linalg.norm(d)
    near = bv[(Wc[bv, 2] >= 0.9) & (np.abs(t[bv] - ELBOW_T) < 0.05)]
    elbow_l = best_loop(near, lambda a, b: abs((P[b] - P[a]) @ dn) < 0.5 * np.linalg.norm(P[b] - P[a]),
                        lambda lp: abs(t[lp].mean() - ELBOW_T))
    cut = Cut(waist=waist, elbow={"L": elbow_l, "R": [int(mirror_hm[v]) for v in elbow_l]})
    cut_edges = set()
    for lp in (waist, cut.elbow["L"], cut.elbow["R"]):
        for a, b in zip(lp, lp[1:] + lp[:1]):
            cut_edges.add((min(a, b), max(a, b)))
    # flood the body's quads from the chest's front, not across the cuts
    seed_v = int(bv[np.argmin(np.linalg.norm(P[bv] - np.array([0.0, -0.1, Z_CUT + 0.2]), axis=1))])
    seen = {edge_faces[(min(seed_v, c), max(seed_v, c))][0] for c in sorted(nbr[seed_v])[:1]}
    todo = list(seen)
    while todo:
        f = todo.pop()
        p = obj.polys[f].tolist()
        for a, b in zip(p, p[1:] + p[:1]):
            e = (min(a, b), max(a, b))
            if e in cut_edges:
                continue
            for g in edge_faces[e]:
                if g not in seen:
                    seen.add(g)
                    todo.append(g)
    keep = sorted(seen)
    if P[np.concatenate([obj.polys[i] for i in keep]), 2].min() < Z_CUT - 0.03:
        raise ValueError("the bust's cuts do not close: the flood leaked below the waist")
    # head model polygons (by their hm08 vertices)
    head_key = {tuple(sorted(mesh.kept[p].tolist())) for p in mesh.polys if np.all(p < len(mesh.kept))}
    in_head = [tuple(sorted(obj.polys[i].tolist())) in head_key for i in keep]
    return np.unique(np.concatenate([obj.polys[i] for i in keep])), keep, np.array(in_head, bool), cut


def build_bust(data_dir: Path, head_model=None, identity_dims: int = 48, keep_samples: int = 0,
               feature_sigma: float | None = None) -> BustData:
    """Build the bust (module docstring). ``head_model``: a head model built from the same data
    (:class:`synth.model.format.HeadModelData`) to check the shared vertices and the basis
    against (optional; on the rows its own bust, if any, does not pose). ``feature_sigma``: the
    head's what-if spread of the inner face's modifiers (``build_makehuman_head``), so that the
    bust's basis regresses on that model's codes."""
    from synth.model.builders.makehuman.skinning import skin_weights

    data = Path(data_dir)
    rng = np.random.default_rng(SEED)
    obj = read_base_obj(data / "mpfb2/3dobjs/base.obj")
    P = obj.verts
    n_hm = len(P)
    groups = vertex_groups(data)
    mirror_hm = hm08_mirror(data, n_hm)
    mesh = build_mesh(obj, groups, mirror_hm)
    V, Jn = len(mesh.base), len(JOINT_NAMES)
    space = TargetSpace(mesh, groups, P)
    rig, wts = _rig(data)
    Wc_hm = weight_classes(rig, wts, n_hm)

    hm08, poly_ids, in_head_all, cut = select(obj, mesh, Wc_hm, rig, groups, mirror_hm)
    # drop the head model's polygons without a shoulder vertex (family 0 = torso) and without a
    # vertex that the pose moves (its head and neck): the seam between the head model's remaining
    # polygons and the bust then does not move with the arms
    _, family = skin_weights(data, mesh)
    fam_hm = np.full(n_hm, -1)
    fam_hm[mesh.kept] = family[: len(mesh.kept)]
    moves = Wc_hm[:, 0] < 1.0 - 1e-9
    sel = [(i, h) for i, h in zip(poly_ids, in_head_all)
           if not h or np.any(fam_hm[obj.polys[i]] == 0) or np.any(moves[obj.polys[i]])]
    poly_ids = [i for i, _ in sel]
    head_polys = np.array([h for _, h in sel], bool)
    hm08 = np.unique(np.concatenate([obj.polys[i] for i in poly_ids]))
    look = np.full(n_hm, -1, np.int64)
    look[hm08] = np.arange(len(hm08))
    if np.any(look[mirror_hm[hm08]] < 0):
        raise ValueError("the bust selection is not mirror-symmetric")
    polys = [look[obj.polys[i]] for i in poly_ids]
    uv_used = np.unique(np.concatenate([obj.poly_uvs[i] for i in poly_ids]))
    uv_look = np.full(len(obj.uvs), -1, np.int64)
    uv_look[uv_used] = np.arange(len(uv_used))
    puvs = [uv_look[obj.poly_uvs[i]] for i in poly_ids]
    # the elbows closed by one polygon each (facing down the arm), so that no hole shows
    caps = {}
    for s, _ in SIDES:
        lp = np.array(cut.elbow[s], np.int64)
        sh = P[joint_vertices(rig, f"{ARM_BONE}.{s}", groups)].mean(0)
        el = P[joint_vertices(rig, f"{ELBOW_BONE}.{s}", groups)].mean(0)
        q = P[lp]
        nrm = np.cross(q - q.mean(0), np.roll(q, -1, axis=0) - q.mean(0)).sum(0)
        if nrm @ (el - sh) < 0:  # reversed about its first vertex: the right loop stays the left's
            lp = np.concatenate([lp[:1], lp[:0:-1]])  # mirror image vertex for vertex, so the caps' fans are too
        caps[s] = look[lp]
        polys.append(look[lp])
        # the cap's corners take the uv of one loop vertex (skin colour; under a sleeve)
        first = next(j for j in poly_ids if lp[0] in obj.polys[j])
        u0 = uv_look[obj.poly_uvs[first][list(obj.polys[first]).index(lp[0])]]
        puvs.append(np.full(len(lp), u0, np.int64))
    head_polys = np.concatenate([head_polys, np.zeros(len(SIDES), bool)])
    mirror = look[mirror_hm[hm08]]
    head_rows = mesh.lookup[hm08]
    Vb = len(hm08)

    # joints: the neck (anchor, as the head's targets) and the rotated bones' heads; the elbow
    jv = {"neck": groups["joint-neck"]}
    for s, _ in SIDES:
        for b in (GIRDLE_BONE, ARM_BONE, ELBOW_BONE):
            jv[f"{b}.{s}"] = joint_vertices(rig, f"{b}.{s}", groups)
    jv["nipple.L"] = joint_vertices(rig, "breast.L", groups, "tail")
    jv["nipple.R"] = joint_vertices(rig, "breast.R", groups, "tail")
    jnames = list(jv)
    jmirror = [jnames.index(n[:-1] + {"L": "R", "R": "L"}[n[-1]]) if n[-2:] in (".L", ".R") else jnames.index(n)
               for n in jnames]

    def joints_of(full):
        return np.array([full[jv[n]].mean(0) for n in jnames])

    # ---- targets: head rows (for the head PCA, as build.py), bust rows and joints
    macro = macro_targets(data)
    mods = modifiers(data)
    files = [p for p, _ in macro] + modifier_files(mods)
    nt = len(files)
    T = np.empty((nt, V * 3))
    TJ = np.empty((nt, Jn * 3))
    B = np.empty((nt, Vb, 3))
    BJ = np.empty((nt, len(jnames), 3))
    for i, p in enumerate(files):
        idx, off = read_target(p)
        full = np.zeros((n_hm, 3))
        full[idx] = off
        o, j = space._from_full(full)
        T[i] = (o - j[0]).ravel()
        TJ[i] = (j - j[0]).ravel()
        B[i] = full[hm08] - j[0]
        BJ[i] = joints_of(full) - j[0]
    flip = np.array([-1.0, 1.0, 1.0])
    Tm, TJm = space.mirror(T.reshape(nt, V, 3), TJ.reshape(nt, Jn, 3))
    Bm = B[:, mirror] * flip
    BJm = BJ[:, jmirror] * flip
    W = sample_identity_weights(rng, N_SAMPLES, macro, mods)
    W_mean = None
    if feature_sigma is not None:  # as build_makehuman_head: wider features about the same template
        W, W_mean = sample_identity_weights(np.random.default_rng(SEED), N_SAMPLES, macro, mods,
                                            float(feature_sigma)), W
    mean, _, basis, std, _, codes, rank, explained = identity_pca(
        W, T, TJ, Tm.reshape(nt, -1), TJm.reshape(nt, -1), int(identity_dims), W_mean=W_mean)

    # ---- regression of the bust (and its joints) on the head codes, over the same samples
    n = len(W)
    W2 = np.zeros((2 * n, 2 * nt))
    W2[:n, :nt] = W
    W2[n:, nt:] = W
    wbar = W2.mean(0)
    Wc2 = W2 - wbar
    if W_mean is not None:  # the template: the mean of the default draws (identity_pca's W_mean)
        W2[:n, :nt] = W_mean
        W2[n:, nt:] = W_mean
        wbar = W2.mean(0)
    B2 = np.concatenate([B, Bm]).reshape(2 * nt, -1)
    J2 = np.concatenate([BJ, BJm]).reshape(2 * nt, -1)
    XB = Wc2 @ B2  # (2n, 3Vb) centred bust samples
    XJ = Wc2 @ J2
    rest_basis = (codes.T @ XB / (2 * n - 1) / std[:, None]).reshape(-1, Vb, 3)
    jbasis = (codes.T @ XJ / (2 * n - 1) / std[:, None]).reshape(-1, len(jnames), 3)
    total = float(np.sum(XB * XB) / (2 * n - 1))
    expl_bust = float(np.sum((rest_basis.reshape(len(std), -1) * std[:, None]) ** 2) / total)
    rest_template = P[hm08] + (wbar @ B2).reshape(Vb, 3)
    base_j = np.array([P[jv[nm]].mean(0) for nm in jnames])
    jrest = base_j + (wbar @ J2).reshape(-1, 3)
    # exact symmetry (as the head's template)
    rest_template = 0.5 * (rest_template + rest_template[mirror] * flip)
    jrest = 0.5 * (jrest + jrest[jmirror] * flip)
    joints = {nm: jrest[i] for i, nm in enumerate(jnames)}
    joint_basis = {nm: jbasis[:, i] for i, nm in enumerate(jnames)}

    # ---- pose: rotations chosen on the template, applied to template and basis alike
    Wcl = Wc_hm[hm08]
    rot, turn = {}, {}
    for s, sd in SIDES:
        R1, R2, ang = hang_rotations(joints[f"{ARM_BONE}.{s}"], joints[f"{ELBOW_BONE}.{s}"], sd)
        rot[f"girdle_{s}"], rot[f"arm_{s}"], turn[s] = R1, R2, ang
    template = pose(rest_template, joints, Wcl, rot)
    jb = {nm: joint_basis[nm] for nm in jnames}
    basis_posed = pose(rest_basis, jb, Wcl, rot)

    tris, tri_uv = triangulate(P[hm08], polys, puvs)
    info = {"vertices": Vb, "polygons": len(polys), "triangles": int(len(tris)),
            "head_polygons_replaced": int(head_polys.sum()), "identity_targets": nt,
            "identity_rank": rank, "head_variance_explained": round(explained, 4),
            "bust_variance_explained_by_head_code": round(expl_bust, 4),
            "arm_turn_deg": {s: round(a, 2) for s, a in turn.items()}}
    shared = head_rows >= 0
    info["shared_vertices"] = int(shared.sum())
    # on the head's vertices the regression is the head's PCA basis (a check of the construction)
    hb = basis.reshape(len(std), V, 3)[:, head_rows[shared]]
    info["shared_basis_max_diff"] = float(np.abs(hb - rest_basis[:, shared]).max())
    if head_model is not None:
        # a model that has a bust already holds the posed shape on the rows the pose moves
        cmp = shared & ((Wc_hm[hm08, 0] >= 1.0 - 1e-9) | ("bust" not in head_model.regions))
        hm_b = np.asarray(head_model.identity_basis, np.float64)[:, head_rows[cmp]]
        k = min(len(hm_b), len(std))
        info["shipped_basis_max_diff"] = float(np.abs(hm_b[:k] - rest_basis[:k, cmp]).max())
        info["shipped_template_max_diff"] = float(np.abs(np.asarray(head_model.template, np.float64)[
            head_rows[cmp]] - rest_template[cmp]).max())
        info["shipped_scale_max_rel_diff"] = float(np.abs(np.asarray(head_model.identity_scale)[:k] / std[:k] - 1).max())
    samples = None
    if keep_samples:
        K = int(keep_samples)
        keys = [k for _, k in macro]

        def share(var, val):
            cols = [i for i, k in enumerate(keys) if len(k) == 4 and (var, val) in k]  # universal targets
            return W[:K, cols].sum(1)

        ex_j = base_j + (W[:K] @ BJ.reshape(nt, -1)).reshape(K, -1, 3)
        samples = {"rest": P[hm08] + (W[:K] @ B.reshape(nt, -1)).reshape(K, Vb, 3),
                   "joints": {nm: ex_j[:, i] for i, nm in enumerate(jnames)}, "codes": codes[:K],
                   "gender": share("gender", "male"),
                   "weight": 0.5 + 0.5 * (share("weight", "max") - share("weight", "min")),
                   "muscle": 0.5 + 0.5 * (share("muscle", "max") - share("muscle", "min")),
                   "old": share("age", "old")}
    return BustData(hm08=hm08, polys=polys, triangles=tris, head_rows=head_rows, head_polys=head_polys,
                    mirror=mirror, rest_template=rest_template, rest_basis=rest_basis, template=template,
                    basis=basis_posed, scale=std, weights=Wcl, joints=joints, joint_basis=joint_basis,
                    rotations=rot, info=info, samples=samples, bottom_loop=look[np.array(cut.waist)],
                    elbow_loops=caps, uvs=np.asarray(obj.uvs)[uv_used], poly_uvs=puvs, tri_uv=tri_uv)


def save_bust(b: BustData, path: Path) -> None:
    """The bust as an .npz (float32 shapes, as the model file), for the benchmark and the render."""
    np.savez_compressed(
        path, hm08=b.hm08.astype(np.int32), triangles=b.triangles.astype(np.int32),
        poly_offsets=np.concatenate([[0], np.cumsum([len(p) for p in b.polys])]).astype(np.int32),
        poly_indices=np.concatenate(b.polys).astype(np.int32), head_rows=b.head_rows.astype(np.int32),
        head_polys=b.head_polys, mirror=b.mirror.astype(np.int32),
        rest_template=b.rest_template.astype(np.float32), rest_basis=b.rest_basis.astype(np.float32),
        template=b.template.astype(np.float32), basis=b.basis.astype(np.float32), scale=b.scale.astype(np.float32),
        weights=b.weights.astype(np.float32),
        joint_names=np.array(list(b.joints)), joints=np.array(list(b.joints.values()), np.float32),
        joint_basis=np.stack(list(b.joint_basis.values()), 1).astype(np.float32),
        rotations=json.dumps({k: v.tolist() for k, v in b.rotations.items()}),
        info=json.dumps(b.info), **({} if b.turn is None else {"turn": b.turn}),
        **({} if b.uvs is None else {"uvs": b.uvs.astype(np.float32), "tri_uv": b.tri_uv.astype(np.int32),
                                      "poly_uv_indices": np.concatenate(b.poly_uvs).astype(np.int32)}),
        **({} if b.bottom_loop is None else {"bottom_loop": b.bottom_loop.astype(np.int32),
                                              "elbow_L": b.elbow_loops["L"].astype(np.int32),
                                              "elbow_R": b.elbow_loops["R"].astype(np.int32)}))


def load_bust(path: Path) -> BustData:
    z = np.load(path, allow_pickle=False)
    off = z["poly_offsets"]
    polys = [z["poly_indices"][a:b].astype(np.int64) for a, b in zip(off[:-1], off[1:])]
    names = [str(x) for x in z["joint_names"]]
    return BustData(
        hm08=z["hm08"].astype(np.int64), polys=polys, triangles=z["triangles"].astype(np.int64),
        head_rows=z["head_rows"].astype(np.int64), head_polys=z["head_polys"], mirror=z["mirror"].astype(np.int64),
        rest_template=z["rest_template"].astype(np.float64), rest_basis=z["rest_basis"].astype(np.float64),
        template=z["template"].astype(np.float64), basis=z["basis"].astype(np.float64),
        scale=z["scale"].astype(np.float64), weights=z["weights"].astype(np.float64),
        joints={n: z["joints"][i].astype(np.float64) for i, n in enumerate(names)},
        joint_basis={n: z["joint_basis"][:, i].astype(np.float64) for i, n in enumerate(names)},
        rotations={k: np.array(v) for k, v in json.loads(str(z["rotations"])).items()},
        info=json.loads(str(z["info"])), turn=z["turn"].astype(np.float64) if "turn" in z else None,
        bottom_loop=z["bottom_loop"].astype(np.int64) if "bottom_loop" in z else None,
        elbow_loops={s: z[f"elbow_{s}"].astype(np.int64) for s in "LR"} if "elbow_L" in z else None,
        uvs=z["uvs"].astype(np.float64) if "uvs" in z else None,
        tri_uv=z["tri_uv"].astype(np.int64) if "tri_uv" in z else None,
        poly_uvs=[z["poly_uv_indices"][a:b].astype(np.int64) for a, b in zip(off[:-1], off[1:])]
        if "poly_uv_indices" in z else None)


#: for :func:`arm_torso_penetration`: torso triangles have every corner's arm weight under this, arm
#: vertices at least 1 - this
PENETRATION_WEIGHT = 0.1
#: ... and lie this far (m) or more under their side's posed shoulder joint, below the armpit's
#: fold (the torso's triangles from PENETRATION_BELOW - 0.03 down): in the fold, arm and torso
#: meet by construction and the sign of a distance to the fold's downward faces means nothing
PENETRATION_BELOW = 0.13


def arm_torso_penetration(b: BustData, V: np.ndarray, J: dict[str, np.ndarray]) -> dict[str, float]:
    """How deep (m) each posed arm's vertices ``V`` (Vb, 3) of the identity whose rest joints are
    ``J`` go inside the
    torso's surface: the largest negative signed distance (vertex-normal sign, robust on the open
    bust) of arm vertices under the armpit to the torso's triangles beside them; 0 when none is
    inside. Side "L", "R"."""
    return {s: max(0.0, -g) for s, g in arm_torso_gap(b, V, J).items()}


def arm_torso_gap(b: BustData, V: np.ndarray, J: dict[str, np.ndarray]) -> dict[str, float]:
    """The smallest signed distance (m) of each arm's vertices under the armpit to the torso's
    triangles beside them (:func:`arm_torso_penetration`'s query, unclipped): negative inside the
    torso, positive the arm's gap to the chest. Side "L", "R" (+inf where nothing is checked)."""
    from synth.geometry.sdf import SignedDistance

    F = b.triangles
    arm_w = b.weights[:, 2] + b.weights[:, 4]
    torso = np.all(arm_w[F] < PENETRATION_WEIGHT, axis=1)
    zc = V[F, 2].mean(1)
    out = {}
    for k, (s, _) in enumerate(SIDES):
        az = float(posed_joint(b, f"{ARM_BONE}.{s}", J)[2])
        faces = np.nonzero(torso & (zc < az - PENETRATION_BELOW + 0.03))[0]
        arm = np.nonzero((b.weights[:, 2 + 2 * k] >= 1 - PENETRATION_WEIGHT) & (V[:, 2] < az - PENETRATION_BELOW))[0]
        if not len(arm) or not len(faces):
            out[s] = float("inf")
            continue
        d = SignedDistance(V, F, faces=faces, sign="vertex")(V[arm])
        out[s] = float(d.min())
    return out


#: :func:`clear_arms`: arms whose vertices go deeper than this (m) into the torso are turned out ...
CLEARANCE_TOL = 0.001
#: ... until they are this far (m) out of it (at most CLEARANCE_STEPS turns, CLEARANCE_MAX_DEG in all)
CLEARANCE_MARGIN = 0.002
CLEARANCE_STEPS = 4
CLEARANCE_MAX_DEG = 25.0


def posed_joint(b: BustData, name: str, J: dict[str, np.ndarray]) -> np.ndarray:
    """A rest joint of ``J`` (an identity's rest joints, :meth:`BustData.joints_of`) where
    :func:`pose` takes it: the shoulder joint turns with the girdle, the elbow with the girdle and
    the arm; other joints stay."""
    j = np.asarray(J[name], np.float64)
    bone, s = name.rsplit(".", 1)
    if bone not in (ARM_BONE, ELBOW_BONE):
        return j
    g = np.asarray(J[f"{GIRDLE_BONE}.{s}"], np.float64)
    R1, R2 = b.rotations[f"girdle_{s}"], b.rotations[f"arm_{s}"]
    if bone == ELBOW_BONE:
        a = np.asarray(J[f"{ARM_BONE}.{s}"], np.float64)
        j = (j - a) @ R2.T + a
    return (j - g) @ R1.T + g


def clear_arms(b: BustData, V: np.ndarray, J: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, float]]:
    """(vertices, extra abduction per side in degrees): the posed bust ``V`` (rest joints ``J``) with each
    arm turned out about its (posed) shoulder joint, about the front-back axis, until its vertices
    under the armpit are :data:`CLEARANCE_MARGIN` outside the torso (:func:`arm_torso_penetration`).
    The linear model poses every identity with the template's rotations; a heavy body's chest
    then takes the arm's place (up to 3.5 cm deep on 200 planned identities): real arms rest
    against the chest, pushed out by it."""
    V = np.array(V, np.float64, copy=True)
    extra = {}
    for k, (s, sign) in enumerate(SIDES):
        a = posed_joint(b, f"{ARM_BONE}.{s}", J)
        w = b.weights[:, 2 + 2 * k]
        total = 0.0
        for _ in range(CLEARANCE_STEPS):
            depth = arm_torso_penetration(b, V, J)[s]
            if depth <= CLEARANCE_TOL:
                break
            # the arm's length to the deepest region: about the distance to the elbow
            r = float(np.linalg.norm(posed_joint(b, f"{ELBOW_BONE}.{s}", J) - a))
            step = min(np.degrees((depth + CLEARANCE_MARGIN) / r), CLEARANCE_MAX_DEG - total)
            if step <= 0:
                break
            # about -y on the left: a point below the joint moves toward +x (out); +y on the right
            R = rotation(np.array([0.0, -sign, 0.0]), np.radians(step))
            V = V + w[:, None] * ((V - a) @ (R - np.eye(3)).T)
            total += step
        extra[s] = total
    return V, extra


#: the deltoids' band for the bideltoid breadth: from this far (m) under the posed shoulder joints ...
DELTOID_BELOW = 0.12
#: ... to this far above them
DELTOID_ABOVE = 0.08
#: the acromion (skin): the most lateral skin point at least this far (m) above the posed shoulder
#: joint, within ACROMION_SLAB (m) of the joint front to back. The acromion's lateral edge sits a few
#: cm above the humeral head's centre; under it the deltoid bulges out (the bideltoid breadth)
ACROMION_ABOVE = 0.03
ACROMION_SLAB = 0.02
#: the chest band: this far (m) above and below the nipples (MakeHuman's breast bones' tails)
CHEST_BAND = 0.015


def measures(b: BustData, V: np.ndarray, J: dict[str, np.ndarray]) -> dict[str, float]:
    """Anthropometric breadths and depths (mm) of a posed bust ``V`` (rest joints ``J``):

    * ``bideltoid``: the largest breadth side to side between DELTOID_BELOW under and
      DELTOID_ABOVE over the (posed) shoulder joints: the deltoids, arms hanging (Pheasant's item 17);
    * ``biacromial``: between the skin acromia (ACROMION_ABOVE; item 18 is measured on the bone,
      a few mm inside the skin); ``gh_centres``: between the glenohumeral joint centres (the rig's);
    * ``chest_depth``: from the back's rearmost point (between the chest band and the shoulder
      joints: the shoulder blades) to the chest's or breasts' foremost point in the chest band
      (item 20, measured to a wall touching the back);
    * ``chest_breadth``: the torso's breadth (arm vertices excluded) in the chest band."""
    a = {s: posed_joint(b, f"{ARM_BONE}.{s}", J) for s, _ in SIDES}
    az = 0.5 * (a["L"][2] + a["R"][2])
    x, y, z = V[:, 0], V[:, 1], V[:, 2]
    d = (z > az - DELTOID_BELOW) & (z < az + DELTOID_ABOVE)
    out = {"bideltoid": x[d].max() - x[d].min()}
    acr = []
    for s, sign in SIDES:
        m = (z >= a[s][2] + ACROMION_ABOVE) & (np.abs(y - a[s][1]) <= ACROMION_SLAB) & (sign * x > 0)
        acr.append((sign * x[m]).max())
    out["biacromial"] = acr[0] + acr[1]
    out["gh_centres"] = float(np.linalg.norm(a["L"] - a["R"]))
    nz = 0.5 * (J["nipple.L"][2] + J["nipple.R"][2])  # the breast bones do not move
    torso = (b.weights[:, 2] + b.weights[:, 4]) < PENETRATION_WEIGHT
    band = torso & (np.abs(z - nz) <= CHEST_BAND)
    back = torso & (z > nz - CHEST_BAND) & (z < az)
    out["chest_depth"] = y[back].max() - y[band].min()
    out["chest_breadth"] = x[band].max() - x[band].min()
    return {k: 1000.0 * float(v) for k, v in out.items()}


# ---- the arm clearance baked into the linear model ------------------------------------------------
#: :func:`bake_clearance`: prior draws the turn is fitted on (fixed seed: a deterministic build) ...
BAKE_DRAWS = 600
BAKE_SEED = 20261204
#: ... plus the codes at +-BAKE_AXIS_SD along every identity direction
BAKE_AXIS_SD = 3.5
#: the fitted turn leaves every fit code's arm this far (m) out of the torso (the bake's linear fit of
#: the turned arm then costs a little of it on the extremes)
BAKE_MARGIN = 0.003
#: then BAKE_ROUNDS times: BAKE_CHECK more prior draws (another seed) and the axes' codes are
#: evaluated on the baked model, and those whose arm is under BAKE_TARGET (m) out of the torso join
#: the fit (cutting planes)
BAKE_CHECK = 1500
#: ... and the BAKE_HEAVY of BAKE_MANY more draws whose fitted turn is largest
BAKE_MANY = 20000
BAKE_HEAVY = 200
#: the fit's target turn: the needed one, but no further in than this (degrees; 0: the clearance
#: step's, which only turns arms out; -inf: every arm rests BAKE_MARGIN off the chest)
BAKE_FLOOR_DEG = 0.0
BAKE_ROUNDS = 4
BAKE_TARGET = 0.001
#: the central differences' step (code units)
BAKE_EPS = 1e-3


def code_mirror_signs(b: BustData) -> np.ndarray:
    """(K,) +1 for each identity direction whose posed bust is mirror-symmetric, -1 antisymmetric:
    the mirror image of the identity with code c has code ``c * signs``."""
    flip = np.array([-1.0, 1.0, 1.0])
    out = np.empty(len(b.basis))
    for k, bk in enumerate(b.basis):
        m = bk[b.mirror] * flip
        out[k] = 1.0 if np.abs(m - bk).max() <= np.abs(m + bk).max() else -1.0
    return out


def turn_arm(b: BustData, V: np.ndarray, J: dict[str, np.ndarray], side: str, angle: float) -> np.ndarray:
    """``V`` with arm ``side`` turned out by ``angle`` radians (negative: in) about its posed
    shoulder joint, about the front-back axis, weighted by the arm's skin weight (:func:`clear_arms`'s turn)."""
    k, sign = [(i, sg) for i, (s, sg) in enumerate(SIDES) if s == side][0]
    a = posed_joint(b, f"{ARM_BONE}.{side}", J)
    R = rotation(np.array([0.0, -sign, 0.0]), angle)
    return V + b.weights[:, 2 + 2 * k, None] * ((V - a) @ (R - np.eye(3)).T)


def needed_turn(b: BustData, code: np.ndarray, margin: float = BAKE_MARGIN, iters: int = 4) -> dict[str, float]:
    """Side -> the turn (radians; negative: in) of the linear model's posed arm of ``code`` that puts
    its vertices under the armpit ``margin`` out of the torso (secant steps on :func:`arm_torso_gap`)."""
    J = b.joints_of(code)
    V0 = b.posed(code)
    out = {}
    for s, _ in SIDES:
        r = float(np.linalg.norm(posed_joint(b, f"{ELBOW_BONE}.{s}", J) - posed_joint(b, f"{ARM_BONE}.{s}", J)))
        th, g = 0.0, arm_torso_gap(b, V0, J)[s]
        th_prev, g_prev = None, None
        for _ in range(iters):
            if abs(g - margin) < 2e-4:
                break
            if th_prev is None or abs(g - g_prev) < 1e-6:
                step = (margin - g) / r
            else:
                step = (margin - g) * (th - th_prev) / (g - g_prev)
            th_prev, g_prev = th, g
            th = th + float(np.clip(step, -0.3, 0.3))
            g = arm_torso_gap(b, turn_arm(b, V0, J, s, th), J)[s]
        out[s] = th
    return out


def _fit_turn(X: np.ndarray, need: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """(K + 1,) coefficients (intercept first) of the linear turn t(c) = w0 + w . c that is at least
    ``need`` on every row of ``X`` (codes) and otherwise as close as possible (L1) to max(0, need):
    the clearance step's turn, where it turns, and no turn where the arm has room. A linear program."""
    from scipy.optimize import linprog

    n, K = X.shape
    A = np.hstack([np.ones((n, 1)), X])
    tgt = np.maximum(need, floor)
    # variables: w (K+1, free), slack e (n, >= 0); min sum e; A w >= need; |A w - tgt| <= e
    c = np.concatenate([np.zeros(K + 1), np.ones(n)])
    I = np.eye(n)
    A_ub = np.vstack([np.hstack([-A, np.zeros((n, n))]), np.hstack([A, -I]), np.hstack([-A, -I])])
    b_ub = np.concatenate([-need, tgt, -tgt])
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=[(None, None)] * (K + 1) + [(0, None)] * n, method="highs")
    if not res.success:
        raise RuntimeError(f"the arm turn's linear program failed: {res.message}")
    return res.x[: K + 1]


def bake_codes(prior, radius: float | None, dims: int, seed: int = BAKE_SEED, draws: int = BAKE_DRAWS) -> np.ndarray:
    """The codes :func:`bake_clearance` fits on: BAKE_DRAWS truncated prior draws and the codes at
    +-BAKE_AXIS_SD on every axis."""
    rng = np.random.default_rng(seed)
    d = prior.sample(rng, draws, radius)
    ax = np.concatenate([np.eye(dims), -np.eye(dims)]) * BAKE_AXIS_SD
    return np.concatenate([d, ax])


def bake_clearance(b: BustData, prior, radius: float | None, seed: int = BAKE_SEED, draws: int = BAKE_DRAWS,
                   rounds: int = BAKE_ROUNDS, check: int = BAKE_CHECK, heavy: int = BAKE_HEAVY) -> BustData:
    """The bust with :func:`clear_arms` baked into its linear model (no evaluation-time step): each
    posed arm turned out (or in) about its posed shoulder joint by a turn *linear in the identity
    code*, t(c) = w0 + w . c, fitted by a linear program (:func:`_fit_turn`) so that every fit code's
    arm clears the torso by BAKE_MARGIN (:func:`needed_turn`) and is otherwise as close as it can be
    to the clearance step's turn. The turned bust is then linearised about the mean code (the
    template turned exactly, the basis by the turn's derivative), so the result is again
    ``template + sum_k code_k * scale_k * basis_k``, mirror-symmetric like the unbaked one (the right
    arm is the left arm's mirror image; its turn is the left's of the mirrored code). Cutting planes:
    ``rounds`` times, ``check`` more prior draws, the axes' codes and the ``heavy`` draws (of
    BAKE_MANY) with the largest turn are evaluated on the baked model, and every arm under
    BAKE_TARGET out of the torso joins the fit with a secant step's turn.

    A linear turn cannot follow the clearance step's hinge (no turn, then a turn growing with the
    body): it lies above it, so the average arm is turned out a few degrees (``info["clearance"]``).
    ``prior``: the head model's identity prior (:class:`synth.model.identity_gmm.GaussianMixture`),
    ``radius``: its truncation (:func:`synth.plan.identities.truncation_radius`)."""
    K = len(b.basis)
    signs = code_mirror_signs(b)
    C = bake_codes(prior, radius, K, seed, draws)

    def needs(codes):
        rows = [needed_turn(b, c) for c in codes]
        # left arm of c and (mirrored) right arm of c, both as a left arm of a code
        return np.concatenate([codes, codes * signs]), np.array([r["L"] for r in rows] + [r["R"] for r in rows])

    X, need = needs(C)
    checks = prior.sample(np.random.default_rng(seed + 1), check, radius)
    checks = np.concatenate([checks, np.concatenate([np.eye(K), -np.eye(K)]) * BAKE_AXIS_SD])
    many = prior.sample(np.random.default_rng(seed + 2), BAKE_MANY, radius)
    added = 0
    for rnd in range(rounds + 1):
        w = _fit_turn(X, need, np.radians(BAKE_FLOOR_DEG))
        dT, dB = _turn_offsets(b, w, signs)
        if rnd == rounds:
            break
        # cutting planes: the check codes whose baked arm is under BAKE_TARGET out of the torso join
        # the fit with the turn that a secant step on the baked model asks for
        newX, newn = [], []
        T1, B1 = b.template + dT, b.basis + dB
        # ... and the many draws' BAKE_HEAVY whose fitted turn is largest: the heavy bodies' extremes
        t = np.maximum(many @ w[1:], (many * signs) @ w[1:])
        for c in np.concatenate([checks, many[np.argsort(-t, kind="stable")[:heavy]]]):
            cs = c * b.scale
            V = T1 + np.tensordot(cs, B1, 1)
            J = b.joints_of(c)
            g = arm_torso_gap(b, V, J)
            for s, cc in (("L", c), ("R", c * signs)):
                if g[s] < BAKE_TARGET:
                    r = float(np.linalg.norm(posed_joint(b, f"{ELBOW_BONE}.{s}", J) - posed_joint(b, f"{ARM_BONE}.{s}", J)))
                    newX.append(cc)
                    newn.append(float(w[0] + w[1:] @ cc) + (BAKE_MARGIN - g[s]) / r)
        if not newX:
            break
        added += len(newX)
        X, need = np.concatenate([X, np.array(newX)]), np.concatenate([need, np.array(newn)])
    info = dict(b.info)
    A = np.hstack([np.ones((len(X), 1)), X])
    info["clearance"] = {"baked": True, "fit_codes": int(len(C)), "cutting_planes": added, "margin_m": BAKE_MARGIN,
                         "turn_at_mean_deg": round(float(np.degrees(w[0])), 3),
                         "turn_fit_deg": {"p50": round(float(np.degrees(np.median(A @ w))), 2),
                                          "max": round(float(np.degrees((A @ w).max())), 2),
                                          "min": round(float(np.degrees((A @ w).min())), 2)},
                         }
    out = apply_turn(b, w)
    out.info = info
    return out


def _turn_offsets(b: BustData, w: np.ndarray, signs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(template offset, basis offset) of the arms turned by the linear turn ``w`` (intercept
    first), linearised about the mean code: the template turned exactly, the basis by the turn's
    derivative (central differences of BAKE_EPS). A turn's tangent moves the arm a little further
    out than the turn itself (safe), and the arm grows by 1 / cos of the turn's departure from the
    mean's (6 % at 20 degrees). The left arm's rows from the left turn, the right arm's as their
    mirror image (exact symmetry; ``signs``: :func:`code_mirror_signs`)."""
    K = len(b.basis)
    flip = np.array([-1.0, 1.0, 1.0])
    rows = np.nonzero(b.weights[:, 2] > 0)[0]  # the left arm's

    def turned(c):
        J = b.joints_of(c)
        V = b.posed(c)
        return (turn_arm(b, V, J, "L", float(w[0] + w[1:] @ c)) - V)[rows]

    coef = np.empty((K + 1, len(rows), 3))
    coef[0] = turned(np.zeros(K))
    for k in range(K):
        e = np.zeros(K)
        e[k] = BAKE_EPS
        coef[1 + k] = (turned(e) - turned(-e)) / (2 * BAKE_EPS)
    dT = np.zeros_like(b.template)
    dB = np.zeros_like(b.basis)
    dT[rows] = coef[0]
    dB[:, rows] = coef[1:] / b.scale[:, None, None]
    # the right arm: the mirror image of the left (the mirror rows of the left arm are the right arm's)
    dT = dT + dT[b.mirror] * flip
    dB = dB + dB[:, b.mirror] * flip * signs[:, None, None]
    return dT, dB


def apply_turn(b: BustData, w) -> BustData:
    """The bust ``b`` (unbaked) with the linear arm turn ``w`` (radians; intercept, then one
    coefficient per identity component: :func:`bake_clearance`'s fit, or the pinned
    :data:`synth.model.builders.makehuman.arm_turn.TURN`) folded into its template and basis.
    Coefficients beyond the bust's components are dropped, missing ones are 0."""
    if b.turn is not None:
        raise ValueError("the bust's arm turn is already baked")
    K = len(b.basis)
    w = np.asarray(w, np.float64)
    ww = np.zeros(K + 1)
    ww[: min(len(w), K + 1)] = w[: K + 1]
    dT, dB = _turn_offsets(b, ww, code_mirror_signs(b))
    out = BustData(**{f.name: getattr(b, f.name) for f in b.__dataclass_fields__.values()})
    out.template = b.template + dT
    out.basis = b.basis + dB
    out.info = dict(b.info)
    out.turn = ww
    return out


# ---- the head model with the bust appended (a builder option, not the default model) --------------
def append_bust(m, b: BustData, name: str | None = None):
    """A copy of the head model ``m`` (:class:`synth.model.format.HeadModelData`, built from the same
    MakeHuman data) with the bust ``b`` (posed, its clearance baked: :func:`bake_clearance`) in its
    mesh:

    * the bust's vertices the head lacks are appended after the head's, so every existing vertex
      index, region, landmark set, eyelid list and ``mirror`` entry stays valid; the shared vertices
      the pose moves (the shoulders') take the bust's posed template and basis, the others keep
      the head's bits;
    * the head's polygons that the bust replaces (its shoulders, ``b.head_polys``) and their
      triangles are removed, the bust's appended after the rest (landmark triangles renumbered);
    * new rows: the bust's identity basis, zero expression rows, skin weight 1 on the root joint
      (``neck``: the plans rotate only jaw and eyes), hm08's uvs;
    * regions ``bust`` (every bust vertex), ``torso``, ``arm_l``, ``arm_r`` (arm weight >= 0.5),
      ``bust_bottom`` (the open waist loop), ``elbow_l``, ``elbow_r`` (the loops the elbow caps
      close, in order); ``shoulders`` and ``skin`` grow by the new vertices.

    ``name``: the result's name (default: the model's, ``+bust``)."""
    import copy

    if b.turn is None:
        raise ValueError("append_bust wants a bust whose arm clearance is baked (bake_clearance)")
    out = copy.deepcopy(m)
    V0 = m.num_vertices
    new = np.nonzero(b.head_rows < 0)[0]
    idx = b.head_rows.copy()
    idx[new] = V0 + np.arange(len(new))
    moved = (b.head_rows >= 0) & (b.weights[:, 0] < 1.0 - 1e-9)
    K = m.identity_dims
    if len(b.basis) < K:
        raise ValueError(f"the bust has {len(b.basis)} identity components, the model {K}")
    bb = b.basis[:K]
    Vn = V0 + len(new)
    tpl = np.zeros((Vn, 3), np.float32)
    tpl[:V0] = m.template
    tpl[idx[new]] = b.template[new]
    tpl[idx[moved]] = b.template[moved]
    ib = np.zeros((K, Vn, 3), np.float32)
    ib[:, :V0] = m.identity_basis
    ib[:, idx[new]] = bb[:, new]
    ib[:, idx[moved]] = bb[:, moved]
    eb = np.zeros((m.expression_dims, Vn, 3), np.float32)
    eb[:, :V0] = m.expression_basis
    sw = np.zeros((Vn, len(m.joint_names)), np.float32)
    sw[:V0] = m.skin_weights
    sw[V0:, m.joint_names.index("neck")] = 1.0
    # polygons: the head's minus the replaced ones, then the bust's
    off = np.asarray(m.poly_offsets)
    npol = len(off) - 1
    replaced = {tuple(sorted(b.head_rows[p].tolist())) for p, h in zip(b.polys, b.head_polys) if h}
    drop = np.array([tuple(sorted(m.poly_indices[off[i]:off[i + 1]].tolist())) in replaced for i in range(npol)])
    if drop.sum() != b.head_polys.sum():
        raise ValueError(f"{drop.sum()} of the model's polygons match the bust's {b.head_polys.sum()} shoulder polygons")
    keep_p = np.nonzero(~drop)[0]
    tri_poly = np.repeat(np.arange(npol), np.diff(off) - 2)
    if len(tri_poly) != len(m.triangles):
        raise ValueError("the model's triangles are not its polygons' fans in order")
    keep_t = ~drop[tri_poly]
    tri_new = np.full(len(m.triangles), -1, np.int64)
    tri_new[keep_t] = np.arange(int(keep_t.sum()))
    # every bust polygon (its copies of the head's shoulder polygons are the replacements)
    bust_polys, bust_puv = b.polys, b.poly_uvs
    U0 = len(m.uvs)
    pi = [m.poly_indices[off[i]:off[i + 1]] for i in keep_p] + [idx[p] for p in bust_polys]
    pu = [m.poly_uv[off[i]:off[i + 1]] for i in keep_p] + [U0 + u for u in bust_puv]
    out.template = tpl
    out.identity_basis = ib
    out.expression_basis = eb
    out.skin_weights = sw
    out.triangles = np.concatenate([np.asarray(m.triangles)[keep_t], idx[b.triangles]]).astype(np.int32)
    out.tri_uv = np.concatenate([np.asarray(m.tri_uv)[keep_t], U0 + b.tri_uv]).astype(np.int32)
    out.poly_offsets = np.concatenate([[0], np.cumsum([len(p) for p in pi])]).astype(np.int32)
    out.poly_indices = np.concatenate(pi).astype(np.int32)
    out.poly_uv = np.concatenate(pu).astype(np.int32)
    out.uvs = np.concatenate([m.uvs, b.uvs]).astype(np.float32)
    lm = {}
    for k, (t, bary) in m.landmarks.items():
        t2 = tri_new[np.asarray(t)]
        if np.any(t2 < 0):
            raise ValueError(f"landmark set {k} lies on a replaced shoulder polygon")
        lm[k] = (t2.astype(np.int32), bary)
    out.landmarks = lm
    arm = (b.weights[:, 2] + b.weights[:, 4]) >= ARM_WEIGHT
    reg = dict(m.regions)
    reg["bust"] = np.sort(idx).astype(np.int32)
    reg["torso"] = np.sort(idx[~arm]).astype(np.int32)
    reg["arm_l"] = np.sort(idx[b.weights[:, 2] >= ARM_WEIGHT]).astype(np.int32)
    reg["arm_r"] = np.sort(idx[b.weights[:, 4] >= ARM_WEIGHT]).astype(np.int32)
    reg["bust_bottom"] = idx[b.bottom_loop].astype(np.int32)
    for s, _ in SIDES:
        reg[f"elbow_{s.lower()}"] = idx[b.elbow_loops[s]].astype(np.int32)
    for k in ("shoulders", "skin"):
        if k in reg:
            reg[k] = np.concatenate([np.asarray(reg[k]), idx[new]]).astype(np.int32)
    out.regions = reg
    extra = dict(m.extra)
    if "mirror" in extra:
        mir = np.concatenate([np.asarray(extra["mirror"]), np.zeros(len(new), np.int64)])
        mir[idx[new]] = idx[b.mirror[new]]
        extra["mirror"] = mir.astype(int).tolist()
    extra["bust"] = {"vertices": int(len(new)), "first_vertex": V0, "polygons_replaced": int(drop.sum()),
                     "polygons_added": len(bust_polys), "clearance": b.info.get("clearance"),
                     "arm_turn_deg": b.info.get("arm_turn_deg"),
                     "turn": [float(x) for x in b.turn]}
    out.extra = extra
    prov = dict(m.provenance)
    prov["bust"] = ("MakeHuman hm08 upper body (waist and elbow edge loops), arms lowered by LBS with the mpfb2 "
                    "standard rig's weights, identity basis regressed on the head codes, arm clearance baked "
                    "(synth.model.builders.makehuman.bust)")
    prov["vertices"] = Vn
    prov["triangles"] = int(len(out.triangles))
    prov["polygons"] = int(len(pi))
    out.provenance = prov
    out.name = m.name + "+bust" if name is None else name
    return out
