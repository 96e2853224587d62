"""The worker protocol (renderer_jobs.events): round trip, noise tolerance, bad events."""

from __future__ import annotations

import io
import json

import pytest

from renderer_jobs.events import (EVENT_TYPES, EXIT_DISK_FULL, EXIT_INPUT, PROTOCOL_VERSION, BatchEnd, Commit, Error,
                                  EventError, Frame, Heartbeat, Rss, Skip, Start, emit, encode, parse_line,
                                  should_retry, stopped_by_signal)

EXAMPLES = [
    Start(shards=("shard_000000", "shard_000001"), pid=4242, host="node-7"),
    Frame(shard="shard_000000", key="id000000_ex00_v00", render_seconds=1.25),
    Frame(shard="shard_000000", key="id000000_ex00_v01", render_seconds=0.0),
    Rss(rss_mb=612.5),
    Heartbeat(shards=("shard_000000",)),
    Skip(shard="shard_000001"),
    Commit(shard="shard_000000"),
    Error(shard="shard_000000,shard_000001", message='HDR environment file not found ("x.hdr"); restore it\n'),
    BatchEnd(batch=3, shards=("shard_000006",), attempt=1, returncode=-9, log_tail="line 1\nline 2 ü", retry=False),
    Start(shards=(), pid=1, host=""),
]


def test_every_event_type_has_an_example():
    assert {type(e) for e in EXAMPLES} == set(EVENT_TYPES.values())


@pytest.mark.parametrize("ev", EXAMPLES, ids=lambda e: e.kind)
def test_round_trip(ev):
    line = encode(ev)
    assert "\n" not in line
    d = json.loads(line)
    assert d["v"] == PROTOCOL_VERSION and d["event"] == ev.kind
    assert parse_line(line) == ev
    assert parse_line(line + "\n") == ev
    buf = io.StringIO()
    emit(ev, buf)
    assert buf.getvalue() == line + "\n"


def test_integer_seconds_read_as_float():
    ev = parse_line('{"v": 2, "event": "frame", "shard": "s", "key": "k", "render_seconds": 2}')
    assert ev == Frame("s", "k", 2.0) and isinstance(ev.render_seconds, float)


@pytest.mark.parametrize("line", [
    "", "\n", "Fra:1 Mem:12.00M (Peak 14.00M) | Time:00:00.01 | Sample 4/4",
    "Error: Not freed memory blocks: 3, total unfreed memory 0.001 MB",
    '{"v": 2, "event": "frame", "shard": "s"',  # cut off
    "{not json}", "[1, 2, 3]", '{"v": 2, "message": "a JSON object that is not an event"}', "{}",
    '"{\\"event\\": \\"frame\\"}"',  # a JSON string
    '{"v": 2, "event": "commit", "shard": "s"} trailing text',
])
def test_noise_is_not_an_event(line):
    assert parse_line(line) is None


def test_text_before_an_event_is_skipped():
    line = "Fra:1 Mem:12.00M " + encode(Commit("shard_000002"))
    assert parse_line(line) == Commit("shard_000002")


@pytest.mark.parametrize("d, needle", [
    ({"event": "commit", "shard": "s"}, "protocol version None"),
    ({"v": 1, "event": "commit", "shard": "s"}, "protocol version 1"),
    ({"v": "1", "event": "commit", "shard": "s"}, "protocol version '1'"),
    ({"v": 2, "event": "explode"}, "unknown event 'explode'"),
    ({"v": 2, "event": "commit"}, "lacks field 'shard'"),
    ({"v": 2, "event": "commit", "shard": 3}, "'shard' is 3"),
    ({"v": 2, "event": "frame", "shard": "s", "key": "k", "render_seconds": "1.5"}, "render_seconds"),
    ({"v": 2, "event": "frame", "shard": "s", "key": "k", "render_seconds": True}, "render_seconds"),
    ({"v": 2, "event": "rss", "rss_mb": None}, "rss_mb"),
    ({"v": 2, "event": "start", "shards": "shard_000000", "pid": 1, "host": "h"}, "shards"),
    ({"v": 2, "event": "start", "shards": ["a", 2], "pid": 1, "host": "h"}, "shards"),
    ({"v": 2, "event": "start", "shards": ["a"], "pid": 1.0, "host": "h"}, "pid"),
    ({"v": 2, "event": "batch_end", "batch": 0, "shards": [], "attempt": 0, "returncode": 0, "log_tail": "",
      "retry": 0}, "retry"),
])
def test_bad_events_raise(d, needle):
    with pytest.raises(EventError) as ei:
        parse_line(json.dumps(d))
    assert needle in str(ei.value)


def test_non_finite_numbers_are_refused_both_ways():
    with pytest.raises(ValueError):
        encode(Frame("s", "k", float("nan")))
    with pytest.raises(EventError):
        parse_line('{"v": 2, "event": "rss", "rss_mb": Infinity}')


def test_a_deeply_nested_line_is_not_an_event():
    """A worker line nested deeper than any event is plain output, never a RecursionError."""
    assert parse_line("x " + "[" * 200_000 + "]" * 200_000) is None
    assert parse_line('{"event": ' + "[" * 200_000 + "]" * 200_000 + "}") is None


@pytest.mark.parametrize("rc, reported, stopped, retry", [
    (0, False, False, False),
    (1, False, False, True),  # a crash (traceback)
    (-9, False, False, True),  # SIGKILL (out of memory, a kill -9)
    (137, False, False, True),
    (-11, False, False, True),  # SIGSEGV
    (EXIT_INPUT, True, False, False),  # a user-facing error, reported: a retry would repeat it
    (1, True, False, False),
    (EXIT_DISK_FULL, True, False, False),
    (EXIT_DISK_FULL, False, False, False),
    (143, False, True, False), (130, False, True, False), (129, False, True, False),  # told to stop
    (-15, False, True, False), (-2, False, True, False),
])
def test_exit_status_meaning(rc, reported, stopped, retry):
    assert stopped_by_signal(rc) is stopped
    assert should_retry(rc, reported) is retry
