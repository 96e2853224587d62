"""Scalp hair: the strands are groomed in numpy (:mod:`synth.assets.fit.hair`); this rig makes
them a Blender Curves object (:class:`blender_scripts.assets.strands.StrandRig`)."""

from __future__ import annotations

from blender_scripts.assets.strands import StrandRig
from synth.assets.fit.hair import groom
from synth.assets.params import AssetPick


def build(ctx, entry: AssetPick) -> StrandRig:
    return StrandRig.build(ctx, groom(ctx, entry))
