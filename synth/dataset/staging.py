"""The staging area of one shard: write frames, find finished ones, commit atomically.

See :mod:`synth.dataset.shards` for the worker loop and docs/shard-format.md for the
crash-safety argument.
"""

from __future__ import annotations

import os
import platform
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

import synth
from synth.dataset.exr import encode_frame_exr, read_frame_exr_header
from synth.dataset.frame_json import check_frame_json, jsonable
from synth.dataset.index import commit_shard, manifest_entry
from synth.dataset.layout import (MANIFEST_FILE, MAX_FRAME_JSON_BYTES, SHARD_FORMAT, frame_files, lease_path, shard_dir,
                                  staging_dir, utc_now)
from synth.dataset.lease import DEFAULT_TTL_S, Lease, LeaseBusy
from synth.dataset.tarshard import (build_tar_shard, check_shard_format, committed_forms, place_tar_shard,
                                   tar_manifest_path)
from synth.errors import SynthError
from synth.io import (atomic_write_bytes, atomic_write_json, dumps_json, file_digest, fsync_dir, is_temp_name,
                      read_json, sha256_bytes)


class ShardBusy(SynthError):
    """Another process holds the shard's lease (it is rendering that shard); ``holder`` says who."""

    holder = None


class ShardCommitted(SynthError):
    """The shard is already committed; committed shards are never modified."""


_RESERVED_MANIFEST = {"format", "shard_id", "plan_hash", "frames", "files", "created", "synth_version", "writer",
                      "container"}


def _writer_versions() -> dict:
    try:
        import OpenEXR

        exr = OpenEXR.__version__
    except ImportError:  # pragma: no cover
        exr = None
    return {"synth": synth.__version__, "python": platform.python_version(), "numpy": np.__version__,
            "OpenEXR": exr}


class StagingShard:
    """One shard being rendered: ``.staging/<id>/`` plus the lease ``.staging/<id>.lease``
    (:mod:`synth.dataset.lease`: a claim that holds across hosts sharing the dataset).

    Made by ``Dataset.staging`` (the dataset root, its plan hash, the shard's planned keys, the
    lease's ttl and the dataset's shard format: ``"dir"`` or ``"tar"``, :mod:`synth.dataset.tarshard`).
    """

    def __init__(self, root: Path, plan_hash: str, shard_id: str, expected_keys: Sequence[str],
                 lease_ttl: float = DEFAULT_TTL_S, shard_format: str = "dir"):
        self.shard_format = check_shard_format(shard_format)
        self.root = Path(root)
        self.plan_hash = plan_hash
        self.shard_id = shard_id
        self.dir = staging_dir(self.root, shard_id)
        self.target = shard_dir(self.root, shard_id)
        self.expected_keys: list[str] = list(expected_keys)
        self._expected_set = set(self.expected_keys)
        self._lease_path = lease_path(self.root, shard_id)
        self._lease_ttl = lease_ttl
        self._lease: Lease | None = None
        self._committed = False
        #: Files removed when the staging area was opened (temp files, half-finished frames).
        self.cleaned: list[str] = []

    # -- lifecycle ---------------------------------------------------------------------------
    def _open(self) -> None:
        self.dir.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._lease = Lease.acquire(self._lease_path, self._lease_ttl)
        except LeaseBusy as e:
            busy = ShardBusy(f"shard {self.shard_id} is being rendered by another process ({e.holder.describe()})",
                             str(self.dir), "wait for it, or stop it first")
            busy.holder = e.holder
            raise busy from None
        try:
            if committed_forms(self.root, self.shard_id):
                raise ShardCommitted(f"shard {self.shard_id} is already committed", str(self.target),
                                     "committed shards are never modified; skip it")
            self.dir.mkdir(exist_ok=True)
            self._clean()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Release the lease (the staging files stay for a later resume)."""
        if self._lease is not None:
            self._lease.release()
            self._lease = None

    def __enter__(self) -> StagingShard:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _need_lock(self) -> None:
        if self._committed:
            raise ShardCommitted(f"shard {self.shard_id} is already committed",
                                 str(self.target), "committed shards are never modified")
        if self._lease is None:
            raise SynthError(f"staging area of {self.shard_id} is closed", str(self.dir),
                             "call dataset.staging() again")

    def _clean(self) -> set[str]:
        """Remove leftovers of a killed process: temp files and frames without a valid pair."""
        names = os.listdir(self.dir)
        for n in names:
            if is_temp_name(n):
                self._remove(n)
        return self._frames_done(cleanup=True)

    def _remove(self, name: str) -> None:
        try:
            os.unlink(self.dir / name)
            self.cleaned.append(name)
        except FileNotFoundError:
            pass

    # -- frames ------------------------------------------------------------------------------
    def frames_done(self) -> set[str]:
        """Frames fully written (in this run or an interrupted earlier one): reuse, don't redo."""
        return self._frames_done(cleanup=False)

    def _frames_done(self, cleanup: bool) -> set[str]:
        names = set(os.listdir(self.dir))
        done = set()
        for n in sorted(names):
            stem, dot, ext = n.rpartition(".")
            if not dot or is_temp_name(n) or ext not in ("exr", "json"):
                continue
            if stem not in self._expected_set:
                if cleanup:
                    self._remove(n)
                continue
            if ext != "json":
                continue
            exr, js = frame_files(stem)
            ok = exr in names
            if ok:
                try:
                    fj = read_json(self.dir / js, max_bytes=MAX_FRAME_JSON_BYTES, follow_symlinks=False)
                    hdr = read_frame_exr_header(self.dir / exr)
                    ok = (fj.get("frame_id") == stem and (hdr["width"], hdr["height"])
                          == (fj["image"]["width"], fj["image"]["height"]))
                except (OSError, ValueError, KeyError, TypeError, AttributeError, SynthError):
                    ok = False
            if ok:
                done.add(stem)
            elif cleanup:
                self._remove(js)
                self._remove(exr)
        if cleanup:  # EXRs whose JSON never landed: the frame was in flight
            for n in names:
                if n.endswith(".exr") and n[:-4] in self._expected_set and n[:-4] not in done:
                    self._remove(n)
        return done

    def write_frame(self, key: str, rgba, depth, normals, segmentation, frame_json: dict, *,
                    exr_header: dict | None = None, durable: bool = True) -> None:
        """Write one frame (EXR, then JSON; both atomic). See :func:`synth.dataset.exr.write_frame_exr`.

        ``frame_json`` is validated against the schema first (numpy values are converted), and
        must agree with ``key`` and the image size. Rewriting a done frame is allowed.
        """
        self._need_lock()
        fj = self._check_frame(key, frame_json)
        exr, js = frame_files(key)
        shape = np.shape(rgba)
        h, w = (shape[0], shape[1]) if len(shape) == 3 else (None, None)
        if (w, h) != (fj["image"]["width"], fj["image"]["height"]):
            raise SynthError(f"frame {key}: image is {w}x{h} but the frame JSON says "
                             f"{fj['image']['width']}x{fj['image']['height']}", str(self.dir),
                             "pass the rendered size in image.width/height")
        hdr = {"synthFrameKey": key, "synthShard": self.shard_id, **(exr_header or {})}
        data = encode_frame_exr(rgba, depth, normals, segmentation, hdr, where=str(self.dir / exr))
        try:  # an existing JSON would pair with a new EXR if we died in between
            os.unlink(self.dir / js)
        except FileNotFoundError:
            pass
        atomic_write_bytes(self.dir / exr, data, durable=durable)
        atomic_write_json(self.dir / js, fj, durable=durable, indent=None)

    def _check_frame(self, key: str, frame_json: dict) -> dict:
        if key not in self._expected_set:
            raise SynthError(f"frame {key} is not planned for shard {self.shard_id}", str(self.dir),
                             "write only the shard's planned frames (StagingShard.expected_keys)")
        fj = jsonable(frame_json)
        if not isinstance(fj, dict) or fj.get("frame_id") != key:
            raise SynthError(f"frame JSON's frame_id {fj.get('frame_id') if isinstance(fj, dict) else None!r} "
                             f"is not {key!r}", str(self.dir), "set frame_id to the frame key")
        check_frame_json(fj, str(self.dir / frame_files(key)[1]))
        return fj

    # -- commit ------------------------------------------------------------------------------
    def commit(self, expected_keys: Sequence[str] | None = None, manifest_extra: dict | None = None, *,
               durable: bool = True) -> dict:
        """Commit the shard atomically and return its manifest.

        Checks that exactly the planned frames are present (``expected_keys``, when given, must
        equal the plan's), fsyncs every file, writes ``manifest.json`` (frames, sha256 and size of
        every file, plan hash, versions, plus ``manifest_extra`` such as seeds), then, under the
        dataset lock, signs the manifest (its commit record), renames the staging directory to
        ``shards/<id>`` and adds the shard to ``index.json``
        (:func:`synth.dataset.index.commit_shard`). A tar shard is written as ``shards/<id>.tar``
        and ``shards/<id>.tar.json`` instead (:meth:`_commit_tar`). Nothing is committed when
        anything is missing.
        """
        self._need_lock()
        where = str(self.dir)
        if expected_keys is not None and sorted(expected_keys) != self.expected_keys:
            raise SynthError(f"shard {self.shard_id}: the keys to commit differ from the plan's", where,
                             "commit the shard's planned frames (StagingShard.expected_keys)")
        extra = jsonable(manifest_extra or {})
        clash = _RESERVED_MANIFEST & set(extra)
        if clash:
            raise SynthError(f"manifest_extra uses reserved key(s) {sorted(clash)}", where, "rename them")
        done = self._clean()
        missing = [k for k in self.expected_keys if k not in done]
        if missing:
            raise SynthError(f"shard {self.shard_id}: {len(missing)} of {len(self.expected_keys)} frame(s) missing "
                             f"(first: {missing[0]}); not committed", where, "render the missing frames first")
        wanted = {n for k in self.expected_keys for n in frame_files(k)}
        stray = sorted(set(os.listdir(self.dir)) - wanted - {MANIFEST_FILE})
        if stray:
            raise SynthError(f"shard {self.shard_id}: unexpected file(s) in staging: {', '.join(stray[:3])}", where,
                             "remove them (only KEY.exr and KEY.json belong to a shard)")
        files = {}
        for name in sorted(wanted):
            digest, size = file_digest(self.dir / name, sync=durable and self.shard_format == "dir",
                                       follow_symlinks=False)  # a tar shard: the tar is fsynced instead
            files[name] = {"sha256": digest, "bytes": size}
        manifest = {
            "format": SHARD_FORMAT,
            "shard_id": self.shard_id,
            "plan_hash": self.plan_hash,
            "frames": list(self.expected_keys),
            "files": files,
            "created": utc_now(),
            "synth_version": synth.__version__,
            "writer": _writer_versions(),
            **extra,
        }
        try:
            data = dumps_json(manifest)
        except (TypeError, ValueError) as e:
            raise SynthError(f"manifest_extra is not JSON-serialisable: {e}", where, "pass plain data") from None
        if self.shard_format == "tar":  # one tar and its manifest instead of a directory
            return self._commit_tar(manifest, durable)
        atomic_write_bytes(self.dir / MANIFEST_FILE, data, durable=durable)
        for name in list(files) + [MANIFEST_FILE]:
            os.chmod(self.dir / name, 0o444)  # read-only by convention (and by mode)
        if durable:
            fsync_dir(self.dir)
        target = self.target
        target.parent.mkdir(exist_ok=True)

        def rename() -> None:  # under the dataset lock, after the commit record signed the manifest
            self._check_commit(target)
            os.rename(self.dir, target)  # the commit point
            self._committed = True
            if durable:
                fsync_dir(target.parent)
                fsync_dir(self.dir.parent)

        commit_shard(self.root, self.plan_hash, self.shard_id, manifest_entry(data, manifest), rename,
                     durable=durable)
        self.close()  # anyone who takes the lease now sees the committed shard
        manifest["manifest_sha256"] = sha256_bytes(data)
        return manifest

    def _check_commit(self, where: Path) -> None:
        """The last checks before the commit point (under the dataset lock): the shard is not
        committed in either form, and this process still holds its lease."""
        if committed_forms(self.root, self.shard_id):
            raise ShardCommitted(f"shard {self.shard_id} is already committed", str(where),
                                 "committed shards are never modified")
        if not self._lease.held():  # broken by another host after a missed heartbeat: let it commit
            raise ShardBusy(f"shard {self.shard_id}: this process's claim was broken by another process; "
                            "not committed", str(self.dir), "the other process finishes the shard")

    def _commit_tar(self, manifest: dict, durable: bool) -> dict:
        """The tar form of the commit: build the tar under a temporary name (which completes the
        manifest: member offsets, ``container``), sign the manifest, then, under the dataset
        lock, rename the tar into place and write its manifest (the commit point;
        :mod:`synth.dataset.tarshard`); the staging directory is removed after it."""
        mp = tar_manifest_path(self.root, self.shard_id)
        if committed_forms(self.root, self.shard_id):  # before the work of building the tar
            raise ShardCommitted(f"shard {self.shard_id} is already committed", str(mp),
                                 "committed shards are never modified")
        tmp = build_tar_shard(self.dir, self.root, self.shard_id, manifest, durable=durable)
        try:
            data = dumps_json(manifest)

            def place() -> None:  # under the dataset lock, after the commit record signed the manifest
                self._check_commit(mp)
                place_tar_shard(tmp, self.root, self.shard_id, data, durable=durable)
                self._committed = True

            commit_shard(self.root, self.plan_hash, self.shard_id, manifest_entry(data, manifest), place,
                         durable=durable)
        finally:
            tmp.unlink(missing_ok=True)  # renamed away when committed
        shutil.rmtree(self.dir, ignore_errors=True)
        if durable:
            fsync_dir(self.dir.parent)
        self.close()
        manifest["manifest_sha256"] = sha256_bytes(data)
        return manifest
