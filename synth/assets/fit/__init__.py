"""The numpy geometry of the asset rigs: no bpy, tested without Blender.

The Blender rigs (``blender_scripts/assets/``) call these and only build objects, materials
and node trees from the result.

- shells fitted to the body (garments, headwear): :mod:`.body` (the body, parts, the fit and
  binding), :mod:`.garment` and :mod:`.garment_parts`, :mod:`.headwear`, on top of
  :mod:`.meshops` (clipping, subdivision, tubes, ...) and :mod:`.attach` (closest point,
  push-out, binding);
- strands (hair, beard, eyebrows, eyelashes): :mod:`.strands` (head surface, growth, curls,
  resampling), :mod:`.groom` (what a strand rig builds; attachment), one groom module per
  class (:mod:`.hair`, :mod:`.beard`, :mod:`.eyebrows`, :mod:`.eyelashes`);
- glasses: :mod:`.glasses` (frame geometry, contact, pose solve);
- shader layers: :mod:`.masks` (per-vertex masks of makeup and skin detail), :mod:`.eyes`
  (polar coordinates on the eyeballs for the iris).

Closest points, signed distances and ray casting come from :mod:`synth.geometry`.

Randomness comes only from the generator the rig passes in (``ctx.rng(cls)``,
:func:`synth.assets.classes.rig_rng`).
"""
