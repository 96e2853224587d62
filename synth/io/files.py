"""Crash-safe file primitives: write to a temporary name, fsync, rename, fsync the directory.

A reader never sees a half-written file or directory under its final name: either the old
state or the new one. Temporary names start with ``.`` and end with ``.tmp`` (see
:func:`is_temp_name`) so that leftovers of a killed process are easy to recognise and remove.
"""

from __future__ import annotations

import errno
import os
import secrets
import shutil
import stat
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

TMP_SUFFIX = ".tmp"


class FileRefused(ValueError):
    """A file that may not be read as asked: not a regular file (a symlink when links are not
    followed, a device, a FIFO, a directory) or larger than the bound. ``path`` names it."""

    def __init__(self, path, what: str):
        super().__init__(f"{os.fsdecode(path)} {what}")
        self.path, self.what = path, what


def open_regular(path, *, follow_symlinks: bool = True) -> tuple[int, os.stat_result]:
    """Open a regular file for reading: (descriptor, its fstat). Never blocks on a FIFO and,
    with ``follow_symlinks=False``, never follows a symbolic link at the last component; any
    other kind of file raises :class:`FileRefused`. The caller closes the descriptor."""
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    if not follow_symlinks:
        flags |= os.O_NOFOLLOW
    try:
        fd = os.open(path, flags)
    except OSError as e:
        if e.errno == errno.ELOOP and not follow_symlinks:
            raise FileRefused(path, "is a symbolic link") from None
        raise
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file"
            raise FileRefused(path, f"is {kind}")
    except BaseException:
        os.close(fd)
        raise
    return fd, st


def read_bounded(path, max_bytes: int, *, follow_symlinks: bool = True) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (:func:`open_regular`); a larger
    one (also one that grows while being read) raises :class:`FileRefused` before it is read."""
    fd, st = open_regular(path, follow_symlinks=follow_symlinks)
    try:
        if st.st_size > max_bytes:
            raise FileRefused(path, f"is {st.st_size} bytes, more than the {max_bytes} allowed")
        chunks, n = [], 0
        while True:
            b = os.read(fd, min(1 << 20, max_bytes + 1 - n))
            if not b:
                break
            chunks.append(b)
            n += len(b)
            if n > max_bytes:
                raise FileRefused(path, f"grew past the {max_bytes} bytes allowed while being read")
        return b"".join(chunks)
    finally:
        os.close(fd)


def temp_name(final: Path) -> Path:
    """A unique temporary path next to ``final`` (same directory, so rename is atomic)."""
    final = Path(final)
    return final.with_name(f".{final.name}.{os.getpid()}.{secrets.token_hex(4)}{TMP_SUFFIX}")


def is_temp_name(name: str) -> bool:
    return name.startswith(".") and name.endswith(TMP_SUFFIX)


@contextmanager
def created_dirs(path: Path) -> Iterator[Path]:
    """Create directory ``path`` and any missing parents; if the body raises, remove again
    those of them that are still empty (deepest first), so a refused command leaves the file
    system as it found it."""
    path = Path(path)
    missing = []
    p = path
    while not os.path.lexists(p) and p != p.parent:
        missing.append(p)
        p = p.parent
    path.mkdir(parents=True, exist_ok=True)
    try:
        yield path
    except BaseException:
        for d in missing:  # deepest first
            try:
                os.rmdir(d)
            except OSError:
                break
        raise


def fsync_dir(path: Path) -> None:
    """Make a rename/creation inside ``path`` durable (POSIX: fsync the directory)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _remove(path: Path) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


def atomic_place(path: Path, fill: Callable[[Path], object], *, durable: bool = True,
                 sync_file: bool = True) -> None:
    """Create ``path`` atomically: ``fill(tmp)`` writes a temp file next to it, which is fsynced
    (``sync_file``; skip it when ``fill`` already did), renamed over ``path``, and the directory
    fsynced. On any error the temporary file is removed and ``path`` is left as it was."""
    path = Path(path)
    tmp = temp_name(path)
    try:
        fill(tmp)
        if durable and sync_file:
            fsync_file(tmp)
        os.replace(tmp, path)
    except BaseException as e:
        _remove(tmp)
        if isinstance(e, OSError) and e.filename is None:  # os.write names no file: "disk full writing WHAT?"
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise
    if durable:
        fsync_dir(path.parent)


def atomic_write_bytes(path: Path, data: bytes, *, durable: bool = True, mode: int = 0o644) -> None:
    """Write ``data`` to ``path`` atomically: temp file (``mode`` less the umask), fsync,
    rename over, fsync the directory. On any error the temporary file is removed and ``path``
    is left as it was."""

    def fill(tmp: Path) -> None:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
        try:
            view = memoryview(data)
            while view:
                n = os.write(fd, view)
                view = view[n:]
            if durable:
                os.fsync(fd)
        finally:
            os.close(fd)

    atomic_place(path, fill, durable=durable, sync_file=False)


class DirectoryTaken(FileExistsError):
    """:func:`atomic_dir` found ``final`` filled by someone else when it came to rename."""

    def __init__(self, final: Path):
        super().__init__(errno.ENOTEMPTY, "directory is not empty", str(final))
        self.final = Path(final)


@contextmanager
def atomic_dir(final: Path, *, durable: bool = True) -> Iterator[Path]:
    """A directory that appears at ``final`` complete or not at all.

    The body fills the yielded temporary directory (next to ``final``: same filesystem). On
    normal exit it is renamed to ``final``, which must be absent or an empty directory (it is
    replaced), and the parent is fsynced (``durable``; the body fsyncs the files it needs
    durable). On an exception it is removed and ``final`` is left as it was. A body that
    decides to keep ``final`` as it is removes the temporary directory itself; nothing is
    renamed then. The rename is one ``rename(2)``, which replaces only an empty directory:
    when another process put content at ``final`` first, :class:`DirectoryTaken` is raised
    (the temporary directory removed), so the caller can compare and adopt what is there."""
    final = Path(final)
    tmp = temp_name(final)
    try:
        tmp.mkdir()
    except OSError as e:  # name the directory asked for, not the temporary name
        raise OSError(e.errno, e.strerror, str(final)) from None
    try:
        yield tmp
        if tmp.exists():
            try:
                os.rename(tmp, final)  # never replaces a directory with content
            except OSError as e:
                if e.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                    raise
                raise DirectoryTaken(final) from None
    except BaseException as e:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(e, OSError) and not isinstance(e, DirectoryTaken):  # name the file as it would have been
            name = os.fsdecode(e.filename) if e.filename is not None else str(tmp)
            if name == str(tmp) or name.startswith(str(tmp) + os.sep):
                raise OSError(e.errno, e.strerror, str(final) + name[len(str(tmp)):]) from e
        raise
    if durable:
        fsync_dir(final.parent)
