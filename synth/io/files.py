"""Crash-safe file primitives: write to a temporary name, fsync, rename, fsync the directory.

A reader never sees a half-written file or directory under its final name: either the old
state or the new one. Temporary names start with ``.`` and end with ``.tmp`` (see
:func:`is_temp_name`) so that leftovers of a killed process are easy to recognise and remove.
"""

from __future__ import annotations

import os
import secrets
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

TMP_SUFFIX = ".tmp"


def temp_name(final: Path) -> Path:
    """A unique temporary path next to ``final`` (same directory, so rename is atomic)."""
    final = Path(final)
    return final.with_name(f".{final.name}.{os.getpid()}.{secrets.token_hex(4)}{TMP_SUFFIX}")


def is_temp_name(name: str) -> bool:
    return name.startswith(".") and name.endswith(TMP_SUFFIX)


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
    except BaseException:
        _remove(tmp)
        raise
    if durable:
        fsync_dir(path.parent)


def atomic_write_bytes(path: Path, data: bytes, *, durable: bool = True) -> None:
    """Write ``data`` to ``path`` atomically: temp file (mode 0644 less the umask), fsync,
    rename over, fsync the directory. On any error the temporary file is removed and ``path``
    is left as it was."""

    def fill(tmp: Path) -> None:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
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


@contextmanager
def atomic_dir(final: Path, *, durable: bool = True) -> Iterator[Path]:
    """A directory that appears at ``final`` complete or not at all.

    The body fills the yielded temporary directory (next to ``final``: same filesystem). On
    normal exit it is renamed to ``final``, which must be absent or an empty directory (it is
    replaced), and the parent is fsynced (``durable``; the body fsyncs the files it needs
    durable). On an exception it is removed and ``final`` is left as it was. A body that
    decides to keep ``final`` as it is removes the temporary directory itself; nothing is
    renamed then."""
    final = Path(final)
    tmp = temp_name(final)
    tmp.mkdir()
    try:
        yield tmp
        if tmp.exists():
            if final.exists():
                final.rmdir()  # empty, or this raises: never replace a directory with content
            os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if durable:
        fsync_dir(final.parent)
