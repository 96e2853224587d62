"""sha256 of bytes and of files (read in 1 MiB blocks, optionally fsynced on the way; regular
files only, optionally without following a symbolic link and bounded in size)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from synth.io.files import FileRefused, open_regular

BLOCK = 1 << 20


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def file_digest(path: str | os.PathLike, *, sync: bool = False, max_bytes: int | None = None,
                follow_symlinks: bool = True) -> tuple[str, int]:
    """(sha256 hex digest, size in bytes) of a regular file; with ``sync`` the file is also
    fsynced through the same descriptor (one pass over a file that is about to be committed).
    More than ``max_bytes`` bytes, or a symbolic link with ``follow_symlinks=False``, raise
    :class:`synth.io.files.FileRefused` (so a check never reads without end)."""
    h = hashlib.sha256()
    n = 0
    fd, _ = open_regular(Path(path), follow_symlinks=follow_symlinks)
    try:
        while True:
            b = os.read(fd, BLOCK)
            if not b:
                break
            h.update(b)
            n += len(b)
            if max_bytes is not None and n > max_bytes:
                raise FileRefused(path, f"has more than the {max_bytes} bytes expected")
        if sync:
            os.fsync(fd)
    finally:
        os.close(fd)
    return h.hexdigest(), n


def sha256_file(path: str | os.PathLike) -> str:
    return file_digest(path)[0]
