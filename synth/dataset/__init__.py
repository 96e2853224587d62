"""The dataset side of rendering: shards, atomic commits, the index, validation and previews.

Public API (also re-exported by :mod:`synth.shards`): :func:`open_dataset`,
:func:`load_dataset`, :class:`Dataset`, :class:`StagingShard`, :func:`shard_name`.
Formats: docs/shard-format.md and docs/frame-format.md.
"""

# Resolved lazily so that importing a leaf module (e.g. synth.dataset.fsio, which
# synth.frames uses) does not import the shard machinery, which imports synth.frames back.
_EXPORTS = {
    "shard_name": "synth.dataset.layout",
    "Dataset": "synth.dataset.shards", "load_dataset": "synth.dataset.shards", "open_dataset": "synth.dataset.shards",
    "ShardBusy": "synth.dataset.staging", "ShardCommitted": "synth.dataset.staging",
    "StagingShard": "synth.dataset.staging",
}


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'synth.dataset' has no attribute {name!r}")


__all__ = ["Dataset", "ShardBusy", "ShardCommitted", "StagingShard", "load_dataset", "open_dataset", "shard_name"]
