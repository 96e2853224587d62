"""The worker protocol: progress events as JSON lines, one module for both sides.

A render worker (``blender_scripts/worker.py``) writes one event per line on stdout with
:func:`emit`; a backend reads the worker's stdout and turns each line into an event with
:func:`parse_line`. bpy and Cycles print to the same stdout, so lines that are not events
(plain text, JSON that is not an event object) parse to ``None``; a line that is an event
but of another protocol version, of an unknown kind or with bad fields raises
:class:`EventError`, because a worker from another synth version must not go unnoticed.

Wire format (``docs/farm.md``)::

    {"v": 1, "event": "frame", "shard": "shard_000000", "key": "id000000_ex00_v00", "render_seconds": 1.25}

Events sent by workers: ``start``, ``frame``, ``rss``, ``skip``, ``commit``, ``error``,
``heartbeat``. ``batch_end`` is made by the backend when a worker process ends (its exit
status and the tail of its log); it shares the encoding so a backend can log every event in
one format (the remote backends write it into the attempt's log, where the controller reads it).

A worker's exit status is part of the protocol: :data:`EXIT_OK`, :data:`EXIT_INPUT` (a
user-facing error, reported with an ``error`` event; a retry would repeat it),
:data:`EXIT_DISK_FULL` (an ``error`` event names the path and the space left), 128 + the
signal number when told to stop (:func:`stopped_by_signal`); anything else is a crash, and
a backend retries the batch.
"""

from __future__ import annotations

import json
import math
import sys
import threading
from dataclasses import asdict, dataclass, fields
from typing import IO, ClassVar, Union

from synth.io.jsonio import MAX_DEPTH, json_depth

#: Bumped whenever an event's fields change meaning or a required field is added.
PROTOCOL_VERSION = 2

#: Worker exit statuses (see the module docstring).
EXIT_OK = 0
EXIT_INPUT = 2
EXIT_DISK_FULL = 4


def stopped_by_signal(returncode: int) -> bool:
    """The worker stopped because it was told to (SIGTERM, SIGINT, SIGHUP): not a crash to retry.
    ``returncode`` as ``subprocess`` gives it (negative: killed by that signal without a handler)."""
    import signal

    stops = {signal.SIGTERM, signal.SIGINT, signal.SIGHUP}
    return returncode in {128 + s for s in stops} or -returncode in stops


def should_retry(returncode: int, reported_error: bool) -> bool:
    """Whether a batch whose worker ended so is worth running again: a crash (non-zero, no
    ``error`` event, not a stop, not out of disk space)."""
    return (returncode != EXIT_OK and not reported_error and returncode != EXIT_DISK_FULL
            and not stopped_by_signal(returncode))


class EventError(ValueError):
    """A line that claims to be an event but cannot be one of this protocol version."""


@dataclass(frozen=True)
class Start:
    """A worker process is up and will render ``shards`` (in order)."""
    kind: ClassVar[str] = "start"
    shards: tuple[str, ...]
    pid: int
    host: str


@dataclass(frozen=True)
class Rss:
    """The worker's resident memory after an identity's scene was closed."""
    kind: ClassVar[str] = "rss"
    rss_mb: float


@dataclass(frozen=True)
class Heartbeat:
    """The worker is alive (sent every few seconds by its lease heartbeat, also mid-render);
    ``shards`` are the shards it holds now. A backend's watchdog stops a silent worker."""
    kind: ClassVar[str] = "heartbeat"
    shards: tuple[str, ...]


@dataclass(frozen=True)
class _ShardEvent:
    """An event about one shard."""
    kind: ClassVar[str] = ""
    shard: str


@dataclass(frozen=True)
class Frame(_ShardEvent):
    """One frame staged (EXR + JSON written); ``render_seconds`` is the time inside Cycles."""
    kind: ClassVar[str] = "frame"
    key: str
    render_seconds: float


class Skip(_ShardEvent):
    """The shard was not rendered: committed meanwhile, or another process holds it."""
    kind: ClassVar[str] = "skip"


class Commit(_ShardEvent):
    """The shard was committed (renamed into ``shards/``)."""
    kind: ClassVar[str] = "commit"


@dataclass(frozen=True)
class Error(_ShardEvent):
    """The worker stopped on a user-facing error; ``shard`` names the shard(s) it held."""
    kind: ClassVar[str] = "error"
    message: str


@dataclass(frozen=True)
class BatchEnd:
    """Made by a backend, not a worker: the process for batch ``batch`` (attempt ``attempt``,
    from 0) ended with ``returncode``; ``log_tail`` holds the last lines of its log, and
    ``retry`` says whether the backend runs the batch again."""
    kind: ClassVar[str] = "batch_end"
    batch: int
    shards: tuple[str, ...]
    attempt: int
    returncode: int
    log_tail: str
    retry: bool


Event = Union[Start, Frame, Rss, Heartbeat, Skip, Commit, Error, BatchEnd]
EVENT_TYPES: dict[str, type] = {t.kind: t for t in (Start, Frame, Rss, Heartbeat, Skip, Commit, Error, BatchEnd)}


def encode(ev: Event) -> str:
    """One JSON line (without the newline); version and kind first."""
    return json.dumps({"v": PROTOCOL_VERSION, "event": ev.kind, **asdict(ev)}, allow_nan=False)


_EMIT_LOCK = threading.Lock()


def emit(ev: Event, stream: IO[str] | None = None) -> None:
    """Write ``ev`` as one line to ``stream`` (default: stdout) and flush it at once (a lock
    keeps lines whole when several threads emit)."""
    out = sys.stdout if stream is None else stream
    line = encode(ev) + "\n"
    with _EMIT_LOCK:
        out.write(line)
        out.flush()


def _field(kind: str, name: str, annotation: str, value):
    bad = EventError(f"{kind} event: field {name!r} is {value!r}, not {annotation}")
    if annotation == "str":
        if not isinstance(value, str):
            raise bad
        return value
    if annotation == "bool":
        if not isinstance(value, bool):
            raise bad
        return value
    if annotation == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad
        return value
    if annotation == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise bad
        return float(value)
    if annotation == "tuple[str, ...]":
        if not isinstance(value, list) or not all(isinstance(s, str) for s in value):
            raise bad
        return tuple(value)
    raise AssertionError(f"unhandled field type {annotation}")  # a new field type needs a case here


def from_dict(d: dict) -> Event:
    """The event a decoded JSON object describes; raises :class:`EventError`."""
    if d.get("v") != PROTOCOL_VERSION:
        raise EventError(f"event of protocol version {d.get('v')!r}, expected {PROTOCOL_VERSION} "
                         "(worker and controller from different synth versions?)")
    kind = d.get("event")
    cls = EVENT_TYPES.get(kind)  # type: ignore[arg-type]
    if cls is None:
        raise EventError(f"unknown event {kind!r}")
    args = {}
    for f in fields(cls):
        if f.name not in d:
            raise EventError(f"{kind} event lacks field {f.name!r}")
        args[f.name] = _field(kind, f.name, f.type, d[f.name])
    return cls(**args)


def parse_line(line: str) -> Event | None:
    """The event on one line of worker output, or ``None`` for a line that is not an event.

    Text before the first ``{`` is ignored (a line that bpy started without a newline)."""
    start = line.find("{")
    if start < 0:
        return None
    text = line[start:]
    if json_depth(text.encode("utf-8", "surrogatepass")) > MAX_DEPTH:  # deeper than any event: not one
        return None
    try:
        d = json.loads(text)  # NaN/Infinity parse here, so that from_dict refuses them as an EventError
    except ValueError:  # not JSON
        return None
    if not isinstance(d, dict) or "event" not in d:
        return None
    return from_dict(d)
