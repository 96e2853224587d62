"""User-facing errors: one clear line (what, where, what to do) and a documented exit code.

Exit codes of ``synth`` (README, "Exit codes"): 0 complete; 1 incomplete or defects found
(:class:`Incomplete`); 2 usage or input error (:class:`SynthError`); 3 a worker or task failed
after its retries (:class:`WorkerFailed`); 4 out of disk space (:class:`DiskFull`); 130
interrupted.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path


class SynthError(Exception):
    """An error caused by the user's input or environment.

    The CLI prints ``str(err)`` as a single line and exits with code 2.
    """

    exit_code = 2

    def __init__(self, what: str, where: str | None = None, fix: str | None = None):
        self.what = what
        self.where = where
        self.fix = fix
        parts = [what]
        if where:
            parts.append(f"({where})")
        msg = " ".join(parts)
        if fix:
            msg += f"; {fix}"
        super().__init__(msg)


class ModelFormatError(SynthError):
    """A head-model file is malformed or inconsistent."""


class CodeError(SynthError, ValueError):
    """An identity/expression/pose array has the wrong shape or non-finite values."""


class Incomplete(SynthError):
    """The work is not finished (shards held by other processes with --no-wait, defects found)."""

    exit_code = 1


class WorkerFailed(SynthError):
    """A render worker or farm task failed after its retries; rerunning resumes."""

    exit_code = 3


class DiskFull(SynthError):
    """Out of disk space (or quota) while writing; names the path and the space left."""

    exit_code = 4


def is_disk_full(err: BaseException) -> bool:
    """True for an OSError that means no space (ENOSPC) or an exhausted quota (EDQUOT)."""
    return isinstance(err, OSError) and err.errno in (errno.ENOSPC, errno.EDQUOT)


def disk_full(path, err: OSError | None = None) -> DiskFull:
    """The one-line :class:`DiskFull` for a failed write under ``path``, with the space left."""
    p = Path(path)
    probe = p
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    try:
        st = os.statvfs(probe)
        left = f"{st.f_bavail * st.f_frsize / 2**20:.1f} MiB left on {probe}"
    except OSError:
        left = f"space left on {probe} unknown"
    what = "disk quota exceeded" if err is not None and err.errno == errno.EDQUOT else "out of disk space"
    return DiskFull(f"{what} writing {p} ({left})", None,
                    "free some space (or choose another --out) and rerun the same command to resume")
