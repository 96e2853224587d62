"""Strict, bounded JSON: the one way synth reads and writes JSON.

- ``NaN`` and ``Infinity`` are not JSON, so they are refused both ways (Python's ``json``
  writes and reads them by default). Text is UTF-8 with a trailing newline.
- Reading is bounded: nesting deeper than ``max_depth`` (default :data:`MAX_DEPTH`) is refused
  (orjson, tried first, nests at most 1,024 deep without recursing in Python; the ``json``
  fallback never sees deeper input), so no input can exhaust the interpreter's recursion (a
  ``RecursionError`` deep inside the parser, or in code walking the result); files are read
  through :func:`synth.io.files.read_bounded` (a size bound, regular files only, optionally no
  symbolic links), so ``/dev/zero`` or a 50 GB file is refused, not read.

Every problem with the input raises :class:`JSONError` (a ``ValueError``) with a short reason;
callers turn it into a one-line user error naming the file.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import orjson

from synth.io.files import atomic_write_bytes, read_bounded

#: Deepest nesting of arrays and objects accepted (synth's own files nest at most ~8 deep).
MAX_DEPTH = 64

_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.S)
_DIGITS_AS_ZERO = bytes(0x30 if 0x30 <= b <= 0x39 else 0x78 for b in range(256))  # digit -> "0", else "x"
_LONG_RUN = b"0" * 19
_BEFORE_TOKEN = frozenset(b"[,: \t\n\r-")
_AFTER_TOKEN = frozenset(b"],} \t\n\r")
_NOT_BRACKETS = bytes(b for b in range(256) if b not in b"[]{}")


class JSONError(ValueError):
    """Input that is not strict, bounded JSON (syntax, encoding, NaN, nesting, size)."""


def dumps_json(obj, *, indent: int | None = 1) -> bytes:
    """Strict JSON (NaN/Infinity refused: they are not JSON), UTF-8, trailing newline."""
    return (json.dumps(obj, indent=indent, allow_nan=False, ensure_ascii=False) + "\n").encode("utf-8")


def _refuse_constant(name: str):
    raise JSONError(f"non-standard JSON constant {name}")


def json_depth(data: bytes) -> int:
    """The deepest nesting of ``[``/``{`` in JSON bytes, strings skipped (linear time, no
    recursion). Meaningful for well-formed JSON; for other bytes it is an upper bound."""
    return _bracket_depth(_STRING.sub(b"", data).translate(None, _NOT_BRACKETS))


def _bracket_depth(brackets: bytes) -> int:
    """The deepest nesting of a string of ``[]{}`` (no recursion)."""
    if brackets.count(b"[") + brackets.count(b"{") <= 1:
        return 1 if brackets else 0
    import numpy as np

    a = np.frombuffer(brackets, np.uint8)
    return int(np.cumsum(np.where((a == ord("[")) | (a == ord("{")), 1, -1).astype(np.int64)).max())


_NOT_BRACKETS_OR_QUOTES = bytes(b for b in range(256) if b not in b'[]{}"')


def _depth_without_escapes(raw: bytes) -> int | None:
    """The nesting depth of JSON bytes known to be well-formed that hold no backslash (then every ``"``
    opens or closes a string, so the brackets outside strings are those between an even and an
    odd quote), in a few whole-buffer operations; None when ``raw`` has a backslash."""
    if b"\\" in raw:
        return None
    return _bracket_depth(b"".join(raw.translate(None, _NOT_BRACKETS_OR_QUOTES).split(b'"')[::2]))


def _deeper_than(obj, limit: int) -> bool:
    """Whether a parsed value nests arrays and objects more than ``limit`` deep (no recursion)."""
    stack = [(obj, 1)] if type(obj) in (dict, list) else []
    while stack:
        o, d = stack.pop()
        if d > limit:
            return True
        for v in (o.values() if type(o) is dict else o):
            if type(v) is dict or type(v) is list:
                stack.append((v, d + 1))
    return False


def _long_integer(raw: bytes) -> bool:
    """Whether JSON bytes may hold an integer token of 19 or more digits. A digit run inside a
    string counts only when it stands between JSON delimiters (a hex digest does not), and then
    it only sends the bytes down the slower, exact path."""
    marked = raw.translate(_DIGITS_AS_ZERO)  # bytes.find below: no per-position regex cost
    a = marked.find(_LONG_RUN)
    while a >= 0:
        b = marked.find(b"x", a)
        b = len(raw) if b < 0 else b
        if (a == 0 or raw[a - 1] in _BEFORE_TOKEN) and (b == len(raw) or raw[b] in _AFTER_TOKEN):
            return True
        a = marked.find(_LONG_RUN, b)
    return False


def loads_json(data: bytes | str, *, max_depth: int = MAX_DEPTH):
    """Parse strict JSON: UTF-8, no ``NaN``/``Infinity``, nesting at most ``max_depth``.
    Raises :class:`JSONError`."""
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else bytes(data)
    if not _long_integer(raw):  # orjson reads integers past 64 bits as floats: json below
        try:  # orjson first (5x faster): it accepts a subset of what json does, with the same values
            obj = orjson.loads(raw)
        except orjson.JSONDecodeError:
            pass  # the path below says why, as it always has
        else:
            depth = _depth_without_escapes(raw)
            if (depth <= max_depth) if depth is not None else not _deeper_than(obj, max_depth):
                return obj
    depth = json_depth(raw)
    if depth > max_depth:
        raise JSONError(f"nested {depth} levels deep (at most {max_depth} allowed)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise JSONError(f"not UTF-8 text (byte {raw[e.start]:#04x} at offset {e.start})") from None
    try:
        return json.loads(text, parse_constant=_refuse_constant)
    except JSONError:
        raise
    except (ValueError, RecursionError) as e:  # JSONDecodeError; integer too long; depth (unreachable)
        raise JSONError(str(e)[:200]) from None


def read_json(path: str | Path, *, max_bytes: int, max_depth: int = MAX_DEPTH, follow_symlinks: bool = True):
    """Read and parse a JSON file of at most ``max_bytes`` (a regular file; with
    ``follow_symlinks=False`` not a symbolic link). Raises OSError when it cannot be opened,
    :class:`synth.io.files.FileRefused` (a ValueError) for the wrong kind or size of file,
    :class:`JSONError` for its content."""
    return loads_json(read_bounded(path, max_bytes, follow_symlinks=follow_symlinks), max_depth=max_depth)


def atomic_write_json(path: Path, obj, *, durable: bool = True, indent: int | None = 1) -> bytes:
    """Atomically write ``obj`` as strict JSON; returns the bytes written."""
    data = dumps_json(obj, indent=indent)
    atomic_write_bytes(path, data, durable=durable)
    return data
