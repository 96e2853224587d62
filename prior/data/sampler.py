"""Training batches: identities x views x pixels, every draw a function of (seed, step, micro-batch, rank).

For step ``s``, micro-batch ``m`` and rank ``r`` the sampler draws, with a generator seeded by
``(seed, s, m, r)``:

1. ``identities`` latent ids from the rank's shard (ids ``r, r + world, ...``), without
   replacement while the shard has enough;
2. for each, ``views`` of its training frames (any expression, held-out views never), without
   replacement while it has enough;
3. for each frame, ``pixels`` pixels: ``round(pixels * foreground_fraction)`` uniformly among its
   foreground pixels (alpha > 0; uniform over the image when it has none), the rest uniformly
   over the image.

Nothing depends on earlier steps, so a resumed run draws exactly the batches it would have.
Rays go through pixel centres (:func:`synth.dataset.reader.camera_rays`) and are cut to the
identity's bounding sphere; ``near == far`` marks a ray that misses it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from prior.data.bounds import intersect_sphere
from prior.data.store import FrameStore
from synth.dataset.reader import camera_rays
from synth.errors import SynthError

#: first word of every sampler seed (other streams of a run use other words)
BATCH_STREAM = 0xBA7C


@dataclass
class Batch:
    origins: np.ndarray  # (N, 3) float32
    directions: np.ndarray  # (N, 3) float32, unit
    near: np.ndarray  # (N,) float32
    far: np.ndarray  # (N,) float32
    radii: np.ndarray  # (N,) float32: cone radius at unit distance, 2 / sqrt(12) / fx (mip-NeRF)
    codes: np.ndarray  # (N, C) float32
    latent_ids: np.ndarray  # (N,) int64
    rgba: np.ndarray  # (N, 4) float32: premultiplied colour and alpha
    frames: np.ndarray  # (N,) int64: index into the store
    pixels: np.ndarray  # (N,) int64: flat pixel index (row * W + col)

    def __len__(self) -> int:
        return int(self.near.shape[0])


def pixel_radius(K: np.ndarray) -> np.ndarray:
    """mip-NeRF's cone radius at unit distance for cameras ``K`` (..., 3, 3): a pixel's width
    (1 / fx) times 2 / sqrt(12)."""
    return (2.0 / np.sqrt(12.0)) / np.asarray(K)[..., 0, 0]


def rays_for(store: FrameStore, frames: np.ndarray, pixels: np.ndarray):
    """origins, directions, near, far of flat ``pixels`` (F, P) of ``frames`` (F,)."""
    H, W = store.size
    F, P = pixels.shape
    o = np.empty((F, P, 3), np.float32)
    d = np.empty((F, P, 3), np.float32)
    for i, f in enumerate(frames.tolist()):
        rows, cols = np.divmod(pixels[i], W)
        r = camera_rays(store.K[f], store.c2w[f], W, H, pixels=(rows, cols))
        o[i], d[i] = r.origins, r.directions
    ids = store.latent[frames]
    centre = np.repeat(store.identities.centre[ids], P, axis=0)
    radius = np.repeat(store.identities.radius[ids], P)
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    near, far = intersect_sphere(o, d, centre, radius)
    return o, d, near.astype(np.float32), far.astype(np.float32)


class RaySampler:
    def __init__(self, store: FrameStore, *, seed: int, identities: int, views: int, pixels: int,
                 foreground_fraction: float = 0.0, rank: int = 0, world: int = 1):
        self.store, self.seed = store, int(seed)
        self.I, self.V, self.P = int(identities), int(views), int(pixels)
        self.n_fg = int(round(self.P * float(foreground_fraction)))
        self.rank, self.world = int(rank), int(world)
        M = len(store.identities.identity_index)
        self.shard = np.arange(self.rank, M, self.world)
        if self.shard.size == 0:
            raise SynthError(f"rank {rank} of {world} has no identity ({M} in the dataset)", "torchrun",
                             "use at most as many ranks as identities")
        train_frames = np.nonzero(store.train)[0]
        self.frames_of = {m: train_frames[store.latent[train_frames] == m] for m in self.shard.tolist()}
        empty = [int(store.identities.identity_index[m]) for m, fr in self.frames_of.items() if fr.size == 0]
        if empty:
            raise SynthError(f"identity {empty[0]} has no training view left", "data.holdout_views",
                             "lower data.holdout_views")

    @property
    def rays_per_batch(self) -> int:
        return self.I * self.V * self.P

    def rng(self, step: int, micro: int = 0) -> np.random.Generator:
        return np.random.default_rng([BATCH_STREAM, self.seed, int(step), int(micro), self.rank])

    def draw(self, step: int, micro: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(frames (F,), flat pixels (F, P)) of one micro-batch."""
        rng = self.rng(step, micro)
        ids = rng.choice(self.shard, size=self.I, replace=self.I > self.shard.size)
        frames = np.concatenate([rng.choice(self.frames_of[m], size=self.V, replace=self.V > self.frames_of[m].size)
                                 for m in ids.tolist()])
        H, W = self.store.size
        pixels = rng.integers(0, H * W, size=(frames.size, self.P))
        if self.n_fg and self.store.fg_pixels.size:
            lo, hi = self.store.fg_offsets[frames], self.store.fg_offsets[frames + 1]
            count = hi - lo
            u = rng.random((frames.size, self.n_fg))
            pick = lo[:, None] + np.minimum((u * count[:, None]).astype(np.int64), np.maximum(count - 1, 0)[:, None])
            fgp = self.store.fg_pixels[np.minimum(pick, self.store.fg_pixels.size - 1)]
            pixels[:, :self.n_fg] = np.where(count[:, None] > 0, fgp, pixels[:, :self.n_fg])
        return frames, pixels

    def batch(self, step: int, micro: int = 0) -> Batch:
        frames, pixels = self.draw(step, micro)
        st = self.store
        o, d, near, far = rays_for(st, frames, pixels)
        H, W = st.size
        rgba = st.rgba.reshape(len(st.rgba), H * W, 4)[frames[:, None], pixels].reshape(-1, 4).astype(np.float32)
        fr = np.repeat(frames, self.P)
        radii = np.repeat(pixel_radius(st.K[frames]), self.P).astype(np.float32)
        return Batch(origins=o, directions=d, near=near, far=far, radii=radii, codes=st.codes[fr], latent_ids=st.latent[fr],
                     rgba=rgba, frames=fr, pixels=pixels.reshape(-1))
