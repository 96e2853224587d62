"""Crash-safe file primitives: write to a temporary name, fsync, rename, fsync the directory.

A reader never sees a half-written file under its final name: either the old state or the new
one. Temporary names start with ``.`` and end with ``.tmp`` (see :func:`is_temp_name`) so that
leftovers of a killed process are easy to recognise and remove.
"""

from __future__ import annotations

import hashlib
import json
import os
import secrets
from pathlib import Path

TMP_SUFFIX = ".tmp"


def temp_name(final: Path) -> Path:
    """A unique temporary path next to ``final`` (same directory, so rename is atomic)."""
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


def atomic_place(path: Path, fill, *, durable: bool = True, sync_file: bool = True) -> None:
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
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(e, OSError) and e.filename is None:  # os.write says no name: "disk full writing WHAT?"
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise
    if durable:
        fsync_dir(path.parent)


def atomic_write_bytes(path: Path, data: bytes, *, durable: bool = True, mode: int | None = None) -> None:
    """Write ``data`` to ``path`` atomically: temp file, fsync, rename over, fsync directory.

    On any error the temporary file is removed and ``path`` is left as it was.
    """

    def fill(tmp: Path) -> None:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644 if mode is None else mode)
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


def dumps_json(obj, *, indent: int | None = 1) -> bytes:
    """Strict JSON (NaN/Infinity refused: they are not JSON), UTF-8, trailing newline."""
    return (json.dumps(obj, indent=indent, allow_nan=False, ensure_ascii=False) + "\n").encode("utf-8")


def _refuse_constant(name: str):
    raise ValueError(f"non-standard JSON constant {name}")


def loads_json(data: bytes | str):
    """Strict JSON parsing: ``NaN``/``Infinity`` are rejected (Python's json accepts them)."""
    return json.loads(data, parse_constant=_refuse_constant)


def atomic_write_json(path: Path, obj, *, durable: bool = True, indent: int | None = 1) -> bytes:
    """Atomically write ``obj`` as strict JSON; returns the bytes written."""
    data = dumps_json(obj, indent=indent)
    atomic_write_bytes(path, data, durable=durable)
    return data


def sha256_file(path: Path, bufsize: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while True:
            b = f.read(bufsize)
            if not b:
                break
            h.update(b)
    return h.hexdigest()


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()
