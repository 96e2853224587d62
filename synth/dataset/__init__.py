"""The dataset side of rendering: shards, atomic commits, the index, validation and previews.

Public API (also re-exported by :mod:`synth.shards`): :func:`open_dataset`,
:func:`load_dataset`, :class:`Dataset`, :class:`StagingShard`, :func:`shard_name`.
Formats: docs/shard-format.md and docs/frame-format.md.
"""

from synth.dataset.layout import shard_name
from synth.dataset.shards import Dataset, load_dataset, open_dataset
from synth.dataset.staging import ShardBusy, ShardCommitted, StagingShard

__all__ = ["Dataset", "ShardBusy", "ShardCommitted", "StagingShard", "load_dataset", "open_dataset", "shard_name"]
