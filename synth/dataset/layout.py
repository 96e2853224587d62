"""Names and paths of a dataset directory (docs/shard-format.md).

::

    DIR/
      dataset.json          plan hash, expected shards -> frame keys, meta, created, versions
      index.json            committed shards and their manifests' sha256, with a digest over them
      .commits/<shard>.json the commit record: the manifest's sha256, signed by the commit itself
      .lock                 flock for dataset-wide updates (dataset.json creation, index)
      logs/                 worker and task logs of `synth render` (one file per attempt)
      plan/                 the plan ``synth render`` made (docs/plan-format.md)
      shards/<shard>/       committed, read-only: KEY.exr, KEY.json, manifest.json
      shards/<shard>.tar    or, with dataset.shard_format = "tar", one tar of them and its
      shards/<shard>.tar.json  manifest (synth.dataset.tarshard)
      .staging/<shard>/     in progress (same files, no manifest yet)
      .staging/<shard>.lease claim of the process rendering that shard (synth.dataset.lease)
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import os
import re
import stat
from contextlib import contextmanager
from pathlib import Path

from synth.errors import SynthError

DATASET_FORMAT = "synth-dataset/1"
SHARD_FORMAT = "synth-shard/1"
INDEX_FORMAT = "synth-index/1"

DATASET_FILE = "dataset.json"
INDEX_FILE = "index.json"
LOCK_FILE = ".lock"
LOGS_DIR = "logs"
SHARDS_DIR = "shards"
STAGING_DIR = ".staging"
COMMITS_DIR = ".commits"
MANIFEST_FILE = "manifest.json"

#: Bounds on the files synth reads from a dataset: a larger one is refused, never read.
MAX_DATASET_JSON_BYTES = 1 << 30  # dataset.json lists every frame key (~25 bytes each)
MAX_INDEX_BYTES = 256 << 20
MAX_MANIFEST_BYTES = 64 << 20
MAX_FRAME_JSON_BYTES = 16 << 20
MAX_EXR_BYTES = 2 << 30
MAX_LEASE_BYTES = 64 << 10
MAX_RECORD_BYTES = 64 << 10

SHARD_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,127}$")
#: ``id{identity:06d}_ex{expression:02d}_v{view:02d}``; in a plan of more than one environment per
#: expression, ``id{identity:06d}_ex{expression:02d}_en{environment:02d}_v{view:02d}``.
FRAME_KEY_RE = re.compile(r"^id(\d{6})_ex(\d{2})(?:_en(\d{2}))?_v(\d{2})$")


def entry_kind(path: Path) -> str | None:
    """What is at ``path`` without following a symbolic link: ``"dir"``, ``"file"`` (regular),
    ``"symlink"``, ``"other"`` (device, FIFO, socket) or ``None`` (nothing)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    if stat.S_ISDIR(mode):
        return "dir"
    if stat.S_ISREG(mode):
        return "file"
    return "symlink" if stat.S_ISLNK(mode) else "other"


#: :func:`entry_kind` in words, for messages ("X is a symbolic link").
KIND_TEXT = {"dir": "directory", "file": "regular file", "symlink": "symbolic link",
             "other": "device, FIFO or socket"}


def utc_now() -> str:
    """A timestamp for records (``created``); never used as a seed."""
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def frame_key(identity: int, expression: int, view: int, environment: int | None = None) -> str:
    """``id{identity:06d}_ex{expression:02d}_v{view:02d}`` (sortable, zero-padded); with an
    ``environment`` (plans of more than one environment per expression, every frame has one)
    ``id{identity:06d}_ex{expression:02d}_en{environment:02d}_v{view:02d}``."""
    if not (0 <= identity <= 999999 and 0 <= expression <= 99 and 0 <= view <= 99
            and (environment is None or 0 <= environment <= 99)):
        raise SynthError(f"frame indices out of range (identity {identity}, expression {expression}, view {view}"
                         + ("" if environment is None else f", environment {environment}") + ")",
                         None, "identity must be < 1e6, expression, environment and view < 100")
    env = "" if environment is None else f"_en{environment:02d}"
    return f"id{identity:06d}_ex{expression:02d}{env}_v{view:02d}"


def frame_keys(identity: int, expression: int, views: int, environment: int | None = None) -> list[str]:
    """``[frame_key(identity, expression, v, environment) for v in range(views)]``, the range
    checked once (the planner makes 585,000 keys for 1,500 identities)."""
    if views <= 0:
        return []
    head = frame_key(identity, expression, views - 1, environment)[:-2]
    return [f"{head}{v:02d}" for v in range(views)]


def parse_frame_key(key: str) -> tuple[int, int, int]:
    """(identity, expression, view) of a frame key; :class:`SynthError` for anything else
    (the environment: :func:`key_environment`)."""
    i, e, _, v = parse_frame_key_env(key)
    return i, e, v


def parse_frame_key_env(key: str) -> tuple[int, int, int, int]:
    """(identity, expression, environment, view) of a frame key (environment 0 when the key
    names none); :class:`SynthError` for anything else."""
    m = FRAME_KEY_RE.match(key) if isinstance(key, str) else None
    if not m:
        raise SynthError(f"bad frame key {key!r}", None, "keys look like id000042_ex07_v13 or id000042_ex07_en01_v13")
    return int(m[1]), int(m[2]), int(m[3] or 0), int(m[4])


def key_environment(key: str) -> int:
    """The environment index of a frame key (0 when it names none)."""
    return parse_frame_key_env(key)[2]


def held_out(keys: list[str], n: int, setting: str, where: str) -> list[bool]:
    """Which of the frames ``keys`` are held out for evaluation: the ``n`` highest view indices
    of each (identity, expression, environment), the split the prior trains with
    (``data.holdout_views``) and the nerfstudio export writes (``--val-views``). A scene with
    ``n`` views or fewer is refused (``setting`` names the option in the message)."""
    scenes: dict[tuple[int, int, int], list[tuple[int, int]]] = {}
    for pos, key in enumerate(keys):
        i, e, k, v = parse_frame_key_env(key)
        scenes.setdefault((i, e, k), []).append((v, pos))
    out = [False] * len(keys)
    if n <= 0:
        return out
    for (i, e, k), views in sorted(scenes.items()):
        if len(views) <= n:
            scene = f"identity {i} expression {e}" + (f" environment {k}" if k else "")
            raise SynthError(f"{scene} has {len(views)} view(s), not more than {setting} = {n}", where,
                             f"lower {setting} or render more views")
        for _, pos in sorted(views)[-n:]:
            out[pos] = True
    return out


def shard_name(index: int) -> str:
    """The shard id of shard ``index``: ``shard_{index:06d}``."""
    if not 0 <= index <= 999999:
        raise SynthError(f"shard index {index} out of range", None, "shard indices are below 1e6")
    return f"shard_{index:06d}"


def check_shard_id(shard_id: str) -> str:
    if not isinstance(shard_id, str) or not SHARD_ID_RE.match(shard_id):
        raise SynthError(f"bad shard id {shard_id!r}", None,
                         "shard ids are letters, digits, '_' and '-' (e.g. shard_000042)")
    return shard_id


def frame_files(key: str) -> tuple[str, str]:
    """The two files of a frame: ``(KEY.exr, KEY.json)``."""
    return f"{key}.exr", f"{key}.json"


def lease_path(root: Path, shard_id: str) -> Path:
    """``DIR/.staging/<shard>.lease``: the claim of the process rendering the shard."""
    return Path(root) / STAGING_DIR / f"{check_shard_id(shard_id)}.lease"


def shard_dir(root: Path, shard_id: str) -> Path:
    """``DIR/shards/<shard>`` (committed)."""
    return Path(root) / SHARDS_DIR / check_shard_id(shard_id)


def staging_dir(root: Path, shard_id: str) -> Path:
    """``DIR/.staging/<shard>`` (in progress)."""
    return Path(root) / STAGING_DIR / check_shard_id(shard_id)


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
