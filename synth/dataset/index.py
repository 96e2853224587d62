"""``DIR/index.json``: the committed shards, derived from their manifests.

The index is a cache, never the truth: the truth is the manifests (``shards/*/manifest.json``,
and ``shards/*.tar.json`` of tar shards, :mod:`synth.dataset.tarshard`). It is updated
after each commit under the dataset lock (so commits from several processes never lose each
other's entries) by reconciling it with the directory listing, and it can be rebuilt from the
files at any time (:func:`rebuild_index`). A kill -9 between a commit's rename and the index
update leaves a stale index that the next :func:`update_index` repairs.
"""

from __future__ import annotations

from pathlib import Path

from synth.dataset.layout import INDEX_FILE, INDEX_FORMAT, LOCK_FILE, MANIFEST_FILE, SHARD_FORMAT, flock
from synth.dataset.tarshard import manifest_paths
from synth.io import atomic_write_json, loads_json, sha256_bytes


class ManifestError(ValueError):
    pass


def parse_manifest(data: bytes, shard_id: str) -> dict:
    """Parse and sanity-check a manifest's bytes; raises :class:`ManifestError`."""
    try:
        m = loads_json(data)
    except (ValueError, UnicodeDecodeError) as e:
        raise ManifestError(f"manifest.json does not parse: {e}") from None
    if not isinstance(m, dict) or m.get("format") != SHARD_FORMAT:
        raise ManifestError(f"manifest.json is not a {SHARD_FORMAT} manifest")
    if m.get("shard_id") != shard_id:
        raise ManifestError(f"manifest.json names shard {m.get('shard_id')!r}, not {shard_id!r}")
    if not isinstance(m.get("frames"), list) or not isinstance(m.get("files"), dict):
        raise ManifestError("manifest.json lacks a 'frames' list or a 'files' object")
    for name, ent in m["files"].items():
        if "/" in name or "\\" in name or name.startswith(".") or name == MANIFEST_FILE:
            raise ManifestError(f"manifest.json lists an invalid file name {name!r}")
        if not isinstance(ent, dict) or not isinstance(ent.get("sha256"), str) or not isinstance(ent.get("bytes"), int):
            raise ManifestError(f"manifest.json entry for {name!r} lacks sha256/bytes")
    return m


def index_entry(shard_dir: Path) -> dict:
    """Read ``shard_dir/manifest.json`` into an index entry; raises OSError/ManifestError."""
    return manifest_index_entry(Path(shard_dir) / MANIFEST_FILE, Path(shard_dir).name)


def manifest_index_entry(manifest: Path, shard_id: str) -> dict:
    """The index entry of one manifest (a directory's or a tar shard's); raises OSError/ManifestError."""
    data = Path(manifest).read_bytes()
    m = parse_manifest(data, shard_id)
    return {"frames": len(m["frames"]), "bytes": sum(e["bytes"] for e in m["files"].values()),
            "manifest_sha256": sha256_bytes(data), "manifest_bytes": len(data), "committed": m.get("created")}


def read_index(root: Path) -> dict | None:
    """The index as stored, or None when missing or unreadable."""
    try:
        idx = loads_json((Path(root) / INDEX_FILE).read_bytes())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(idx, dict) or idx.get("format") != INDEX_FORMAT or not isinstance(idx.get("shards"), dict):
        return None
    return idx


def reconcile(root: Path, idx: dict | None, plan_hash: str) -> tuple[dict, bool]:
    """Bring ``idx`` in line with the files: add shards missing from it, drop vanished ones."""
    root = Path(root)
    changed = idx is None or idx.get("plan_hash") != plan_hash
    shards = {} if changed else dict(idx["shards"])
    on_disk: dict[str, Path] = {}
    for name, mp in manifest_paths(root):  # directories and tar shards; a shard in both forms: the directory
        on_disk.setdefault(name, mp)
    for name in set(shards) - set(on_disk):
        del shards[name]
        changed = True
    for name, mp in on_disk.items():
        ent = shards.get(name)
        if ent is not None:
            try:
                if mp.stat().st_size == ent.get("manifest_bytes"):
                    continue
            except OSError:
                pass
        try:
            new = manifest_index_entry(mp, name)
        except (OSError, ManifestError):
            new = None  # not a committed shard (no valid manifest): not indexed; validate reports it
        if new != ent:
            changed = True
            if new is None:
                shards.pop(name, None)
            else:
                shards[name] = new
    out = {"format": INDEX_FORMAT, "plan_hash": plan_hash,
           "num_shards": len(shards), "num_frames": sum(e["frames"] for e in shards.values()),
           "shards": dict(sorted(shards.items()))}
    return out, changed or out != idx


def update_index(root: Path, plan_hash: str, *, durable: bool = True) -> dict:
    """Reconcile ``index.json`` with the committed shards under the dataset lock; returns it."""
    root = Path(root)
    with flock(root / LOCK_FILE):
        idx, changed = reconcile(root, read_index(root), plan_hash)
        if changed:
            atomic_write_json(root / INDEX_FILE, idx, durable=durable)
    return idx


def rebuild_index(root: Path, plan_hash: str) -> dict:
    """Rebuild ``index.json`` from the manifests alone (ignores the stored index)."""
    root = Path(root)
    with flock(root / LOCK_FILE):
        idx, _ = reconcile(root, None, plan_hash)
        atomic_write_json(root / INDEX_FILE, idx)
    return idx
