"""The bottom layer of synth: files written crash-safely, strict JSON, sha256, the cache folder.

One home each, used by every package (dataset, model, plan, assets, cli) and by
``blender_scripts``, ``renderer_jobs`` and ``prior``; nothing here imports the rest of synth.

- :mod:`synth.io.files`: temporary names, fsync, atomic file and directory creation;
- :mod:`synth.io.jsonio`: strict JSON (no NaN/Infinity) to and from bytes, atomic JSON files;
- :mod:`synth.io.hashing`: sha256 of bytes and of files (optionally fsyncing while reading);
- :mod:`synth.io.cache`: the per-user cache folder (``SYNTH_CACHE_DIR`` overrides it).
"""

from synth.io.cache import cache_dir
from synth.io.files import (atomic_dir, atomic_place, atomic_write_bytes, fsync_dir, fsync_file, is_temp_name,
                            temp_name)
from synth.io.hashing import file_digest, sha256_bytes, sha256_file
from synth.io.jsonio import atomic_write_json, dumps_json, loads_json

__all__ = ["atomic_dir", "atomic_place", "atomic_write_bytes", "atomic_write_json", "cache_dir", "dumps_json",
           "file_digest", "fsync_dir", "fsync_file", "is_temp_name", "loads_json", "sha256_bytes", "sha256_file",
           "temp_name"]
