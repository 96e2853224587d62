"""The expression basis: the 52 ARKit face units (then, on request, MakeHuman's expression units)
as blendshapes of the model vertices. jawOpen is split into a jaw rotation and a residual
blendshape; gaze units become eye-joint rotations (the eyeballs stay rigid)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.errors import SynthError
from synth.geometry.rotations import fit_rigid, matrix_to_axis_angle
from synth.model.builders.makehuman.mesh import Mesh
from synth.model.builders.makehuman.skinning import JOINT_NAMES, lbs_single, rot_x
from synth.model.builders.makehuman.sources import check_files, read_target

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


def expression_specs(data: Path, expression_dims: int | None) -> list[tuple[str, list[Path]]]:
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
    check_files([p for _, paths in specs[:k] for p in paths], "expression target")
    return specs[:k]


def expression_space(specs: list[tuple[str, list[Path]]], mesh: Mesh, template: np.ndarray,
                     weights: np.ndarray, joint_rest: np.ndarray, groups: dict[str, np.ndarray], P: np.ndarray):
    """(names, basis (K, V, 3), joint rotation per unit for the extra metadata)."""
    V, nk = len(mesh.base), len(mesh.kept)
    names, basis, rotations = [], [], {}
    J = {n: i for i, n in enumerate(JOINT_NAMES)}
    for name, paths in specs:
        full = np.zeros((len(P), 3))
        for p in paths:  # MakeHuman expression units: mean of the three ethnic variants
            idx, off = read_target(p)
            np.add.at(full, idx, off / len(paths))
        d = np.zeros((V, 3))
        d[:nk] = full[mesh.kept]  # eyeball vertices stay zero: eyes are rigid
        if name in GAZE_UNITS:  # gaze: fit the rotation of the eye helper, give it to the eye joint
            side = GAZE_UNITS[name]
            hv = groups["helper-l-eye" if side == "eye_l" else "helper-r-eye"]
            R, _ = fit_rigid(P[hv], P[hv] + full[hv])
            rotations[name] = {side: matrix_to_axis_angle(R).round(6).tolist()}
        if name == "jawOpen":
            d, theta = split_jaw_open(template, d, weights[:, J["jaw"]], joint_rest[J["jaw"]])
            rotations[name] = {"jaw": [round(theta, 6), 0.0, 0.0]}
        names.append(name)
        basis.append(d)
    return names, np.stack(basis), rotations


def split_jaw_open(template: np.ndarray, d: np.ndarray, w_jaw: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, float]:
    """Split the sculpted jawOpen offsets d into a rotation of the jaw joint about +X (fitted
    on the vertices skinned mostly to the jaw) and a residual blendshape r, such that
    skinning template + r with that rotation reproduces template + d exactly."""
    from scipy.optimize import minimize_scalar

    rigid = w_jaw > 0.9
    x, y = template[rigid], template[rigid] + d[rigid]

    def err(t):
        return float(np.sum((lbs_single(x, w_jaw[rigid], rot_x(t), c) - y) ** 2))

    theta = float(minimize_scalar(err, bounds=(0.0, 1.0), method="bounded", options={"xatol": 1e-6}).x)
    R = rot_x(theta)
    # per-vertex skinning matrix M_v = I + w_v (R - I) acting on (x - c); invert it on the target
    M = np.eye(3)[None] + w_jaw[:, None, None] * (R - np.eye(3))[None]
    target = template + d - c
    r = np.linalg.solve(M, target[..., None])[..., 0] + c - template
    return r, theta
