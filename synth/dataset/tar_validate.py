"""``synth validate`` for a tar shard (:mod:`synth.dataset.tarshard`; docs/shard-format.md).

Checks, in order, reading each byte at most once and never more than the manifest allows:

- the manifest ``<id>.tar.json``: as for a directory shard (``synth.dataset.validate``: parses,
  names the shard, agrees with the index and the plan, lists both files of every frame), plus a
  ``container`` entry naming ``<id>.tar`` with its size and sha256;
- the tar: a regular file (``lstat``: never a link, a FIFO or a device), of the manifest's
  size and sha256 (the hash not with ``--quick``; never reading more than that size);
- its members, walked header by header (:func:`synth.dataset.tarshard.iter_members`): regular
  files only, flat ``KEY.exr`` / ``KEY.json`` names (no ``..``, no absolute paths, no
  directories), sizes within bounds; each listed in the manifest, once, at the manifest's
  offset, with its size and sha256, in name order (so WebDataset sees a frame's two files
  together); a member's data is read only when the manifest lists it with that size, and a
  frame JSON only up to the bound a directory shard's has (``MAX_FRAME_JSON_BYTES``);
- each frame's JSON and EXR, from the member bytes, exactly as for a directory shard (the
  caller's ``check_frame``).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from synth.dataset.layout import KIND_TEXT, MAX_FRAME_JSON_BYTES, entry_kind
from synth.dataset.tarshard import CONTAINER_FORMAT, TarRefused, iter_members, tar_path
from synth.io import file_digest, open_regular, sha256_bytes

#: A finding: (frame key or None, defect kind, message); ``synth.dataset.validate`` makes
#: them its ``Defect``s (this module does not import it: validate calls into here).
Finding = tuple


def check_tar_shard(root, shard: str, manifest: dict, quick: bool,
                    check_frame: Callable[[str, bytes, bytes], None]) -> tuple[list[Finding], int]:
    """Check a tar shard whose manifest (``<id>.tar.json``) has been read and checked already:
    the container entry, the tar, its members; ``check_frame(key, json_bytes, exr_bytes)`` is
    called for each frame whose two members are intact. Returns (findings, frames checked)."""
    tp = tar_path(root, shard)
    c = manifest.get("container")
    if not (isinstance(c, dict) and c.get("format") == CONTAINER_FORMAT and c.get("file") == tp.name
            and isinstance(c.get("sha256"), str) and isinstance(c.get("bytes"), int) and c["bytes"] >= 0):
        return [(None, "manifest", f"{tp.name}.json lacks a valid 'container' entry (format tar, file {tp.name}, "
                                   "sha256, bytes)")], 0
    kind = entry_kind(tp)
    if kind is None:
        return [(None, "missing-file", f"{tp.name} is missing")], 0
    if kind != "file":
        return [(None, "tar", f"{tp.name} is a {KIND_TEXT[kind]}, not a regular file (not read)")], 0
    found: list[Finding] = []
    size = os.lstat(tp).st_size
    if size != c["bytes"]:
        found.append((None, "checksum", f"{tp.name} is {size} bytes, manifest says {c['bytes']}"))
    elif not quick:
        try:
            digest, _ = file_digest(tp, max_bytes=c["bytes"], follow_symlinks=False)
        except (OSError, ValueError) as e:
            return found + [(None, "io", f"{tp.name} cannot be read: {e}")], 0
        if digest != c["sha256"]:
            found.append((None, "checksum", f"{tp.name} sha256 differs from the manifest"))
    more, checked = _check_members(Path(tp), shard, manifest["files"], quick, check_frame)
    return found + more, checked


def _check_members(tp: Path, shard: str, listed: dict, quick: bool,
                   check_frame: Callable[[str, bytes, bytes], None]) -> tuple[list[Finding], int]:
    found: list[Finding] = []
    seen: list[str] = []  # member names in tar order
    seen_set: set[str] = set()
    pending: dict[str, dict[str, bytes]] = {}
    checked = 0

    def wanted(name: str, size: int) -> bool:  # read only what the manifest lists, with its size (bounded)
        return name in listed and name not in seen_set and listed[name]["bytes"] == size \
            and not (name.endswith(".json") and size > MAX_FRAME_JSON_BYTES)

    try:
        fd, _ = open_regular(tp, follow_symlinks=False)
        with os.fdopen(fd, "rb") as f:
            for mem in iter_members(f, f"{shard}/{tp.name}", select=wanted):
                n, key = mem.name, mem.key
                if n in seen_set:
                    found.append((key, "tar", f"{n} is in the tar more than once"))
                    continue
                seen.append(n)
                seen_set.add(n)
                ent = listed.get(n)
                if ent is None:
                    found.append((key, "extra-file", f"{n} is in the tar but not in the manifest"))
                    continue
                if mem.data is None and mem.size != ent["bytes"]:
                    found.append((key, "checksum", f"{n} is {mem.size} bytes, manifest says {ent['bytes']}"))
                    continue
                if mem.data is None:
                    found.append((key, "json", f"{n} is {mem.size} bytes, more than the {MAX_FRAME_JSON_BYTES} "
                                               "allowed for a frame JSON (not read)"))
                    continue
                if not quick and sha256_bytes(mem.data) != ent["sha256"]:
                    found.append((key, "checksum", f"{n} sha256 differs from the manifest"))
                if "offset" in ent and ent["offset"] != mem.offset:
                    found.append((key, "manifest", f"{n} is at byte {mem.offset} of the tar, manifest says "
                                                   f"{ent['offset']}"))
                parts = pending.setdefault(key, {})
                parts[n.rpartition(".")[2]] = mem.data
                if len(parts) == 2:
                    del pending[key]
                    check_frame(key, parts["json"], parts["exr"])
                    checked += 1
    except TarRefused as e:
        found.append((None, "tar", e.what))
    except (OSError, ValueError) as e:  # ValueError: FileRefused (replaced since the lstat)
        found.append((None, "io", f"cannot read {tp.name}: {getattr(e, 'strerror', None) or e}"))
    for n in sorted(set(listed) - seen_set):
        found.append((n.rsplit(".", 1)[0], "missing-file", f"{n} is listed but not in {tp.name}"))
    if seen != sorted(seen):
        found.append((None, "tar", "members are not in name order (WebDataset needs a frame's two files next to "
                                   "each other)"))
    return found, checked
