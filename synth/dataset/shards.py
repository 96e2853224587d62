"""Datasets of shards: create/check, stage frames, commit atomically, resume (docs/shard-format.md).

Typical worker loop::

    ds = open_dataset(out, plan_hash, expected={shard_id: [keys...], ...}, meta={...})
    for shard_id in ds.pending_shards():
        with ds.staging(shard_id) as st:          # lease: one process per shard, across hosts
            done = st.frames_done()               # frames finished by an interrupted run
            for key in st.expected_keys:
                if key not in done:
                    st.write_frame(key, rgba, depth, normals, seg, frame_json)
            st.commit(manifest_extra={"seeds": ..., "versions": ...})

Crash safety (kill -9 at any instant):

- a frame is written as ``KEY.exr`` then ``KEY.json``, each via temp file + fsync + rename;
  a frame counts as done only when its JSON exists and its EXR header reads with the JSON's
  size, so an interrupted frame is redone and a finished one never is;
- a commit fsyncs every file, writes ``manifest.json`` (sha256 of every file) atomically,
  fsyncs, then renames the whole staging directory to ``shards/<id>`` in one ``rename(2)``:
  a shard is either committed complete or not at all (a tar shard, ``dataset.shard_format =
  "tar"``: the tar is built and fsynced first, and the atomic write of its manifest
  ``shards/<id>.tar.json`` is the commit point; :mod:`synth.dataset.tarshard`);
- the commit signs the manifest's sha256 (its commit record, :mod:`synth.dataset.index`)
  under the dataset lock just before that commit point, so the signatures are never behind
  the files and a manifest that changed after its commit is never re-signed;
- a shard is claimed with a lease file (:mod:`synth.dataset.lease`) that a process on another
  host can see and, once its holder is gone, break: flock is not reliable on NFS or Lustre.
"""

from __future__ import annotations

import os
import platform
from collections.abc import Mapping, Sequence
from pathlib import Path

import synth
from synth.dataset.index import (REPAIR_HINT, ManifestError, parse_manifest, read_manifest_bytes, signatures,
                                 update_index)
from synth.dataset.frame_json import jsonable
from synth.dataset.layout import (DATASET_FILE, DATASET_FORMAT, FRAME_KEY_RE, KIND_TEXT, LOCK_FILE, LOGS_DIR,
                                  MAX_DATASET_JSON_BYTES, SHARDS_DIR, STAGING_DIR, check_shard_id, flock, lease_path,
                                  shard_dir, staging_dir, utc_now)
from synth.dataset.lease import DEFAULT_TTL_S, Holder, read_holder
from synth.dataset.staging import ShardBusy, ShardCommitted, StagingShard
from synth.dataset.tarshard import (SHARD_FORMATS, TAR_MANIFEST_SUFFIX, check_shard_format, manifest_file,
                                   shard_entries)
from synth.errors import SynthError
from synth.io import atomic_write_json, is_temp_name, read_json


#: ``synth render`` keeps the plan directory it renders next to the shards (DIR/plan/).
PLAN_DIR = "plan"


def _normalise_expected(expected: Mapping[str, Sequence[str]]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    seen: dict[str, str] = {}
    if not isinstance(expected, Mapping) or not expected:
        raise SynthError("the plan has no shards to render", None, "check the plan (expected shard -> frame keys)")
    for sid in sorted(expected):
        check_shard_id(sid)
        if not isinstance(expected[sid], (list, tuple)):
            raise SynthError(f"shard {sid}'s frames are not a list of frame keys", None, "check the plan")
        keys = list(expected[sid])
        if not keys:
            raise SynthError(f"shard {sid} has no frames in the plan", None, "drop empty shards from the plan")
        for k in keys:
            if not isinstance(k, str) or not FRAME_KEY_RE.match(k):
                raise SynthError(f"bad frame key {k!r} in shard {sid}", None, "keys look like id000042_ex07_v13")
            if k in seen:
                raise SynthError(f"frame {k} is in shards {seen[k]} and {sid}", None, "each frame belongs to one shard")
            seen[k] = sid
        out[sid] = sorted(keys)
    return out


def _read_dataset_json(root: Path) -> dict:
    p = root / DATASET_FILE
    fix = "restore it or render into a new --out directory"
    try:
        d = read_json(p, max_bytes=MAX_DATASET_JSON_BYTES, follow_symlinks=False)
    except (ValueError, OSError) as e:
        why = e.strerror if isinstance(e, OSError) else str(e)
        raise SynthError(f"dataset.json cannot be read ({why})", str(p), fix) from None
    if not isinstance(d, dict) or d.get("format") != DATASET_FORMAT or not isinstance(d.get("plan_hash"), str) \
            or not isinstance(d.get("expected"), dict):
        raise SynthError(f"dataset.json is not a {DATASET_FORMAT} file", str(p), fix)
    try:
        if _normalise_expected(d["expected"]) != d["expected"]:
            raise SynthError("its expected shards are not sorted lists of frame keys")
        if d.get("shard_format", "dir") not in SHARD_FORMATS:
            raise SynthError(f"its shard_format is not one of {', '.join(SHARD_FORMATS)}")
    except SynthError as e:
        raise SynthError(f"dataset.json is damaged: {e.what}", str(p), fix) from None
    return d


def check_out_dir(root: Path) -> dict | None:
    """Refuse a directory that cannot hold a dataset, before anything is written: a path that
    is not a directory, or a non-empty directory without ``dataset.json`` (only a plan, logs,
    the lock and temporary names of other ``synth render`` runs may be there). Returns the
    existing ``dataset.json`` (checked), or ``None``."""
    root = Path(root)
    if not os.path.lexists(root):
        return None
    if not root.is_dir():
        raise SynthError("output path exists and is not a directory", str(root), "choose a directory for --out")
    if os.path.lexists(root / DATASET_FILE):
        return _read_dataset_json(root)
    others = sorted(n for n in os.listdir(root) if n not in (LOCK_FILE, PLAN_DIR, LOGS_DIR) and not is_temp_name(n))
    if others:
        raise SynthError(f"directory is not empty and holds no dataset.json (found {others[0]!r})", str(root),
                         "use an empty or new --out directory")
    return None


def _check_same_plan(root: Path, info: dict, plan_hash: str, exp: dict, shard_format: str | None) -> None:
    if info["plan_hash"] != plan_hash:
        raise SynthError(f"{root} holds a dataset from a different plan (hash {info['plan_hash'][:16]}, "
                         f"this plan {plan_hash[:16]})", str(root / DATASET_FILE),
                         "use a new --out or the original plan")
    if info["expected"] != exp:
        raise SynthError("dataset.json's expected shards differ from this plan's although the hashes match",
                         str(root / DATASET_FILE), "the plan hash must cover the shard layout; use a new --out")
    if shard_format is not None and info.get("shard_format", "dir") != shard_format:
        raise SynthError(f"{root} stores shards as {info.get('shard_format', 'dir')!r}, not {shard_format!r}",
                         str(root / DATASET_FILE), "use a new --out, or the dataset's shard format")


def _shard_names(kinds: dict[str, str]) -> dict[str, tuple[str, str]]:
    """The names under ``shards/`` that a committed shard would have -> (shard id, the kind it
    must be): ``<id>`` a directory, ``<id>.tar.json`` a regular file."""
    out = {}
    for n in kinds:
        sid = n[:-len(TAR_MANIFEST_SUFFIX)] if n.endswith(TAR_MANIFEST_SUFFIX) else n
        out[n] = (sid, "dir" if sid == n else "file")
    return out


class Dataset:
    """A dataset directory. Use :func:`open_dataset` (writers) or :func:`load_dataset` (readers)."""

    def __init__(self, root: Path, info: dict, *, writable: bool):
        self.root = Path(root)
        self.info = info
        self.plan_hash: str = info["plan_hash"]
        self.expected: dict[str, list[str]] = {k: list(v) for k, v in info["expected"].items()}
        #: How new commits store a shard: "dir" or "tar" (readers accept both forms).
        self.shard_format: str = info.get("shard_format", "dir")
        self.writable = writable

    # -- paths -------------------------------------------------------------------------------
    def shard_dir(self, shard_id: str) -> Path:
        return shard_dir(self.root, shard_id)

    def staging_dir(self, shard_id: str) -> Path:
        return staging_dir(self.root, shard_id)

    # -- state (always read from the files) --------------------------------------------------
    def committed_shards(self) -> set[str]:
        """Planned shards that are committed: a directory under ``shards/``, or a tar shard's
        manifest ``shards/<id>.tar.json``, that a commit signed (its commit record, or its
        ``index.json`` entry; :mod:`synth.dataset.index`).

        Read from the files each time; ``shards/`` is listed before the signatures are read
        and a commit signs before its commit point, so a commit in progress in another process
        is seen whole or not at all. Raises a :class:`SynthError` (run ``synth validate
        --repair-index``) when ``index.json`` is damaged or of another plan, and when a planned
        shard's entry is unsigned or not a real directory (a regular file for a tar manifest):
        synth did not commit it, and nothing will silently adopt it. Unplanned entries are left
        to ``synth validate``.
        """
        kinds = shard_entries(self.root).kinds
        sigs = signatures(self.root, self.plan_hash)
        out = set()
        for name, (sid, want) in _shard_names(kinds).items():
            kind = kinds[name]
            if sid not in self.expected:
                continue
            where = str(self.root / SHARDS_DIR / name)
            if sid not in sigs:
                raise SynthError(f"shards/{name} has no commit record (synth did not commit it, or its index was "
                                 "lost)", where, REPAIR_HINT)
            if kind != want:
                raise SynthError(f"shards/{name} is a {KIND_TEXT[kind]}, not a {KIND_TEXT[want]}", where,
                                 "restore the shard, or delete it and rerun the render")
            out.add(sid)
        return out

    def pending_shards(self) -> list[str]:
        """Planned shards not yet committed, in order."""
        done = self.committed_shards()
        return [s for s in self.expected if s not in done]

    def read_manifest(self, shard_id: str) -> dict:
        p = manifest_file(self.root, check_shard_id(shard_id))
        try:
            return parse_manifest(read_manifest_bytes(p), shard_id, p.name)
        except FileNotFoundError:
            raise SynthError(f"shard {shard_id} is not committed", str(self.shard_dir(shard_id)), "render it first") \
                from None
        except ManifestError as e:
            raise SynthError(str(e), str(p), "run `synth validate`; re-render the shard into a new --out") from None

    # -- writing -----------------------------------------------------------------------------
    def _need_writable(self) -> None:
        if not self.writable:
            raise SynthError("dataset opened read-only", str(self.root), "use open_dataset() to write")

    def staging(self, shard_id: str, lease_ttl: float = DEFAULT_TTL_S) -> StagingShard:
        """Claim and open the staging area of one shard (use as a context manager).

        Refuses a shard that is not in the plan, one already committed, and one another
        process is rendering right now (its lease is held; ``lease_ttl`` is how long this
        process's own lease stays valid on other hosts without a heartbeat).
        """
        self._need_writable()
        check_shard_id(shard_id)
        if shard_id not in self.expected:
            raise SynthError(f"shard {shard_id} is not in this dataset's plan", str(self.root),
                             "use a shard id from the plan")
        st = StagingShard(self.root, self.plan_hash, shard_id, self.expected[shard_id], lease_ttl, self.shard_format)
        st._open()
        return st

    def try_staging(self, shard_id: str, lease_ttl: float = DEFAULT_TTL_S) -> StagingShard | None:
        """Like :meth:`staging`, but ``None`` when another process is rendering the shard or has
        committed it meanwhile: the loop for several workers sharing one dataset is
        ``for s in ds.pending_shards(): st = ds.try_staging(s); if st is None: continue; with st: ...``."""
        try:
            return self.staging(shard_id, lease_ttl)
        except (ShardBusy, ShardCommitted):
            return None

    def claims(self, shard_ids: Sequence[str]) -> dict[str, Holder]:
        """The shards among ``shard_ids`` that a live process holds (read from the lease files;
        a lease whose holder is gone is not listed: the next claimant breaks it)."""
        out = {}
        for s in shard_ids:
            h = read_holder(lease_path(self.root, s))
            if h is not None and h.alive():
                out[s] = h
        return out

    def summary(self) -> dict:
        """Counts for progress displays, read from the files."""
        done = self.committed_shards()
        return {"shards": len(self.expected), "shards_committed": len(done & set(self.expected)),
                "frames": sum(len(v) for v in self.expected.values()),
                "frames_committed": sum(len(self.expected[s]) for s in done if s in self.expected)}

    def __repr__(self) -> str:
        return f"Dataset({str(self.root)!r}, plan_hash={self.plan_hash[:12]}..., shards={len(self.expected)})"


def open_dataset(root, plan_hash: str, expected: Mapping[str, Sequence[str]], meta: dict | None = None, *,
                 shard_format: str | None = None) -> Dataset:
    """Create the dataset directory for a plan, or reopen it to resume.

    - ``plan_hash``: a stable hash of the plan (``synth plan`` records it in its plan.json).
    - ``expected``: shard id -> the frame keys planned for that shard.
    - ``meta``: JSON-able facts recorded once in dataset.json (plan path, config, versions).
    - ``shard_format``: ``"dir"`` or ``"tar"`` (``dataset.shard_format``), recorded in
      dataset.json; ``None``: as recorded there (``"dir"`` for a new dataset).

    Refuses (:class:`SynthError`) a directory that holds a dataset from another plan, and a
    non-empty directory that is not a dataset. Safe when several workers open it at once.
    """
    root = Path(root)
    if not isinstance(plan_hash, str) or not plan_hash:
        raise SynthError("plan hash is empty", str(root), "pass the plan's hash")
    exp = _normalise_expected(expected)
    if shard_format is not None:
        check_shard_format(shard_format, str(root))
    found = check_out_dir(root)  # refuse before anything is created
    if found is not None:
        _check_same_plan(root, found, plan_hash, exp, shard_format)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise SynthError(f"cannot create the dataset directory ({e.strerror})", str(root),
                         "choose a writable --out") from None
    with flock(root / LOCK_FILE):
        info = check_out_dir(root)  # again, under the lock: another process may have created it
        if info is not None:
            _check_same_plan(root, info, plan_hash, exp, shard_format)
        else:
            info = {
                "format": DATASET_FORMAT,
                "plan_hash": plan_hash,
                "created": utc_now(),
                "synth_version": synth.__version__,
                "python": platform.python_version(),
                "num_shards": len(exp),
                "num_frames": sum(len(v) for v in exp.values()),
                "shard_format": shard_format or "dir",
                "meta": jsonable(meta or {}),
                "expected": exp,
            }
            try:
                atomic_write_json(root / DATASET_FILE, info)
            except (TypeError, ValueError) as e:
                raise SynthError(f"meta is not JSON-serialisable: {e}", str(root), "pass plain data") from None
        (root / SHARDS_DIR).mkdir(exist_ok=True)
        (root / STAGING_DIR).mkdir(exist_ok=True)
    ds = Dataset(root, info, writable=True)
    update_index(root, plan_hash)
    return ds


def load_dataset(root) -> Dataset:
    """Open an existing dataset read-only (validate, preview, training readers)."""
    root = Path(root)
    if not os.path.lexists(root):
        raise SynthError("dataset directory not found", str(root), "pass the --out directory of `synth render`")
    if not root.is_dir():
        raise SynthError("not a directory", str(root), "pass the dataset directory (the --out of `synth render`)")
    if not (root / DATASET_FILE).is_file():
        raise SynthError("not a synth dataset (no dataset.json)", str(root),
                         "pass the --out directory of `synth render`")
    return Dataset(root, _read_dataset_json(root), writable=False)
