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
same); the tar is made at commit in two steps. :func:`build_tar_shard` writes it to a
temporary name in ``shards/`` and fsyncs it, which gives the manifest's bytes; the commit
signs them (:func:`synth.dataset.index.commit_shard`: the commit record), then, under the
dataset lock, :func:`place_tar_shard` renames the tar to ``<id>.tar`` and writes the manifest
``<id>.tar.json`` atomically, which is the commit point (a tar without its manifest is the
leftover of a killed commit: not committed, replaced by the next commit); then the staging
directory is removed.

Reading back, :func:`iter_members` walks a tar's 512-byte headers one at a time with
``tarfile.TarInfo.frombuf`` (which checks each header's checksum) and accepts only what this
writer makes: plain ustar regular-file members with a flat ``KEY.exr`` / ``KEY.json`` name
and a bounded size. Anything else (links, directories, devices, pax or GNU extension
headers, ``..`` or absolute names) is refused before its data is read.
"""

from __future__ import annotations

import os
import tarfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, NamedTuple

from synth.dataset.layout import FRAME_KEY_RE, MANIFEST_FILE, SHARD_ID_RE, SHARDS_DIR, check_shard_id, entry_kind
from synth.errors import SynthError
from synth.io import FileRefused, atomic_write_bytes, file_digest, fsync_dir, is_temp_name, open_regular, temp_name

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


def committed_forms(root: Path, shard_id: str) -> list[str]:
    """The forms in which ``shard_id`` is present under ``shards/``: ``"dir"`` (an entry
    ``shards/<id>``) and/or ``"tar"`` (an entry ``shards/<id>.tar.json``), of whatever kind
    (not following links). Whether they are valid (and signed) is not checked here."""
    out = []
    if os.path.lexists(Path(root) / SHARDS_DIR / check_shard_id(shard_id)):
        out.append("dir")
    if os.path.lexists(tar_manifest_path(root, shard_id)):
        out.append("tar")
    return out


def manifest_file(root: Path, shard_id: str) -> Path:
    """Where the manifest of ``shard_id`` is: ``shards/<id>/manifest.json`` when there is a
    directory ``shards/<id>`` (a shard in both forms is read as its directory), else
    ``shards/<id>.tar.json`` when that is there, else the directory's (which does not exist)."""
    d = Path(root) / SHARDS_DIR / check_shard_id(shard_id)
    tp = tar_manifest_path(root, shard_id)
    return tp if not os.path.lexists(d) and os.path.lexists(tp) else d / MANIFEST_FILE


class ShardEntries(NamedTuple):
    """What ``shards/`` holds, by name, never following a link (:func:`entry_kind`):

    - ``dirs``: names of real directories (shard directories, or strays whose name is not a
      shard id: ``synth validate`` reports those);
    - ``tars``: shard ids whose manifest ``<id>.tar.json`` is a regular file (``<id>.tar``
      belongs to it, whatever it is: validate checks it);
    - ``orphans``: shard ids with a regular file ``<id>.tar`` and no ``<id>.tar.json`` at all
      (a commit killed before its commit point, or a stray tar);
    - ``temps``: regular files with temporary names (leftovers of a killed commit);
    - ``others``: every other name -> its kind: links, devices, FIFOs, stray files (not opened);
    - ``kinds``: every name -> its kind.
    """

    dirs: list[str]
    tars: list[str]
    orphans: list[str]
    temps: list[str]
    others: dict[str, str]
    kinds: dict[str, str]


def shard_entries(root: Path) -> ShardEntries:
    base = Path(root) / SHARDS_DIR
    try:
        names = sorted(os.listdir(base))
    except (FileNotFoundError, NotADirectoryError):
        names = []
    kinds = {n: entry_kind(base / n) for n in names}
    kinds = {n: k for n, k in kinds.items() if k is not None}  # gone since the listing
    dirs, tars, orphans, temps, others = [], [], [], [], {}
    for n, k in kinds.items():
        tar_id = n[:-len(TAR_SUFFIX)] if n.endswith(TAR_SUFFIX) else ""
        man_id = n[:-len(TAR_MANIFEST_SUFFIX)] if n.endswith(TAR_MANIFEST_SUFFIX) else ""
        if k == "dir" and not is_temp_name(n):
            dirs.append(n)
        elif k == "file" and is_temp_name(n):
            temps.append(n)
        elif k == "file" and SHARD_ID_RE.match(man_id):
            tars.append(man_id)
        elif SHARD_ID_RE.match(tar_id) and n + ".json" in kinds:
            continue  # the tar of a tar shard (checked with it; a manifest that is not a file is reported)
        elif k == "file" and SHARD_ID_RE.match(tar_id):
            orphans.append(tar_id)
        else:
            others[n] = k
    return ShardEntries(dirs, tars, orphans, temps, others, kinds)


def manifest_paths(root: Path, entries: ShardEntries | None = None) -> list[tuple[str, Path]]:
    """(shard id, manifest path) of every shard present under ``shards/`` as a real directory
    or a regular ``.tar.json`` manifest, sorted; a shard present in both forms is listed twice,
    its directory first (``synth validate`` reports it)."""
    root = Path(root)
    e = entries or shard_entries(root)
    out = [(s, root / SHARDS_DIR / s / MANIFEST_FILE) for s in e.dirs if SHARD_ID_RE.match(s)]
    out += [(s, tar_manifest_path(root, s)) for s in e.tars]
    return sorted(out)


def present_shards(root: Path, entries: ShardEntries | None = None) -> dict[str, Path]:
    """Shard id -> its manifest path, for every shard present in a real form (a shard in both
    forms: its directory's)."""
    out: dict[str, Path] = {}
    for s, mp in manifest_paths(root, entries):
        out.setdefault(s, mp)
    return out


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


def build_tar_shard(src_dir: Path, root: Path, shard_id: str, manifest: dict, *, durable: bool = True) -> Path:
    """The first step of a tar commit: write the staged files listed in ``manifest["files"]``
    (in ``src_dir``) as a tar under a temporary name in ``shards/`` and fsync it; fill in the
    manifest's member offsets and ``container``. Returns the temporary path (the caller removes
    it if it does not get to :func:`place_tar_shard`). Temporary tars of this shard left by a
    killed commit are removed first (the caller holds the shard's lease)."""
    tp = tar_path(root, shard_id)
    tp.parent.mkdir(exist_ok=True)
    for n in os.listdir(tp.parent):
        if is_temp_name(n) and n.startswith(f".{tp.name}."):
            os.unlink(tp.parent / n)
    names = sorted(manifest["files"])
    tmp = temp_name(tp)
    try:
        with open(tmp, "xb") as f:
            offsets = write_tar(f, [(n, Path(src_dir) / n) for n in names])
        os.chmod(tmp, MEMBER_MODE)
        digest, size = file_digest(tmp, sync=durable)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    for n in names:
        manifest["files"][n]["offset"] = offsets[n]
    manifest["container"] = {"format": CONTAINER_FORMAT, "file": tp.name, "sha256": digest, "bytes": size}
    return tmp


def place_tar_shard(tmp: Path, root: Path, shard_id: str, data: bytes, *, durable: bool = True) -> None:
    """The second step, the commit itself (under the dataset lock, after the commit record
    signed ``data``): rename the tar built by :func:`build_tar_shard` to ``shards/<id>.tar``
    (replacing the orphan tar of a killed commit; the caller refused an already committed
    shard), then write the manifest ``data`` as ``shards/<id>.tar.json``, read-only, atomically:
    the commit point."""
    tp, mp = tar_path(root, shard_id), tar_manifest_path(root, shard_id)
    os.replace(tmp, tp)
    if durable:  # the tar's rename is durable before the manifest can be
        fsync_dir(tp.parent)
    atomic_write_bytes(mp, data, durable=durable, mode=MEMBER_MODE)  # the commit point


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
    try:
        fd, _ = open_regular(path)  # never a FIFO or a device
    except FileRefused as e:
        raise SynthError(f"tar shard refused: it {e.what}", where or str(path), "run `synth validate` on the dataset") \
            from None
    with os.fdopen(fd, "rb") as f:
        f.seek(offset)
        data = f.read(size)
    if len(data) != size:
        raise SynthError(f"tar ends before the member's {size} bytes at offset {offset}", where or str(path),
                         "run `synth validate` on the dataset")
    return data
