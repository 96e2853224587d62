"""Procedural headwear (``procedural:headwear_shell``): beanie and baseball cap, the Blender side.

The geometry (cut plane, crown shell, rim, pompom, brim, the fit to the skull and the
binding) is numpy in :mod:`synth.assets.fit.headwear`; the mesh object (segmentation class
``headwear``, pass index 11) and cloth materials come from the garment rig's helpers.
"""

from __future__ import annotations

from blender_scripts.assets import HeadContext, Rig
from blender_scripts.assets.garment import shell_rig
from synth.assets.fit.body import Body, fit_shell
from synth.assets.fit.headwear import CLEARANCE, headwear_shell
from synth.assets.params import AssetPick


def build(ctx: HeadContext, entry: AssetPick) -> Rig:
    body = Body.of(ctx)
    return shell_rig(fit_shell(body, headwear_shell(body, entry, ctx.rng("headwear")), CLEARANCE))
