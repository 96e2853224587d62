"""The bottom layer of synth: files written crash-safely, strict JSON, sha256, the cache folder.

One home each, used by every package (dataset, model, plan, assets, cli) and by
``blender_scripts``, ``renderer_jobs`` and ``prior``; nothing here imports the rest of synth.

- :mod:`synth.io.files`: temporary names, fsync, atomic file and directory creation, bounded
  reads of regular files;
- :mod:`synth.io.jsonio`: strict, depth- and size-bounded JSON to and from bytes and files;
- :mod:`synth.io.hashing`: sha256 of bytes and of files (optionally fsyncing while reading);
- :mod:`synth.io.cache`: the per-user cache folder (``SYNTH_CACHE_DIR`` overrides it).
"""

from synth.io.cache import cache_dir
from synth.io.files import (DirectoryTaken, FileRefused, atomic_dir, atomic_place, atomic_write_bytes, created_dirs,
                            fsync_dir, fsync_file, is_temp_name, open_regular, read_bounded, temp_name)
from synth.io.hashing import file_digest, sha256_bytes, sha256_file
from synth.io.jsonio import JSONError, atomic_write_json, dumps_json, loads_json, read_json

__all__ = ["DirectoryTaken", "FileRefused", "JSONError", "atomic_dir", "atomic_place", "atomic_write_bytes",
           "atomic_write_json", "cache_dir", "created_dirs", "dumps_json", "file_digest", "fsync_dir", "fsync_file",
           "is_temp_name", "loads_json", "open_regular", "read_bounded", "read_json", "sha256_bytes", "sha256_file",
           "temp_name"]
