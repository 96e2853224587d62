"""Exports of a rendered dataset to the formats other tools read (docs/export.md).

- :mod:`synth.export.nerfstudio`: nerfstudio's ``transforms.json`` with PNG colour, masks and
  depth (``synth export nerfstudio``);
- :mod:`synth.export.cafca`: the Cafca release's folder layout (``synth export cafca``);
- :mod:`synth.export.usd`: a USD stage of one shard, the head (and the built meshes of the
  shell assets) per expression as time samples and a camera per view (``synth export usd``;
  needs ``usd-core``, the ``export`` extra);
- :mod:`synth.export.select`: which committed frames an export covers.

Every camera conversion comes from :mod:`synth.conventions`.
"""
