"""Deterministic fan-out over forked processes.

``fork_map(fn, items, jobs)`` returns ``[fn(x) for x in items]``; with ``jobs > 1`` the calls
run in forked children, which share the parent's memory (the arrays ``fn`` closes over are
not copied or pickled; only the results travel back). Every item's result is a pure
function of the item, so the output never depends on ``jobs``: tests compare 1 and 2.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
from typing import Any, Callable, Sequence

_FN: Callable[[Any], Any] | None = None


def _call(x):
    assert _FN is not None
    return _FN(x)


def _child_init() -> None:
    """Forked children take the default SIGTERM (a handler inherited from the parent, e.g. a
    command's graceful shutdown, would let ``Pool.terminate`` wait forever on a child blocked
    on the task queue) and leave Ctrl-C to the parent."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def fork_map(fn: Callable[[Any], Any], items: Sequence[Any], jobs: int) -> list:
    global _FN
    if jobs <= 1 or len(items) <= 1 or "fork" not in mp.get_all_start_methods():
        return [fn(x) for x in items]
    _FN = fn
    try:
        with mp.get_context("fork").Pool(min(jobs, len(items)), initializer=_child_init) as pool:
            out = pool.map(_call, items, chunksize=1)
            pool.close()  # children leave on the queue's sentinel; no terminate() needed
            pool.join()
            return out
    finally:
        _FN = None


def chunks(n: int, parts: int) -> list[tuple[int, int]]:
    """Split range(n) into up to ``parts`` contiguous, nearly equal [a, b) ranges."""
    parts = max(1, min(parts, n))
    edges = [round(n * k / parts) for k in range(parts + 1)]
    return [(edges[k], edges[k + 1]) for k in range(parts) if edges[k] < edges[k + 1]]
