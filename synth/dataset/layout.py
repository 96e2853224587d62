"""Names and paths of a dataset directory (docs/shard-format.md).

::

    DIR/
      dataset.json          plan hash, expected shards -> frame keys, meta, created, versions
      plan.json             copy of the plan (when the render command passes one)
      index.json            committed shards (derived from the manifests; rebuildable)
      .lock                 flock for dataset-wide updates (dataset.json creation, index)
      shards/<shard>/       committed, read-only: KEY.exr, KEY.json, manifest.json
      .staging/<shard>/     in progress (same files, no manifest yet)
      .staging/<shard>.lock flock held by the process rendering that shard
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import os
import re
from contextlib import contextmanager
from pathlib import Path

from synth.errors import SynthError

DATASET_FORMAT = "synth-dataset/1"
SHARD_FORMAT = "synth-shard/1"
INDEX_FORMAT = "synth-index/1"

DATASET_FILE = "dataset.json"
PLAN_FILE = "plan.json"
INDEX_FILE = "index.json"
LOCK_FILE = ".lock"
SHARDS_DIR = "shards"
STAGING_DIR = ".staging"
MANIFEST_FILE = "manifest.json"

SHARD_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,127}$")


def utc_now() -> str:
    """A timestamp for records (``created``); never used as a seed."""
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def shard_name(index: int) -> str:
    """The recommended shard id: ``shard_{index:06d}``."""
    return f"shard_{index:06d}"


def check_shard_id(shard_id: str) -> str:
    if not isinstance(shard_id, str) or not SHARD_ID_RE.match(shard_id):
        raise SynthError(f"bad shard id {shard_id!r}", None,
                         "shard ids are letters, digits, '_' and '-' (e.g. shard_000042)")
    return shard_id


def frame_files(key: str) -> tuple[str, str]:
    return f"{key}.exr", f"{key}.json"


@contextmanager
def flock(path: Path, *, blocking: bool = True):
    """Hold an exclusive ``fcntl.flock`` on ``path`` (created if needed).

    The kernel drops the lock when the process dies, so a kill -9 never leaves a stale lock.
    Raises :class:`BlockingIOError` when ``blocking`` is false and another process holds it.
    """
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if blocking else fcntl.LOCK_NB))
        try:
            yield fd
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)
