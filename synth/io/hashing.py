"""sha256 of bytes and of files (read in 1 MiB blocks, optionally fsynced on the way)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

BLOCK = 1 << 20


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def file_digest(path: str | os.PathLike, *, sync: bool = False) -> tuple[str, int]:
    """(sha256 hex digest, size in bytes) of a file; with ``sync`` the file is also fsynced
    through the same descriptor (one pass over a file that is about to be committed)."""
    h = hashlib.sha256()
    n = 0
    fd = os.open(Path(path), os.O_RDONLY)
    try:
        while True:
            b = os.read(fd, BLOCK)
            if not b:
                break
            h.update(b)
            n += len(b)
        if sync:
            os.fsync(fd)
    finally:
        os.close(fd)
    return h.hexdigest(), n


def sha256_file(path: str | os.PathLike) -> str:
    return file_digest(path)[0]
