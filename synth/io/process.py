"""Facts about the running process."""

from __future__ import annotations

import os
import resource


def rss_mb() -> float:
    """Resident memory of this process now (MiB), from /proc; where that cannot be read, the
    peak so far (``getrusage``)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def default_jobs(cap: int = 4) -> int:
    """Worker processes when the user gives none: the CPUs this process may run on, at most ``cap``."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        n = os.cpu_count() or 1
    return max(1, min(cap, n))
