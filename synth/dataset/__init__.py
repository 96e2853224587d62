"""The dataset format: everything a render writes and a training job reads.

Modules, bottom to top (each imports only from its own line and the lines above):

- ``layout``: names and paths (frame keys, shard names); crash-safe writes come from ``synth.io``
- ``segmentation``, ``labels``, ``exr``, ``exr_check``, ``frame_json``: the two files of a
  frame (docs/frame-format.md) and the labels in them
- ``index``, ``staging``, ``shards``: shards, atomic commits, the index (docs/shard-format.md)
- ``validate``, ``preview``: ``synth validate`` and ``synth preview``

Nothing here imports from ``synth.plan``, ``synth.cli``, ``synth.render`` or ``blender_scripts``.
"""
