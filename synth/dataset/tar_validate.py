"""``synth validate`` for a tar shard (:mod:`synth.dataset.tarshard`; docs/shard-format.md).

Checks, in order, reading each byte at most once and never more than the manifest allows:

- the manifest ``<id>.tar.json``: as for a directory shard (parses, names the shard, agrees
  with the index and the plan, lists both files of every frame), plus a ``container`` entry
  naming ``<id>.tar`` with its size and sha256;
- the tar: a regular file (not a link), of the manifest's size and sha256 (the hash not with
  ``--quick``);
- its members, walked header by header (:func:`synth.dataset.tarshard.iter_members`): regular
  files only, flat ``KEY.exr`` / ``KEY.json`` names (no ``..``, no absolute paths, no
  directories), sizes within bounds; each listed in the manifest, once, at the manifest's
  offset, with its size and sha256, in name order (so WebDataset sees a frame's two files
  together); a member's data is read only when the manifest lists it with that size;
- each frame's JSON and EXR, from the member bytes, exactly as for a directory shard.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from synth.dataset.tarshard import CONTAINER_FORMAT, TarRefused, iter_members, tar_manifest_path, tar_path
from synth.dataset.validate import Defect, check_frame_data, check_manifest
from synth.io import sha256_bytes, sha256_file


def _container_ok(c, name: str) -> bool:
    return (isinstance(c, dict) and c.get("format") == CONTAINER_FORMAT and c.get("file") == name
            and isinstance(c.get("sha256"), str) and isinstance(c.get("bytes"), int) and c["bytes"] >= 0)


def validate_tar_shard(root, shard: str, expected_keys: list[str] | None, quick: bool, index_entry: dict | None,
                       has_index: bool = True) -> tuple[list[Defect], list[Defect], int]:
    """Check one committed tar shard; returns (defects, warnings, frames checked)."""
    root = Path(root)
    mp, tp = tar_manifest_path(root, shard), tar_path(root, shard)
    m, defects, warnings = check_manifest(mp, shard, expected_keys, index_entry, has_index)
    if m is None:
        return defects, warnings, 0
    c = m.get("container")
    if not _container_ok(c, tp.name):
        defects.append(Defect(shard, None, "manifest", f"{mp.name} lacks a valid 'container' entry "
                                                       f"(format tar, file {tp.name}, sha256, bytes)"))
        return defects, warnings, 0
    try:
        st = os.lstat(tp)
    except FileNotFoundError:
        return defects + [Defect(shard, None, "missing-file", f"{tp.name} is missing")], warnings, 0
    if not stat.S_ISREG(st.st_mode):
        return defects + [Defect(shard, None, "tar", f"{tp.name} is not a regular file (a link or a device?)")], \
            warnings, 0
    if st.st_size != c["bytes"]:
        defects.append(Defect(shard, None, "checksum", f"{tp.name} is {st.st_size} bytes, manifest says {c['bytes']}"))
    elif not quick and sha256_file(tp) != c["sha256"]:
        defects.append(Defect(shard, None, "checksum", f"{tp.name} sha256 differs from the manifest"))
    d, checked = _check_members(tp, shard, m["files"], quick)
    return defects + d, warnings, checked


def _check_members(tp: Path, shard: str, listed: dict, quick: bool) -> tuple[list[Defect], int]:
    defects: list[Defect] = []
    seen: list[str] = []  # member names in tar order
    seen_set: set[str] = set()
    pending: dict[str, dict[str, bytes]] = {}
    checked = 0

    def wanted(name: str, size: int) -> bool:  # read only what the manifest lists, with its size
        return name in listed and name not in seen_set and listed[name]["bytes"] == size

    try:
        fd = os.open(tp, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        with os.fdopen(fd, "rb") as f:
            for mem in iter_members(f, f"{shard}/{tp.name}", select=wanted):
                n, key = mem.name, mem.key
                if n in seen_set:
                    defects.append(Defect(shard, key, "tar", f"{n} is in the tar more than once"))
                    continue
                seen.append(n)
                seen_set.add(n)
                ent = listed.get(n)
                if ent is None:
                    defects.append(Defect(shard, key, "extra-file", f"{n} is in the tar but not in the manifest"))
                    continue
                if mem.data is None:
                    defects.append(Defect(shard, key, "checksum", f"{n} is {mem.size} bytes, manifest says "
                                                                  f"{ent['bytes']}"))
                    continue
                if not quick and sha256_bytes(mem.data) != ent["sha256"]:
                    defects.append(Defect(shard, key, "checksum", f"{n} sha256 differs from the manifest"))
                if "offset" in ent and ent["offset"] != mem.offset:
                    defects.append(Defect(shard, key, "manifest", f"{n} is at byte {mem.offset} of the tar, "
                                                                  f"manifest says {ent['offset']}"))
                parts = pending.setdefault(key, {})
                parts[n.rpartition(".")[2]] = mem.data
                if len(parts) == 2:
                    del pending[key]
                    defects.extend(check_frame_data(shard, key, parts["json"], parts["exr"]))
                    checked += 1
    except TarRefused as e:
        defects.append(Defect(shard, None, "tar", e.what))
    except OSError as e:
        defects.append(Defect(shard, None, "io", f"cannot read {tp.name}: {e.strerror or e}"))
    for n in sorted(set(listed) - seen_set):
        defects.append(Defect(shard, n.rsplit(".", 1)[0], "missing-file", f"{n} is listed but not in {tp.name}"))
    if seen != sorted(seen):
        defects.append(Defect(shard, None, "tar", "members are not in name order (WebDataset needs a frame's two "
                                                  "files next to each other)"))
    return defects, checked
