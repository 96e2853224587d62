"""Tar shards (``dataset.shard_format = "tar"``; docs/shard-format.md, "Tar shards").

A committed tar shard is two files in ``DIR/shards/``::

    shard_000000.tar        members KEY.exr, KEY.json of every frame, sorted by name
    shard_000000.tar.json   its manifest: the directory form's manifest.json, plus the tar's
                            own sha256 and size ("container") and each member's data offset

The members have no directory prefix, so WebDataset (which groups consecutive members by the
name up to the first dot) yields one sample ``{"__key__": KEY, "exr": ..., "json": ...}`` per
frame, and ``tarfile`` or ``tar -x`` unpack the same files as a directory shard holds. The
manifest stays outside the tar, where WebDataset would read it as a sample.

Written with the standard library's ``tarfile`` (maintained with CPython, needs no extra
package, so the render workers do not depend on the ``export`` extra) with fixed headers:
POSIX ustar, regular files only, mode 0444, mtime 0, uid/gid 0, no user or group names,
members in name order. The same frames therefore give the same tar, byte for byte.

Frames are staged as files exactly as for directory shards (so resume after a kill works the
same); the tar is made at commit: written to a temporary name in ``shards/``, fsynced and
renamed to ``<id>.tar``; then the manifest ``<id>.tar.json`` is written atomically, which is
the commit point (a tar without its manifest is the leftover of a killed commit: not
committed, replaced by the next commit); then the staging directory is removed.

Reading back, :func:`iter_members` walks a tar's 512-byte headers one at a time with
``tarfile.TarInfo.frombuf`` (which checks each header's checksum) and accepts only what this
writer makes: plain ustar regular-file members with a flat ``KEY.exr`` / ``KEY.json`` name
and a bounded size. Anything else (links, directories, devices, pax or GNU extension
headers, ``..`` or absolute names) is refused before its data is read.
"""

from __future__ import annotations

import os
import stat
import tarfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, NamedTuple

from synth.dataset.layout import FRAME_KEY_RE, MANIFEST_FILE, SHARD_ID_RE, SHARDS_DIR, check_shard_id
from synth.errors import SynthError
from synth.io import atomic_place, atomic_write_bytes, dumps_json, file_digest, is_temp_name

SHARD_FORMATS = ("dir", "tar")
TAR_SUFFIX = ".tar"
TAR_MANIFEST_SUFFIX = ".tar.json"
CONTAINER_FORMAT = "tar"
BLOCK = tarfile.BLOCKSIZE  # 512
#: Largest member synth reads from a tar (bytes); a larger one is refused, never read.
MAX_MEMBER_BYTES = 1 << 30
MEMBER_MODE = 0o444


def check_shard_format(fmt, where: str | None = None) -> str:
    if fmt not in SHARD_FORMATS:
        raise SynthError(f"unknown shard format {fmt!r}", where, f"use one of: {', '.join(SHARD_FORMATS)}")
    return fmt


def tar_path(root: Path, shard_id: str) -> Path:
    """``DIR/shards/<id>.tar``."""
    return Path(root) / SHARDS_DIR / f"{check_shard_id(shard_id)}{TAR_SUFFIX}"


def tar_manifest_path(root: Path, shard_id: str) -> Path:
    """``DIR/shards/<id>.tar.json``: the manifest of a tar shard; its presence commits the shard."""
    return Path(root) / SHARDS_DIR / f"{check_shard_id(shard_id)}{TAR_MANIFEST_SUFFIX}"


def _kind(path: Path) -> str | None:
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    return "dir" if stat.S_ISDIR(mode) else "file" if stat.S_ISREG(mode) else "other"


def committed_forms(root: Path, shard_id: str) -> list[str]:
    """The forms in which ``shard_id`` is present under ``shards/``: ``"dir"`` (a directory
    ``shards/<id>``) and/or ``"tar"`` (a manifest ``shards/<id>.tar.json``). Whether the
    manifest is valid is not checked here."""
    out = []
    if os.path.lexists(Path(root) / SHARDS_DIR / check_shard_id(shard_id)):
        out.append("dir")
    if os.path.lexists(tar_manifest_path(root, shard_id)):
        out.append("tar")
    return out


def manifest_file(root: Path, shard_id: str) -> Path:
    """Where the manifest of ``shard_id`` is: ``shards/<id>.tar.json`` for a tar shard, else
    ``shards/<id>/manifest.json`` (which may not exist)."""
    tp = tar_manifest_path(root, shard_id)
    return tp if os.path.lexists(tp) else Path(root) / SHARDS_DIR / shard_id / MANIFEST_FILE


class ShardEntries(NamedTuple):
    """What ``shards/`` holds, by name: ``dirs`` and ``tars`` (shard ids with a directory, or a
    ``.tar.json`` manifest), ``orphans`` (``<id>.tar`` without its manifest: a commit killed
    before its commit point), ``temps`` (leftover temporary files) and ``others``."""

    dirs: list[str]
    tars: list[str]
    orphans: list[str]
    temps: list[str]
    others: list[str]


def shard_entries(root: Path) -> ShardEntries:
    base = Path(root) / SHARDS_DIR
    try:
        names = sorted(os.listdir(base))
    except FileNotFoundError:
        names = []
    dirs, tars, orphans, temps, others = [], [], [], [], []
    present = set(names)
    for n in names:
        if is_temp_name(n):
            temps.append(n)
        elif n.endswith(TAR_MANIFEST_SUFFIX) and SHARD_ID_RE.match(n[:-len(TAR_MANIFEST_SUFFIX)]):
            tars.append(n[:-len(TAR_MANIFEST_SUFFIX)])
        elif n.endswith(TAR_SUFFIX) and SHARD_ID_RE.match(n[:-len(TAR_SUFFIX)]):
            if n + ".json" not in present:
                orphans.append(n[:-len(TAR_SUFFIX)])
        elif _kind(base / n) == "dir":
            dirs.append(n)
        else:
            others.append(n)
    return ShardEntries(dirs, tars, orphans, temps, others)


def manifest_paths(root: Path) -> list[tuple[str, Path]]:
    """(shard id, manifest path) of every shard present under ``shards/`` in either form,
    sorted; a shard present in both forms is listed twice (``synth validate`` reports it)."""
    root = Path(root)
    e = shard_entries(root)
    out = [(s, root / SHARDS_DIR / s / MANIFEST_FILE) for s in e.dirs if SHARD_ID_RE.match(s)]
    out += [(s, tar_manifest_path(root, s)) for s in e.tars]
    return sorted(out)


# --------------------------------------------------------------------------- writing


def _member_info(name: str, size: int) -> tarfile.TarInfo:
    ti = tarfile.TarInfo(name)
    ti.size, ti.mode, ti.mtime, ti.type = size, MEMBER_MODE, 0, tarfile.REGTYPE
    ti.uid = ti.gid = 0
    ti.uname = ti.gname = ""
    return ti


def write_tar(fileobj: IO[bytes], members: list[tuple[str, Path]]) -> dict[str, int]:
    """Write ``members`` (name, source file) as a deterministic ustar archive, in name order;
    returns each member's data offset. Names must be flat frame-file names."""
    offsets = {}
    with tarfile.open(fileobj=fileobj, mode="w", format=tarfile.USTAR_FORMAT) as tf:
        for name, src in sorted(members):
            _check_member_name(name, str(src))
            with open(src, "rb") as f:
                ti = _member_info(name, os.fstat(f.fileno()).st_size)
                offsets[name] = tf.offset + len(ti.tobuf(tf.format, tf.encoding, tf.errors))
                tf.addfile(ti, f)
    return offsets


def place_tar_shard(src_dir: Path, root: Path, shard_id: str, manifest: dict, *, check: Callable[[], None],
                    durable: bool = True) -> bytes:
    """Commit the staged files listed in ``manifest["files"]`` (in ``src_dir``) as a tar shard:
    write ``shards/<id>.tar`` under a temporary name, fsync it, call ``check()`` (the caller's
    last check, e.g. that it still holds the shard's lease; an exception aborts and leaves
    nothing), rename it into place, then write ``shards/<id>.tar.json`` atomically: the commit
    point. Fills in the manifest's member offsets and ``container``; returns the manifest's
    bytes. The caller refuses an already committed shard first and removes its staging after."""
    tp, mp = tar_path(root, shard_id), tar_manifest_path(root, shard_id)
    tp.parent.mkdir(exist_ok=True)
    for n in os.listdir(tp.parent):  # temp tars of this shard left by a killed commit (we hold the lease)
        if is_temp_name(n) and n.startswith(f".{tp.name}."):
            os.unlink(tp.parent / n)
    names = sorted(manifest["files"])
    container: dict = {}

    def fill(tmp: Path) -> None:
        with open(tmp, "xb") as f:
            offsets = write_tar(f, [(n, Path(src_dir) / n) for n in names])
        os.chmod(tmp, MEMBER_MODE)
        digest, size = file_digest(tmp, sync=durable)
        container.update(format=CONTAINER_FORMAT, file=tp.name, sha256=digest, bytes=size)
        for n in names:
            manifest["files"][n]["offset"] = offsets[n]
        check()

    # replaces the orphan tar of a killed commit, never a committed one (that has a manifest)
    atomic_place(tp, fill, durable=durable, sync_file=False)
    manifest["container"] = container
    data = dumps_json(manifest)
    atomic_write_bytes(mp, data, durable=durable)  # the commit point
    os.chmod(mp, MEMBER_MODE)
    return data


# --------------------------------------------------------------------------- reading


class TarRefused(SynthError):
    """A tar member (or the tar itself) that synth does not read; ``what`` says why."""


def _check_member_name(name: str, where: str) -> str:
    """``KEY.exr`` / ``KEY.json`` with a valid frame key, nothing else; returns the key."""
    stem, dot, ext = name.partition(".")
    if not dot or ext not in ("exr", "json") or not FRAME_KEY_RE.match(stem):
        shown = name if len(name) < 120 else name[:117] + "..."
        raise TarRefused(f"tar member {shown!r} is not a frame file (KEY.exr or KEY.json with a flat name)", where,
                         "this is not a synth tar shard; re-render the shard")
    return stem


class Member(NamedTuple):
    name: str
    key: str
    offset: int  # of the data, from the start of the tar
    size: int
    data: bytes | None


def _skip(f: IO[bytes], n: int) -> None:
    if n <= 0:
        return
    try:
        f.seek(n, os.SEEK_CUR)
    except (AttributeError, OSError, ValueError):  # a pipe or socket: read and drop
        while n > 0:
            got = f.read(min(n, 1 << 20))
            if not got:
                return
            n -= len(got)


def iter_members(f: IO[bytes], where: str, *, max_bytes: int = MAX_MEMBER_BYTES,
                 select: Callable[[str, int], bool] | None = None) -> Iterator[Member]:
    """The members of a synth tar shard read from ``f`` (at its start), in one forward pass.

    Strict: each header must have a valid checksum and describe a regular file with a flat
    frame-file name and at most ``max_bytes`` bytes; raises :class:`TarRefused` otherwise,
    before reading that member's data. ``select(name, size)`` says whose data to read (default:
    every member's); the others are skipped and come with ``data=None``. Stops at the
    end-of-archive block.
    """
    pos = 0
    while True:
        buf = f.read(BLOCK)
        if len(buf) < BLOCK:
            raise TarRefused(f"tar ends without an end-of-archive block (at byte {pos + len(buf)})", where,
                             "the tar is truncated; re-render the shard")
        if buf == bytes(BLOCK):
            return
        try:
            ti = tarfile.TarInfo.frombuf(buf, tarfile.ENCODING, "surrogateescape")
        except tarfile.HeaderError as e:
            raise TarRefused(f"bad tar header at byte {pos} ({e})", where, "the tar is damaged; re-render the shard") \
                from None
        if ti.type not in (tarfile.REGTYPE, tarfile.AREGTYPE):
            kind = {tarfile.SYMTYPE: "a symbolic link", tarfile.LNKTYPE: "a hard link", tarfile.DIRTYPE: "a directory",
                    tarfile.XHDTYPE: "a pax header", tarfile.XGLTYPE: "a pax global header",
                    tarfile.GNUTYPE_LONGNAME: "a GNU long-name header"}.get(ti.type, f"of type {ti.type!r}")
            raise TarRefused(f"tar member {ti.name[:120]!r} at byte {pos} is {kind}, not a regular file", where,
                             "synth tar shards hold regular files only; re-render the shard")
        key = _check_member_name(ti.name, where)
        if ti.size > max_bytes:
            raise TarRefused(f"tar member {ti.name} has {ti.size} bytes (limit {max_bytes})", where,
                             "this is not a synth frame; re-render the shard")
        data_at = pos + BLOCK
        padded = -(-ti.size // BLOCK) * BLOCK
        data = None
        if select is None or select(ti.name, ti.size):
            data = f.read(ti.size)
            if len(data) < ti.size:
                raise TarRefused(f"tar member {ti.name} is truncated ({len(data)} of {ti.size} bytes)", where,
                                 "the tar is truncated; re-render the shard")
            _skip(f, padded - ti.size)
        else:
            _skip(f, padded)
        pos = data_at + padded
        yield Member(ti.name, key, data_at, ti.size, data)


def read_member(path: Path, offset: int, size: int, where: str | None = None) -> bytes:
    """``size`` bytes at ``offset`` of a tar file (a member's data, offsets from the manifest)."""
    if not (isinstance(offset, int) and isinstance(size, int) and 0 <= size <= MAX_MEMBER_BYTES and offset >= BLOCK
            and offset % BLOCK == 0):
        raise SynthError(f"bad member offset/size in the manifest ({offset!r}, {size!r})", where or str(path),
                         "run `synth validate` on the dataset")
    with open(path, "rb") as f:
        f.seek(offset)
        data = f.read(size)
    if len(data) != size:
        raise SynthError(f"tar ends before the member's {size} bytes at offset {offset}", where or str(path),
                         "run `synth validate` on the dataset")
    return data
