"""What a run keeps about its identities (saved in every checkpoint; enough to render): the
dataset identity index of each latent id, its bounding sphere, a front camera and the
conditioning code of each (identity, expression). Built by :mod:`prior.data.prepare`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.errors import SynthError


@dataclass
class IdentityInfo:
    """What a run keeps about its identities (saved in checkpoints; enough to render)."""

    identity_index: np.ndarray  # (M,) int64: dataset identity index of latent id m
    centre: np.ndarray  # (M, 3) float64: bounding sphere centres (world, metres)
    radius: np.ndarray  # (M,) float64; 0 for an identity of the plan not committed yet (never trained)
    front_K: np.ndarray  # (M, 3, 3) float64
    front_c2w: np.ndarray  # (M, 4, 4) float64
    front_size: np.ndarray  # (M, 2) int64: width, height of the front camera's image
    code_keys: np.ndarray  # (Q, 2) int64: (latent id, expression index) of each row of ``codes``
    codes: np.ndarray  # (Q, C) float32: conditioning code of each (identity, expression)

    def latent_id(self, identity_index: int) -> int:
        hits = np.nonzero(self.identity_index == int(identity_index))[0]
        if hits.size == 0:
            raise SynthError(f"identity {identity_index} is not in this run (it has "
                             f"{_short(self.identity_index.tolist())})", "--identity", "pick a trained identity")
        if not self.radius[hits[0]] > 0:
            raise SynthError(f"identity {identity_index} was not rendered yet when this checkpoint was written",
                             "--identity", "pick a trained identity (synth prior info lists them)")
        return int(hits[0])

    def code(self, latent_id: int, expression_index: int) -> np.ndarray:
        hit = np.nonzero((self.code_keys[:, 0] == latent_id) & (self.code_keys[:, 1] == int(expression_index)))[0]
        if hit.size == 0:
            have = self.code_keys[self.code_keys[:, 0] == latent_id, 1].tolist()
            raise SynthError(f"expression {expression_index} of identity {int(self.identity_index[latent_id])} is "
                             f"not in this run (it has {_short(have)})", "--expression", "pick a trained expression")
        return self.codes[int(hit[0])]

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.ascontiguousarray(getattr(self, k)) for k in self.__dataclass_fields__}


def _short(xs: list) -> str:
    return ", ".join(map(str, xs[:8])) + (", ..." if len(xs) > 8 else "")
