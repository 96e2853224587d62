"""Training batches: identities x views x pixels, every draw a function of (seed, step, micro-batch, rank)
and of the identities the rank's buffer holds (:mod:`prior.data.stream`).

For step ``s``, micro-batch ``m`` and rank ``r`` the sampler draws, with a generator seeded by
``(seed, s, m, r)``:

1. ``identities`` latent ids among those the buffer holds (ascending), without replacement while
   it holds enough;
2. for each, ``views`` of its training frames (any expression, held-out views never), without
   replacement while it has enough;
3. for each frame, ``pixels`` pixels: ``round(pixels * foreground_fraction)`` uniformly among its
   foreground pixels (alpha > 0; uniform over the image when it has none), the rest uniformly
   over the image.

The buffer's contents are part of the checkpoint, so a resumed run draws exactly the batches it
would have. With a buffer that holds every identity of the rank the draws are those of the
former in-memory store (identities ``r, r + world, ...``).
Rays go through pixel centres (:func:`synth.dataset.reader.camera_rays`) and are cut to the
identity's bounding sphere; ``near == far`` marks a ray that misses it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from prior.data.bounds import intersect_sphere
from prior.data.stream import IdentityData, Loader
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
    frames: np.ndarray  # (N,) int64: frame index within its identity (IdentityData)
    pixels: np.ndarray  # (N,) int64: flat pixel index (row * W + col)

    def __len__(self) -> int:
        return int(self.near.shape[0])


def pixel_radius(K: np.ndarray) -> np.ndarray:
    """mip-NeRF's cone radius at unit distance for cameras ``K`` (..., 3, 3): a pixel's width
    (1 / fx) times 2 / sqrt(12)."""
    return (2.0 / np.sqrt(12.0)) / np.asarray(K)[..., 0, 0]


def rays_for(data: list[IdentityData], frames: np.ndarray, pixels: np.ndarray, size: tuple[int, int], centre,
             radius):
    """origins, directions, near, far of flat ``pixels`` (F, P) of frame ``frames[i]`` of ``data[i]``."""
    H, W = size
    F, P = pixels.shape
    o = np.empty((F, P, 3), np.float32)
    d = np.empty((F, P, 3), np.float32)
    for i, f in enumerate(frames.tolist()):
        rows, cols = np.divmod(pixels[i], W)
        r = camera_rays(data[i].K[f], data[i].c2w[f], W, H, pixels=(rows, cols))
        o[i], d[i] = r.origins, r.directions
    ids = np.array([x.latent for x in data], np.int64)
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    near, far = intersect_sphere(o, d, np.repeat(centre[ids], P, axis=0), np.repeat(radius[ids], P))
    return o, d, near.astype(np.float32), far.astype(np.float32)


class RaySampler:
    def __init__(self, loader: Loader, *, seed: int, identities: int, views: int, pixels: int,
                 foreground_fraction: float = 0.0, rank: int = 0):
        self.loader, self.seed = loader, int(seed)
        self.I, self.V, self.P = int(identities), int(views), int(pixels)
        self.n_fg = int(round(self.P * float(foreground_fraction)))
        self.rank = int(rank)
        #: latent ids drawn since the last :meth:`step_done` (one per identity draw)
        self.drawn: list[np.ndarray] = []

    @property
    def rays_per_batch(self) -> int:
        return self.I * self.V * self.P

    def rng(self, step: int, micro: int = 0) -> np.random.Generator:
        return np.random.default_rng([BATCH_STREAM, self.seed, int(step), int(micro), self.rank])

    def draw(self, step: int, micro: int = 0) -> tuple[list[IdentityData], np.ndarray, np.ndarray]:
        """(identity of each frame, frame index within it (F,), flat pixels (F, P)) of one micro-batch."""
        rng = self.rng(step, micro)
        slots = self.loader.slots
        ids = rng.choice(slots, size=self.I, replace=self.I > slots.size)
        self.drawn.append(ids)
        data, frames = [], []
        for m in ids.tolist():
            d = self.loader.held[m]
            tf = d.train_frames
            if tf.size == 0:
                raise SynthError(f"identity {int(self.loader.table.info.identity_index[m])} has no training view left",
                                 "data.holdout_views", "lower data.holdout_views")
            pick = rng.choice(tf, size=self.V, replace=self.V > tf.size)
            data += [d] * self.V
            frames.append(pick)
        frames = np.concatenate(frames)
        H, W = self.loader.table.size
        pixels = rng.integers(0, H * W, size=(frames.size, self.P))
        if self.n_fg:
            lo = np.array([d.fg_offsets[f] for d, f in zip(data, frames.tolist())], np.int64)
            hi = np.array([d.fg_offsets[f + 1] for d, f in zip(data, frames.tolist())], np.int64)
            count = hi - lo
            u = rng.random((frames.size, self.n_fg))
            pick = np.minimum((u * count[:, None]).astype(np.int64), np.maximum(count - 1, 0)[:, None])
            fgp = np.stack([d.fg_pixels[np.minimum(lo[i] + pick[i], max(d.fg_pixels.size - 1, 0))]
                            if d.fg_pixels.size else np.zeros(self.n_fg, np.int64) for i, d in enumerate(data)])
            pixels[:, :self.n_fg] = np.where(count[:, None] > 0, fgp, pixels[:, :self.n_fg])
        return data, frames, pixels

    def batch(self, step: int, micro: int = 0) -> Batch:
        data, frames, pixels = self.draw(step, micro)
        t = self.loader.table
        H, W = t.size
        o, d, near, far = rays_for(data, frames, pixels, t.size, t.info.centre, t.info.radius)
        rgba = np.stack([x.rgba[f].reshape(H * W, 4)[p] for x, f, p in zip(data, frames.tolist(), pixels)])
        latent = np.array([x.latent for x in data], np.int64)
        codes = np.stack([x.codes[f] for x, f in zip(data, frames.tolist())])
        K = np.stack([x.K[f] for x, f in zip(data, frames.tolist())])
        return Batch(origins=o, directions=d, near=near, far=far,
                     radii=np.repeat(pixel_radius(K), self.P).astype(np.float32),
                     codes=np.repeat(codes, self.P, axis=0), latent_ids=np.repeat(latent, self.P),
                     rgba=rgba.reshape(-1, 4).astype(np.float32), frames=np.repeat(frames, self.P),
                     pixels=pixels.reshape(-1))

    def step_done(self) -> None:
        """Tell the buffer what this step drew (it may swap identities)."""
        drawn = np.concatenate(self.drawn) if self.drawn else np.zeros(0, np.int64)
        self.drawn = []
        self.loader.advance(drawn, self.V)
