"""The five joints of the model and their skin weights, merged from MakeHuman's standard rig;
single-joint linear blend skinning for the jaw split."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from synth.model.builders.makehuman.mesh import Mesh

JOINT_NAMES = ("neck", "head", "jaw", "eye_l", "eye_r")
JOINT_PARENTS = (-1, 0, 1, 1, 1)
JOINT_MIRROR = (0, 1, 2, 4, 3)  # index of each joint's mirror image (eye_l <-> eye_r)
NECK_BONES = ("neck01", "neck02", "neck03")


def skin_weights(data: Path, mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
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


def lbs_single(x: np.ndarray, w: np.ndarray, R: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Skin x (n,3) with one joint (centre c, rotation R, weights w (n,)) and identity elsewhere."""
    return x + w[:, None] * ((x - c) @ (R - np.eye(3)).T)


def rot_x(t: float) -> np.ndarray:
    """Rotation matrix about +X by ``t`` radians."""
    c, s = np.cos(t), np.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
