"""What a run keeps about its identities (saved in every checkpoint; enough to render): the
dataset identity index of each latent id, its bounding sphere, a front camera and the
conditioning code of each (identity, expression). Built by :mod:`prior.data.prepare`."""

from __future__ import annotations

from dataclasses import dataclass, field

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
    #: (Q, C) float32: conditioning code of each (identity, expression); or None, with the
    #: identity part once per latent id in ``identity_codes`` (M, I) and the rest per row in
    #: ``psi_codes`` (Q, C - I): what a run holds when every expression of an identity has the
    #: same identity code (the identity code is most of a row: 48 of 60 numbers for the default)
    codes: np.ndarray | None = None
    identity_codes: np.ndarray | None = field(default=None, repr=False)
    psi_codes: np.ndarray | None = field(default=None, repr=False)

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
        q = int(hit[0])
        if self.codes is not None:
            return self.codes[q]
        return np.concatenate([self.identity_codes[latent_id], self.psi_codes[q]])

    def full_codes(self) -> np.ndarray:
        """The (Q, C) codes, one full row per (identity, expression)."""
        if self.codes is not None:
            return self.codes
        return np.concatenate([self.identity_codes[self.code_keys[:, 0]], self.psi_codes], 1)

    def arrays(self) -> dict[str, np.ndarray]:
        """What a checkpoint stores (:data:`SAVED`; ``codes`` as full rows)."""
        return {k: np.ascontiguousarray(self.full_codes() if k == "codes" else getattr(self, k)) for k in SAVED}


#: the fields a checkpoint stores, as ``identities.<name>``
SAVED = ("identity_index", "centre", "radius", "front_K", "front_c2w", "front_size", "code_keys", "codes")


def _short(xs: list) -> str:
    return ", ".join(map(str, xs[:8])) + (", ..." if len(xs) > 8 else "")
