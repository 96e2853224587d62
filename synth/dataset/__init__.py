"""The dataset format: everything a render writes and a training job reads.

Modules, bottom to top (each imports only from its own line and the lines above):

- ``layout``: names and paths (frame keys, shard names); crash-safe writes come from ``synth.io``
- ``segmentation``, ``labels``, ``exr``, ``exr_check``, ``frame_json``: the two files of a
  frame (docs/frame-format.md) and the labels in them
- ``tarshard``, ``index``, ``staging``, ``shards``: shards, atomic commits, the index, the tar
  form of a shard (docs/shard-format.md)
- ``reader``, ``defects``, ``validate``, ``tar_validate``, ``validate_index``, ``preview``: the
  training-side reader (docs/reading.md), ``synth validate`` (of both shard forms; the index
  and commit records, and ``--repair-index``, in ``validate_index``) and ``synth preview``

Nothing here imports from ``synth.plan``, ``synth.cli``, ``synth.render`` or ``blender_scripts``.
"""
