"""Asset classes and their catalogue, bpy-free (docs/assets.md).

- :mod:`synth.assets.classes`: THE registry of asset classes (name, seed slot, segmentation
  id, rig module, build order, generators, pack anchor);
- :mod:`synth.assets.catalogue`: reading and checking ``assets_manifest/`` (stops at the
  first defect; used at plan time);
- :mod:`synth.assets.packs`: the checks on external ``.blend`` packs (plan time, validation
  and the rig use the same functions);
- :mod:`synth.assets.validate`: ``synth assets validate``, every defect of a catalogue;
- :mod:`synth.assets.fit`: the numpy geometry of the rigs (garments, headwear, glasses,
  strands), tested without Blender.

Sampling assets per identity is planning: :mod:`synth.plan.assets`.
"""
