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


def return_freed_memory() -> bool:
    """Hand the heap's freed pages back to the system (glibc ``malloc_trim``) after a phase that
    made and dropped many small arrays, so that they do not stay in this process's resident
    memory for the rest of a long run. False where there is no glibc (nothing to do)."""
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return False
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return bool(trim(0))


def default_jobs(cap: int = 4) -> int:
    """Worker processes when the user gives none: the CPUs this process may run on, at most ``cap``."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        n = os.cpu_count() or 1
    return max(1, min(cap, n))
