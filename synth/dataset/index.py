"""What is committed, and with which manifest: commit records and ``DIR/index.json``.

A commit signs its shard: before its commit point (the rename of the staging directory into
``shards/``, or for a tar shard the write of ``shards/<id>.tar.json``,
:mod:`synth.dataset.tarshard`) it writes the **commit record** ``.commits/<shard>.json`` (the
sha256 and size of the manifest, the frame and byte counts), then, after the commit point,
adds the same entry to ``index.json`` (the records of every shard in one file, with
``digest``, a sha256 over every ``shard_id manifest_sha256`` line: one number that changes
when any committed shard does). Both writes are atomic; the record is one file per shard, so
commits on several hosts never lose each other's signatures even where ``flock`` does not work
(NFS, Lustre) and ``index.json``'s read-modify-write might.

A shard's **signature** is its commit record, else its ``index.json`` entry (datasets from
before commit records). Signatures are written only by a commit, never from what happens to
be on disk:

- a shard (a directory, or a tar and its manifest) without a signature was not committed by
  synth: nothing adopts it;
- a manifest changed after its commit is never re-signed: ``synth validate`` reports it and a
  rerun of the render cannot launder it;
- :func:`update_index` (every time a dataset is opened for writing) rebuilds ``index.json``
  from the signatures (never from the manifests), forgetting shards no longer on disk in
  either form; a damaged ``index.json`` is left for the explicit repair;
- :func:`repair_index` (``synth validate --repair-index``) is the one way to sign what the
  manifests now say; it reports every change, and ``synth validate`` logs it.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path

from synth.dataset.layout import (COMMITS_DIR, INDEX_FILE, INDEX_FORMAT, LOCK_FILE, MANIFEST_FILE, MAX_INDEX_BYTES,
                                  MAX_MANIFEST_BYTES, MAX_RECORD_BYTES, SHARD_FORMAT, SHARD_ID_RE, entry_kind, flock)
from synth.dataset.tarshard import present_shards
from synth.errors import SynthError
from synth.io import FileRefused, atomic_write_json, loads_json, read_bounded, read_json, sha256_bytes

_SHA256 = re.compile(r"^[0-9a-f]{64}$")
REPAIR_HINT = "run `synth validate --repair-index DIR` to sign the manifests as they are now (it reports what changed)"


class ManifestError(ValueError):
    pass


class IndexDamaged(ValueError):
    """``index.json`` exists but is not a valid index (reason in the message)."""


def _is_count(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def parse_manifest(data: bytes, shard_id: str, name: str = MANIFEST_FILE) -> dict:
    """Parse and sanity-check a manifest's bytes (``name``: the file's name, for messages: a
    tar shard's is ``<id>.tar.json``); raises :class:`ManifestError`."""
    try:
        m = loads_json(data)
    except ValueError as e:
        raise ManifestError(f"{name} does not parse: {e}") from None
    if not isinstance(m, dict) or m.get("format") != SHARD_FORMAT:
        raise ManifestError(f"{name} is not a {SHARD_FORMAT} manifest")
    if m.get("shard_id") != shard_id:
        raise ManifestError(f"{name} names shard {str(m.get('shard_id'))[:80]!r}, not {shard_id!r}")
    if not isinstance(m.get("frames"), list) or not isinstance(m.get("files"), dict) \
            or not all(isinstance(k, str) for k in m["frames"]):
        raise ManifestError(f"{name} lacks a 'frames' list of keys or a 'files' object")
    for fname, ent in m["files"].items():
        if "/" in fname or "\\" in fname or "\0" in fname or fname.startswith(".") or fname == MANIFEST_FILE:
            raise ManifestError(f"{name} lists an invalid file name {fname[:80]!r}")
        if not isinstance(ent, dict) or not isinstance(ent.get("sha256"), str) or not _is_count(ent.get("bytes")):
            raise ManifestError(f"{name} entry for {fname[:80]!r} lacks sha256/bytes")
    return m


def read_manifest_bytes(path: Path) -> bytes:
    """A manifest's bytes (``shards/<id>/manifest.json`` or ``shards/<id>.tar.json``): a
    regular file (never a symlink) of bounded size. Raises OSError (FileNotFoundError when
    absent) or ManifestError."""
    try:
        return read_bounded(path, MAX_MANIFEST_BYTES, follow_symlinks=False)
    except FileRefused as e:
        raise ManifestError(f"{Path(path).name} {e.what}") from None


def manifest_index_entry(path: Path, shard_id: str) -> dict:
    """The signature of the manifest at ``path`` (a directory's or a tar shard's) as it is
    now; raises OSError/ManifestError."""
    data = read_manifest_bytes(path)
    return manifest_entry(data, parse_manifest(data, shard_id, Path(path).name))


def manifest_entry(data: bytes, manifest: dict) -> dict:
    """The signature of a manifest (its bytes and their parse)."""
    return {"frames": len(manifest["frames"]), "bytes": sum(e["bytes"] for e in manifest["files"].values()),
            "manifest_sha256": sha256_bytes(data), "manifest_bytes": len(data), "committed": manifest.get("created")}


def dataset_digest(shards: dict) -> str:
    """sha256 over the lines ``shard_id manifest_sha256``, sorted: changes with any manifest."""
    return sha256_bytes("".join(f"{s} {shards[s]['manifest_sha256']}\n" for s in sorted(shards)).encode())


def _entry_ok(e) -> bool:
    return isinstance(e, dict) and bool(_SHA256.match(str(e.get("manifest_sha256")))) \
        and all(_is_count(e.get(k)) for k in ("manifest_bytes", "frames", "bytes"))


def _check_index(idx) -> dict:
    if not isinstance(idx, dict) or idx.get("format") != INDEX_FORMAT:
        raise IndexDamaged(f"not a {INDEX_FORMAT} file")
    if not isinstance(idx.get("plan_hash"), str) or not isinstance(idx.get("shards"), dict):
        raise IndexDamaged("lacks plan_hash or the shards object")
    for s, e in idx["shards"].items():
        if not SHARD_ID_RE.match(s):
            raise IndexDamaged(f"lists a bad shard id {s[:80]!r}")
        if not _entry_ok(e):
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


def record_path(root: Path, shard_id: str) -> Path:
    return Path(root) / COMMITS_DIR / f"{shard_id}.json"


def read_records(root: Path, plan_hash: str) -> tuple[dict[str, dict], list[str]]:
    """The commit records of this plan: ``({shard: signature}, [problems])``. A record that is
    not a regular file, does not parse or belongs to another plan is left out and named in
    ``problems`` (``synth validate`` reports them)."""
    base = Path(root) / COMMITS_DIR
    try:
        names = sorted(os.listdir(base))
    except FileNotFoundError:
        return {}, []
    out, problems = {}, []
    for n in names:
        sid = n[:-5] if n.endswith(".json") else ""
        if not SHARD_ID_RE.match(sid):
            if not (n.startswith(".") and n.endswith(".tmp")):
                problems.append(f"{COMMITS_DIR}/{n[:120]!r} is not a commit record")
            continue
        try:
            rec = read_json(base / n, max_bytes=MAX_RECORD_BYTES, follow_symlinks=False)
        except (OSError, ValueError) as e:
            problems.append(f"{COMMITS_DIR}/{n} cannot be read ({e})")
            continue
        if not isinstance(rec, dict) or rec.get("plan_hash") != plan_hash or not _entry_ok(rec.get("entry")):
            problems.append(f"{COMMITS_DIR}/{n} is not a commit record of this plan")
            continue
        out[sid] = rec["entry"]
    return out, problems


def _write_record(root: Path, plan_hash: str, shard_id: str, entry: dict, durable: bool) -> None:
    (Path(root) / COMMITS_DIR).mkdir(exist_ok=True)
    atomic_write_json(record_path(root, shard_id), {"plan_hash": plan_hash, "shard": shard_id, "entry": entry},
                      durable=durable)


def new_index(plan_hash: str, shards: dict) -> dict:
    shards = dict(sorted(shards.items()))
    return {"format": INDEX_FORMAT, "plan_hash": plan_hash, "num_shards": len(shards),
            "num_frames": sum(e["frames"] for e in shards.values()), "digest": dataset_digest(shards),
            "shards": shards}


def signatures(root: Path, plan_hash: str) -> dict[str, dict]:
    """Every shard's signature (its commit record, else its ``index.json`` entry), whether or
    not its directory exists. Raises :class:`SynthError` when ``index.json`` is damaged or of
    another plan (run the repair)."""
    where = str(Path(root) / INDEX_FILE)
    try:
        idx = read_index(root)
    except IndexDamaged as e:
        raise SynthError(f"index.json is damaged ({e})", where, REPAIR_HINT) from None
    if idx is not None and idx["plan_hash"] != plan_hash:
        raise SynthError("index.json belongs to another plan", where, REPAIR_HINT)
    records, _ = read_records(root, plan_hash)
    return {**(idx["shards"] if idx else {}), **records}


def commit_shard(root: Path, plan_hash: str, shard_id: str, entry: dict, rename: Callable[[], None], *,
                 durable: bool = True) -> dict:
    """Sign ``entry`` (the commit record), ``rename()`` the shard into place (the commit point:
    the staging directory's rename, or a tar shard's manifest), then add it to ``index.json``;
    under the dataset lock. If ``rename()`` fails the record is taken back. Returns the new
    index."""
    root = Path(root)
    with flock(root / LOCK_FILE):
        sigs = signatures(root, plan_hash)
        rec = record_path(root, shard_id)
        before = rec.read_bytes() if entry_kind(rec) == "file" else None
        _write_record(root, plan_hash, shard_id, entry, durable)
        try:
            rename()
        except BaseException:
            if before is None:
                rec.unlink(missing_ok=True)
            else:
                atomic_write_json(rec, loads_json(before), durable=durable)
            raise
        sigs[shard_id] = entry
        on_disk = present_shards(root)
        idx = new_index(plan_hash, {s: e for s, e in sigs.items() if s in on_disk})
        atomic_write_json(root / INDEX_FILE, idx, durable=durable)
    return idx


def update_index(root: Path, plan_hash: str, *, durable: bool = True) -> dict:
    """Under the dataset lock, rewrite ``index.json`` from the signatures of the shards present
    in either form (it creates the empty index of a new dataset, recovers an entry a lost
    update dropped, forgets shards deleted to be re-rendered). Never signs a manifest.
    Raises :class:`SynthError` when ``index.json`` is damaged or of another plan."""
    root = Path(root)
    with flock(root / LOCK_FILE):
        sigs = signatures(root, plan_hash)
        idx = new_index(plan_hash, {s: sigs[s] for s in present_shards(root) if s in sigs})
        try:
            old = read_index(root)
        except IndexDamaged:
            old = None
        if old != idx:
            atomic_write_json(root / INDEX_FILE, idx, durable=durable)
    return idx


def repair_index(root: Path, plan_hash: str) -> tuple[dict, list[dict]]:
    """Sign every present shard's manifest (a directory's, or a tar shard's ``<id>.tar.json``)
    as it is now: commit records and ``index.json`` rebuilt from the manifests (explicitly:
    this is the one place that signs what is on disk).
    Returns the new index and the changes, each ``{"shard", "change": "added" | "removed" |
    "changed" | "skipped", ...}``; ``"shard": None`` is ``index.json`` itself."""
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
        records, _ = read_records(root, plan_hash)
        before = {**(old or {}).get("shards", {}), **records}
        shards = {}
        on_disk = present_shards(root)
        for s, mp in on_disk.items():
            try:
                shards[s] = manifest_index_entry(mp, s)
            except (OSError, ManifestError) as e:
                changes.append({"shard": s, "change": "skipped", "reason": f"not signed: {e}"})
        for s in sorted((set(before) & set(on_disk)) | set(shards)):
            a, b = before.get(s), shards.get(s)
            if a is None and b is not None:
                changes.append({"shard": s, "change": "added", "new": b["manifest_sha256"]})
            elif b is None and a is not None:
                changes.append({"shard": s, "change": "removed", "old": a["manifest_sha256"]})
            elif a is not None and a["manifest_sha256"] != b["manifest_sha256"]:
                changes.append({"shard": s, "change": "changed", "old": a["manifest_sha256"],
                                "new": b["manifest_sha256"]})
        for s, e in shards.items():
            if records.get(s) != e:
                _write_record(root, plan_hash, s, e, durable=True)
        for s in set(records) - set(shards):
            record_path(root, s).unlink(missing_ok=True)
        idx = new_index(plan_hash, shards)
        if old != idx:
            atomic_write_json(root / INDEX_FILE, idx)
    return idx, changes
