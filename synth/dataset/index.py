"""``DIR/index.json``: the committed shards, each with the sha256 of its manifest, signed at commit.

A commit adds its shard's entry to the index (under the dataset lock) *before* it renames the
staging directory into ``shards/``, and holds the lock until the rename is done (see
:func:`commit_shard`). So the index is never behind the files, and it is written only by a
commit, never from what happens to be on disk:

- a shard directory the index does not list was not committed by synth (or the index was
  lost): nothing adds it automatically;
- an entry whose manifest changed after commit is never re-signed: ``synth validate`` reports
  the change, and a rerun of the render cannot launder it;
- an index-less dataset with committed shards stays index-less (``synth validate`` fails)
  until the explicit, logged repair :func:`repair_index` (``synth validate --repair-index``)
  rebuilds it from the manifests and reports every change.

:func:`update_index` (run when a dataset is opened for writing) only forgets entries whose
shard directory is gone (deleted to be re-rendered, or a commit killed between the two
steps) and creates the empty index of a new dataset. The index also holds ``digest``: the
sha256 over every ``shard_id manifest_sha256`` line, one number that changes when any
committed shard does (docs/reliability.md).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path

from synth.dataset.layout import (INDEX_FILE, INDEX_FORMAT, LOCK_FILE, MANIFEST_FILE, MAX_INDEX_BYTES,
                                  MAX_MANIFEST_BYTES, SHARD_FORMAT, SHARD_ID_RE, SHARDS_DIR, entry_kind, flock)
from synth.errors import SynthError
from synth.io import FileRefused, atomic_write_json, loads_json, read_bounded, read_json, sha256_bytes

_SHA256 = re.compile(r"^[0-9a-f]{64}$")
REPAIR_HINT = "run `synth validate --repair-index DIR` to rebuild it from the manifests (it reports what changed)"


class ManifestError(ValueError):
    pass


class IndexDamaged(ValueError):
    """``index.json`` exists but is not a valid index (reason in the message)."""


def _is_count(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def parse_manifest(data: bytes, shard_id: str) -> dict:
    """Parse and sanity-check a manifest's bytes; raises :class:`ManifestError`."""
    try:
        m = loads_json(data)
    except ValueError as e:
        raise ManifestError(f"manifest.json does not parse: {e}") from None
    if not isinstance(m, dict) or m.get("format") != SHARD_FORMAT:
        raise ManifestError(f"manifest.json is not a {SHARD_FORMAT} manifest")
    if m.get("shard_id") != shard_id:
        raise ManifestError(f"manifest.json names shard {str(m.get('shard_id'))[:80]!r}, not {shard_id!r}")
    if not isinstance(m.get("frames"), list) or not isinstance(m.get("files"), dict) \
            or not all(isinstance(k, str) for k in m["frames"]):
        raise ManifestError("manifest.json lacks a 'frames' list of keys or a 'files' object")
    for name, ent in m["files"].items():
        if "/" in name or "\\" in name or "\0" in name or name.startswith(".") or name == MANIFEST_FILE:
            raise ManifestError(f"manifest.json lists an invalid file name {name[:80]!r}")
        if not isinstance(ent, dict) or not isinstance(ent.get("sha256"), str) or not _is_count(ent.get("bytes")):
            raise ManifestError(f"manifest.json entry for {name!r} lacks sha256/bytes")
    return m


def read_manifest_bytes(shard_dir: Path) -> bytes:
    """``shard_dir/manifest.json``: a regular file (never a symlink) of bounded size. Raises
    OSError (FileNotFoundError when absent) or ManifestError."""
    try:
        return read_bounded(Path(shard_dir) / MANIFEST_FILE, MAX_MANIFEST_BYTES, follow_symlinks=False)
    except FileRefused as e:
        raise ManifestError(f"manifest.json {e.what}") from None


def index_entry(shard_dir: Path) -> dict:
    """Read ``shard_dir/manifest.json`` into an index entry; raises OSError/ManifestError."""
    data = read_manifest_bytes(shard_dir)
    m = parse_manifest(data, Path(shard_dir).name)
    return manifest_entry(data, m)


def manifest_entry(data: bytes, manifest: dict) -> dict:
    """The index entry of a manifest (its bytes and their parse)."""
    return {"frames": len(manifest["frames"]), "bytes": sum(e["bytes"] for e in manifest["files"].values()),
            "manifest_sha256": sha256_bytes(data), "manifest_bytes": len(data), "committed": manifest.get("created")}


def dataset_digest(shards: dict) -> str:
    """sha256 over the lines ``shard_id manifest_sha256``, sorted: changes with any manifest."""
    return sha256_bytes("".join(f"{s} {shards[s]['manifest_sha256']}\n" for s in sorted(shards)).encode())


def _check_index(idx) -> dict:
    if not isinstance(idx, dict) or idx.get("format") != INDEX_FORMAT:
        raise IndexDamaged(f"not a {INDEX_FORMAT} file")
    if not isinstance(idx.get("plan_hash"), str) or not isinstance(idx.get("shards"), dict):
        raise IndexDamaged("lacks plan_hash or the shards object")
    for s, e in idx["shards"].items():
        if not SHARD_ID_RE.match(s):
            raise IndexDamaged(f"lists a bad shard id {s[:80]!r}")
        if not isinstance(e, dict) or not _SHA256.match(str(e.get("manifest_sha256"))) \
                or not all(_is_count(e.get(k)) for k in ("manifest_bytes", "frames", "bytes")):
            raise IndexDamaged(f"entry of {s} is not an object with manifest_sha256, manifest_bytes, frames, bytes")
    if "digest" in idx and not _SHA256.match(str(idx["digest"])):
        raise IndexDamaged("digest is not a sha256")
    return idx


def read_index(root: Path) -> dict | None:
    """The index as stored; ``None`` when there is none. Raises :class:`IndexDamaged` when it
    cannot be read or is not a valid index (a symlink, too large, bad JSON, bad entries)."""
    try:
        return _check_index(read_json(Path(root) / INDEX_FILE, max_bytes=MAX_INDEX_BYTES, follow_symlinks=False))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as e:
        raise IndexDamaged(str(e.strerror if isinstance(e, OSError) else e)) from None


def shard_entries(root: Path) -> dict[str, str]:
    """Every entry under ``shards/`` (not following links) -> its kind (:func:`entry_kind`)."""
    base = Path(root) / SHARDS_DIR
    try:
        names = os.listdir(base)
    except FileNotFoundError:
        return {}
    return {n: entry_kind(base / n) for n in sorted(names)}


def shard_dirs(root: Path) -> list[str]:
    """Names under ``shards/`` that are shard ids and real directories (no symlinks)."""
    return [n for n, k in shard_entries(root).items() if k == "dir" and SHARD_ID_RE.match(n)]


def _new_index(plan_hash: str, shards: dict) -> dict:
    shards = dict(sorted(shards.items()))
    return {"format": INDEX_FORMAT, "plan_hash": plan_hash, "num_shards": len(shards),
            "num_frames": sum(e["frames"] for e in shards.values()), "digest": dataset_digest(shards),
            "shards": shards}


def _index_for_writing(root: Path, plan_hash: str) -> dict:
    """The stored index, or a new empty one when there is none and nothing is committed;
    :class:`SynthError` when it is damaged, of another plan, or lost while shards exist."""
    where = str(Path(root) / INDEX_FILE)
    try:
        idx = read_index(root)
    except IndexDamaged as e:
        raise SynthError(f"index.json is damaged ({e})", where, REPAIR_HINT) from None
    if idx is None:
        if shard_dirs(root):
            raise SynthError("index.json is missing but shards/ holds committed shards", where, REPAIR_HINT)
        return _new_index(plan_hash, {})
    if idx["plan_hash"] != plan_hash:
        raise SynthError("index.json belongs to another plan", where, REPAIR_HINT)
    return idx


def commit_shard(root: Path, plan_hash: str, shard_id: str, entry: dict, rename: Callable[[], None], *,
                 durable: bool = True) -> dict:
    """Sign ``entry`` into the index, then ``rename()`` the shard into place, all under the
    dataset lock (so the index is never behind ``shards/``). If the rename fails the entry is
    taken out again. Returns the new index."""
    root = Path(root)
    with flock(root / LOCK_FILE):
        idx = _index_for_writing(root, plan_hash)
        shards = dict(idx["shards"])
        before = shards.get(shard_id)
        shards[shard_id] = entry
        new = _new_index(plan_hash, shards)
        atomic_write_json(root / INDEX_FILE, new, durable=durable)
        try:
            rename()
        except BaseException:
            if before is None:
                shards.pop(shard_id)
            else:
                shards[shard_id] = before
            atomic_write_json(root / INDEX_FILE, _new_index(plan_hash, shards), durable=durable)
            raise
    return new


def update_index(root: Path, plan_hash: str, *, durable: bool = True) -> dict:
    """Under the dataset lock: create the empty index of a new dataset, and forget entries
    whose shard directory is gone. Never adds or re-signs a shard. Raises :class:`SynthError`
    when the index is damaged, of another plan, or missing while shards exist."""
    root = Path(root)
    with flock(root / LOCK_FILE):
        exists = (root / INDEX_FILE).exists()
        idx = _index_for_writing(root, plan_hash)
        gone = [s for s in idx["shards"] if entry_kind(root / SHARDS_DIR / s) is None]
        if gone or not exists:
            shards = {s: e for s, e in idx["shards"].items() if s not in gone}
            idx = _new_index(plan_hash, shards)
            atomic_write_json(root / INDEX_FILE, idx, durable=durable)
    return idx


def repair_index(root: Path, plan_hash: str) -> tuple[dict, list[dict]]:
    """Rebuild ``index.json`` from the manifests of the shard directories (explicitly: this
    signs whatever the manifests now say). Returns the new index and the changes, each
    ``{"shard", "change": "added" | "removed" | "changed" | "skipped", ...}``; the index
    itself is ``"shard": None`` when it was missing or damaged."""
    root = Path(root)
    changes: list[dict] = []
    with flock(root / LOCK_FILE):
        try:
            old = read_index(root)
            if old is None:
                changes.append({"shard": None, "change": "added", "reason": "index.json was missing"})
            elif old["plan_hash"] != plan_hash:
                changes.append({"shard": None, "change": "changed", "reason": "index.json belonged to another plan"})
                old = None
        except IndexDamaged as e:
            changes.append({"shard": None, "change": "changed", "reason": f"index.json was damaged ({e})"})
            old = None
        before = (old or {}).get("shards", {})
        shards = {}
        for s in shard_dirs(root):
            try:
                shards[s] = index_entry(root / SHARDS_DIR / s)
            except (OSError, ManifestError) as e:
                changes.append({"shard": s, "change": "skipped", "reason": f"not indexed: {e}"})
        for s in sorted(set(before) | set(shards)):
            a, b = before.get(s), shards.get(s)
            if a is None and b is not None:
                changes.append({"shard": s, "change": "added", "new": b["manifest_sha256"]})
            elif b is None and a is not None:
                changes.append({"shard": s, "change": "removed", "old": a["manifest_sha256"]})
            elif a is not None and a["manifest_sha256"] != b["manifest_sha256"]:
                changes.append({"shard": s, "change": "changed", "old": a["manifest_sha256"],
                                "new": b["manifest_sha256"]})
        idx = _new_index(plan_hash, shards)
        if changes or old != idx:
            atomic_write_json(root / INDEX_FILE, idx)
    return idx, changes
