"""MakeHuman targets (sparse per-vertex offsets of the hm08 mesh) as dense offsets of the model
vertices and joints. Eyeballs and joints are linear functions of the offsets, so they follow
every target exactly."""

from __future__ import annotations

import numpy as np

from synth.model.builders.makehuman.mesh import Mesh
from synth.model.builders.makehuman.skinning import JOINT_MIRROR, JOINT_NAMES


class TargetSpace:
    """Maps sparse hm08 target offsets to dense model-vertex and joint offsets (all linear)."""

    def __init__(self, mesh: Mesh, groups: dict[str, np.ndarray], P: np.ndarray):
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

    def base_joints(self, P: np.ndarray) -> np.ndarray:
        """(J, 3) joints of the base mesh: centres of the joint cubes and eye helpers."""
        return np.array([P[self.cubes[n]].mean(0) if n in self.cubes else P[self.eye_helpers[n]].mean(0)
                         for n in JOINT_NAMES])

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
