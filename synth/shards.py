"""Shards and datasets (docs/shard-format.md). The implementation lives in :mod:`synth.dataset`.

    from synth.shards import open_dataset
    ds = open_dataset(out_dir, plan_hash, expected={"shard_000000": ["id000000_ex00_v00", ...]}, meta={...})
"""

from synth.dataset.index import rebuild_index, update_index
from synth.dataset.layout import shard_name
from synth.dataset.shards import Dataset, load_dataset, open_dataset
from synth.dataset.staging import ShardBusy, ShardCommitted, StagingShard

__all__ = ["Dataset", "ShardBusy", "ShardCommitted", "StagingShard", "load_dataset", "open_dataset", "rebuild_index",
           "shard_name", "update_index"]
