"""Decoded frames of a dataset held in memory for training.

:func:`load_store` reads every committed frame once (``synth.dataset.reader``) and keeps:

- ``rgba`` (N, H, W, 4): premultiplied colour and alpha as stored (float16 keeps the EXR's
  HALF values exactly; float32 on request);
- per frame: camera (``K``, ``camera_to_world``), identity / expression / view indices, the
  dense latent id of its identity, its conditioning code (:mod:`prior.data.codes`), whether it
  is held out, and the flat indices of its foreground pixels (for foreground-weighted sampling);
- per identity (latent id order): the dataset's identity index, its bounding sphere
  (:mod:`prior.data.bounds`) and a "front" camera (the view nearest azimuth 0 / elevation 0)
  for orbit renders.

Memory: 8 bytes per pixel in float16 (16 in float32) plus ~4 bytes per foreground pixel; 2
identities x 2 expressions x 30 views at 64^2 take 2 MB, 1,500 x 13 x 30 at 64^2 take 19 GB
(``docs/prior.md``: at paper scale the frames must be streamed instead).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from prior.data.bounds import bounding_sphere, foreground_points
from prior.data.codes import CodeLayout
from synth.dataset.layout import held_out
from synth.dataset.reader import list_frames
from synth.errors import SynthError


@dataclass
class IdentityInfo:
    """What a run keeps about its identities (saved in checkpoints; enough to render)."""

    identity_index: np.ndarray  # (M,) int64: dataset identity index of latent id m
    centre: np.ndarray  # (M, 3) float64: bounding sphere centres (world, metres)
    radius: np.ndarray  # (M,) float64
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


@dataclass
class FrameStore:
    layout: CodeLayout
    identities: IdentityInfo
    keys: list[str]
    rgba: np.ndarray  # (N, H, W, 4)
    K: np.ndarray  # (N, 3, 3) float64
    c2w: np.ndarray  # (N, 4, 4) float64
    latent: np.ndarray  # (N,) int64
    expression: np.ndarray  # (N,) int64
    view: np.ndarray  # (N,) int64
    codes: np.ndarray  # (N, C) float32
    train: np.ndarray  # (N,) bool: False for held-out views
    fg_offsets: np.ndarray  # (N + 1,) int64 into fg_pixels
    fg_pixels: np.ndarray  # flat (row * W + col) indices of foreground pixels, int32
    head_model: dict | None = None  # the head model the frames were rendered with: name, sha256 (frame JSON)

    @property
    def size(self) -> tuple[int, int]:
        """(height, width) of every frame."""
        return int(self.rgba.shape[1]), int(self.rgba.shape[2])

    @property
    def nbytes(self) -> int:
        return int(self.rgba.nbytes + self.fg_pixels.nbytes + self.codes.nbytes)


def _front_score(meta: dict) -> float:
    cam = meta.get("camera", {})
    try:
        return abs(float(cam["azimuth_deg"])) + abs(float(cam["elevation_deg"]))
    except (KeyError, TypeError, ValueError):
        return float("inf")


def load_store(dataset, *, joints: tuple[str, ...], holdout_views: int = 0, margin: float = 0.05,
               pixel_dtype: str = "float16", progress=None) -> FrameStore:
    """Decode every committed frame of ``dataset`` (see the module docstring)."""
    refs = list_frames(dataset)
    if not refs:
        raise SynthError("dataset has no committed frames", str(dataset),
                         "render it first (synth render ... --out DIR) or pass the --out directory of a render")
    # checked before anything is decoded
    train = ~np.array(held_out([r.key for r in refs], holdout_views, "data.holdout_views", str(dataset)), bool)
    dt = np.dtype(pixel_dtype)
    layout = head_model = None
    rgba = K = c2w = None
    ids, exprs, views, codes, fg, keys = [], [], [], [], [], []
    points: dict[int, list[np.ndarray]] = {}
    front: dict[int, tuple[float, int]] = {}
    for n, ref in enumerate(refs):
        f = ref.read()
        if layout is None:
            layout = CodeLayout.of_frame(f, joints)
            head_model = {k: f.meta.get("model", {}).get(k) for k in ("name", "sha256")}
            H, W = f.height, f.width
            rgba = np.empty((len(refs), H, W, 4), dt)
            K, c2w = np.empty((len(refs), 3, 3)), np.empty((len(refs), 4, 4))
        if (f.height, f.width) != (H, W):
            raise SynthError(f"frame is {f.width}x{f.height}, the first frame {W}x{H}", str(ref.json_path),
                             "train on a dataset rendered at one resolution")
        rgba[n] = f.rgba
        K[n], c2w[n] = f.K, f.camera_to_world
        ident = f.identity_index
        ids.append(ident)
        exprs.append(f.expression_index)
        views.append(f.view_index)
        codes.append(layout.code(f))
        fg.append(np.flatnonzero(f.alpha.reshape(-1) > 0).astype(np.int32))
        keys.append(f.key)
        points.setdefault(ident, []).append(foreground_points(f).astype(np.float32))
        score = _front_score(f.meta)
        if ident not in front or score < front[ident][0]:
            front[ident] = (score, n)
        if progress is not None:
            progress(n + 1, len(refs))
    ids_a, exprs_a, views_a = (np.asarray(x, np.int64) for x in (ids, exprs, views))
    uniq = np.unique(ids_a)
    latent = np.searchsorted(uniq, ids_a)

    centre, radius = np.zeros((len(uniq), 3)), np.zeros(len(uniq))
    for m, ident in enumerate(uniq.tolist()):
        pts = np.concatenate(points.pop(ident))
        if len(pts) == 0:
            raise SynthError(f"identity {ident} has no foreground depth pixel in any frame", str(dataset),
                             "check the renders (synth preview): the head must be visible")
        centre[m], radius[m] = bounding_sphere(pts, margin)

    codes_a = np.stack(codes)
    pairs, first = np.unique(np.stack([latent, exprs_a], 1), axis=0, return_index=True)
    fronts = [front[i][1] for i in uniq.tolist()]
    info = IdentityInfo(identity_index=uniq, centre=centre, radius=radius, front_K=K[fronts], front_c2w=c2w[fronts],
                        front_size=np.tile([W, H], (len(uniq), 1)).astype(np.int64), code_keys=pairs.astype(np.int64),
                        codes=codes_a[first])
    offsets = np.concatenate([[0], np.cumsum([len(x) for x in fg])]).astype(np.int64)
    return FrameStore(layout=layout, identities=info, keys=keys, rgba=rgba, K=K, c2w=c2w, latent=latent,
                      expression=exprs_a, view=views_a, codes=codes_a, train=train, fg_offsets=offsets,
                      fg_pixels=np.concatenate(fg) if fg else np.zeros(0, np.int32), head_model=head_model)
