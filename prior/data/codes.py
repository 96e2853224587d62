"""The conditioning code of a frame: ``beta || psi``.

Layout (sizes read from the dataset, never assumed)::

    [ identity code beta (I) | expression code (E) | joint rotation j_1 (3) | ... | j_k (3) ]
      \\_____ beta ________/  \\__________________________ psi ____________________________/

``beta`` is the head model's identity code, the expression code and the axis-angle rotations
(radians) of the face-shaping joints (``data.joints``; default jaw, eye_l, eye_r) form ``psi``.
The learned latent ``w`` is not part of this code: the model looks it up in its codebook.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.errors import SynthError


@dataclass(frozen=True)
class CodeLayout:
    identity_size: int
    expression_size: int
    joints: tuple[str, ...]

    @property
    def size(self) -> int:
        return self.identity_size + self.expression_size + 3 * len(self.joints)

    @property
    def psi_size(self) -> int:
        return self.size - self.identity_size

    def slices(self) -> dict[str, slice]:
        """Name -> slice of the code vector: ``beta``, ``expression`` and one per joint."""
        out = {"beta": slice(0, self.identity_size)}
        o = self.identity_size
        out["expression"] = slice(o, o + self.expression_size)
        o += self.expression_size
        for j in self.joints:
            out[j] = slice(o, o + 3)
            o += 3
        return out

    @classmethod
    def of_frame(cls, frame, joints: tuple[str, ...]) -> "CodeLayout":
        missing = [j for j in joints if j not in frame.joint_rotations]
        if missing:
            raise SynthError(f"frame has no rotation for joint(s) {', '.join(missing)} (it has: "
                             f"{', '.join(frame.joint_rotations) or 'none'})", frame.key,
                             "set data.joints to joints the dataset records")
        return cls(int(frame.identity_code.size), int(frame.expression_code.size), tuple(joints))

    def code(self, frame) -> np.ndarray:
        """The (size,) float32 code of a frame; its sizes must match this layout."""
        beta, expr = frame.identity_code.reshape(-1), frame.expression_code.reshape(-1)
        if (beta.size, expr.size) != (self.identity_size, self.expression_size):
            raise SynthError(f"frame codes have sizes identity {beta.size}, expression {expr.size}; the run has "
                             f"{self.identity_size}, {self.expression_size}", frame.key,
                             "use one head model for the whole dataset")
        parts = [beta, expr]
        for j in self.joints:
            r = frame.joint_rotations.get(j)
            if r is None or np.asarray(r).size != 3:
                raise SynthError(f"frame lacks a 3-vector rotation for joint {j!r}", frame.key,
                                 "set data.joints to joints every frame records")
            parts.append(np.asarray(r, np.float32).reshape(3))
        out = np.concatenate(parts).astype(np.float32)
        if not np.isfinite(out).all():
            raise SynthError("frame codes hold NaN or Inf", frame.key, "re-render the frame")
        return out

    def to_dict(self) -> dict:
        return {"identity_size": self.identity_size, "expression_size": self.expression_size,
                "joints": list(self.joints), "size": self.size}

    @classmethod
    def from_dict(cls, d: dict) -> "CodeLayout":
        return cls(int(d["identity_size"]), int(d["expression_size"]), tuple(d["joints"]))
