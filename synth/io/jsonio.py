"""Strict JSON: ``NaN`` and ``Infinity`` are not JSON, so they are refused both ways (Python's
``json`` writes and reads them by default). UTF-8 bytes with a trailing newline."""

from __future__ import annotations

import json
from pathlib import Path

from synth.io.files import atomic_write_bytes


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
