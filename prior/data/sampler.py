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
would have. With a buffer that holds every identity of the rank, every identity of the rank
(``r, r + world, ...``) is drawn from at every step.
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
    """origins, directions, near, far of flat ``pixels`` (G, V, P) of frames ``frames`` (G, V) of
    identity ``data[g]`` (G identity draws of V frames each)."""
    H, W = size
    G, V, P = pixels.shape
    K = np.concatenate([x.K[f] for x, f in zip(data, frames)])
    c2w = np.concatenate([x.c2w[f] for x, f in zip(data, frames)])
    rows, cols = np.divmod(pixels.reshape(G * V, P), W)
    r = camera_rays(K, c2w, W, H, pixels=(rows, cols))
    ids = np.array([x.latent for x in data], np.int64)
    o, d = r.origins.reshape(-1, 3), r.directions.reshape(-1, 3)
    near, far = intersect_sphere(o, d, np.repeat(centre[ids], V * P, axis=0), np.repeat(radius[ids], V * P))
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
        """(the identity of each draw (G,), frame indices within it (G, V), flat pixels (G, V, P)) of one
        micro-batch."""
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
            frames.append(rng.choice(tf, size=self.V, replace=self.V > tf.size))
            data.append(d)
        frames = np.stack(frames)
        H, W = self.loader.table.size
        pixels = rng.integers(0, H * W, size=(frames.size, self.P)).reshape(self.I, self.V, self.P)
        if self.n_fg:
            u = rng.random((frames.size, self.n_fg)).reshape(self.I, self.V, self.n_fg)
            for g, d in enumerate(data):
                lo, hi = d.fg_offsets[frames[g]], d.fg_offsets[frames[g] + 1]
                count = hi - lo
                if not d.fg_pixels.size:
                    continue
                pick = lo[:, None] + np.minimum((u[g] * count[:, None]).astype(np.int64), np.maximum(count - 1, 0)[:, None])
                fgp = d.fg_pixels[np.minimum(pick, d.fg_pixels.size - 1)]
                pixels[g, :, :self.n_fg] = np.where(count[:, None] > 0, fgp, pixels[g, :, :self.n_fg])
        return data, frames, pixels

    def batch(self, step: int, micro: int = 0) -> Batch:
        data, frames, pixels = self.draw(step, micro)
        t = self.loader.table
        H, W = t.size
        o, d, near, far = rays_for(data, frames, pixels, t.size, t.info.centre, t.info.radius)
        G, V, P = pixels.shape
        rgba = np.empty((G, V, P, 4), np.float32)
        codes = np.empty((G, V, t.layout.size), np.float32)
        K = np.empty((G, V, 3, 3))
        for g, x in enumerate(data):
            rgba[g] = x.rgba.reshape(len(x.rgba), H * W, 4)[frames[g][:, None], pixels[g]]
            codes[g], K[g] = x.codes[frames[g]], x.K[frames[g]]
        latent = np.repeat(np.array([x.latent for x in data], np.int64), V * P)
        return Batch(origins=o, directions=d, near=near, far=far,
                     radii=np.repeat(pixel_radius(K).reshape(-1), P).astype(np.float32),
                     codes=np.repeat(codes.reshape(G * V, -1), P, axis=0), latent_ids=latent,
                     rgba=rgba.reshape(-1, 4), frames=np.repeat(frames.reshape(-1), P), pixels=pixels.reshape(-1))

    def step_done(self) -> None:
        """Tell the buffer what this step drew (it may swap identities)."""
        drawn = np.concatenate(self.drawn) if self.drawn else np.zeros(0, np.int64)
        self.drawn = []
        self.loader.advance(drawn, self.V)
