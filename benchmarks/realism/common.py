"""What several realism measurements share: the ITA categories, the planned heads, frames as 8-bit images."""

from __future__ import annotations

from pathlib import Path

import numpy as np

CATS = ("very light", "light", "intermediate", "tan", "brown", "dark")


HEAD_NOT_SKIN = (2, 3, 4, 5, 6, 7, 8, 10, 11)  # synth.dataset.segmentation.CLASSES, skin = 1


def _cat(ita):
    from synth.appearance.skin import ita_category

    return ita_category(ita)


def planned_options(p, identities: int, resolution: int | None = None):
    """The options of a measurement on planned identities, added to the (sub)parser ``p``:
    ``--identities`` (the first N planned ones, default ``identities``), ``--seed`` (0) and, where
    ``resolution`` is given, ``--resolution`` (the render size that sets strand counts)."""
    p.add_argument("--identities", type=int, default=identities)
    p.add_argument("--seed", type=int, default=0)
    if resolution is not None:
        p.add_argument("--resolution", type=int, default=resolution)
    return p


def _planned_heads(seed: int, n: int, ids=None):
    """(model, HeadModel, identity indices, identity codes) of the first n planned identities
    (or of the identities ``ids``)."""
    from synth.config import load_config
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from synth.plan import identities

    model = load_default_model()
    cfg = load_config()
    ids = np.arange(n) if ids is None else np.asarray(ids, np.int64)
    codes = identities.sample_identities(seed, ids, identities.prior_of(model),
                                         identities.truncation_radius(model.identity_dims, cfg.identity))
    return model, HeadModel(model, np.float64), ids, codes


def _neutral_context(model, hm, code, identity: int, seed: int, resolution: int, assets: dict):
    """(the rigs' HeadContext of an identity's neutral head, its evaluation)."""
    from blender_scripts.assets import HeadContext

    ev = hm.evaluate(code, np.zeros(model.expression_dims), np.zeros((hm.J, 3)))
    verts = ev.vertices[0]
    ctx = HeadContext(data=model, head=None, materials={}, rest_vertices=verts, vertices=verts,
                      joint_transforms=ev.joint_transforms[0], joint_index=dict(hm.joint_index),
                      landmarks={k: v[0] for k, v in ev.landmarks.items()}, resolution=resolution,
                      identity_index=identity, run_seed=seed, assets=assets)
    return ctx, ev


def _srgb8(fr) -> np.ndarray:
    """(H, W, 3) uint8 sRGB of a frame composited over mid grey."""
    from synth.appearance.srgb import srgb8

    return srgb8(fr.rgb_premultiplied + (1.0 - fr.alpha[..., None]) * 0.5)  # composited in linear


def _png(fr, path: Path) -> None:
    from PIL import Image

    Image.fromarray(_srgb8(fr)).save(path)
