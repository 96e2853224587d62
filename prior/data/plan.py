"""A dataset's plan as training needs it, read in a bounded amount of memory.

``dataset.json`` names every planned frame key (585,000 of them for the paper's 1,500
identities, 14 MB). Parsing it whole (:func:`synth.dataset.shards.load_dataset`) holds about
140 MB of Python strings for a moment, on every rank, and the allocator keeps part of it;
training needs only which shards hold each identity. :func:`read_plan` scans the file in
256 kB blocks and keeps per identity only the ids of the shards that plan its frames (a run of keys is
matched at once, so the scan is fast). It checks what the run relies on: the format, the plan
hash, and that every frame key of ``expected`` is a frame key; the rest of the file's checks
(sorted keys, no key in two shards) are ``synth validate``'s.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from synth.dataset.layout import DATASET_FILE, DATASET_FORMAT, MAX_DATASET_JSON_BYTES
from synth.errors import SynthError
from synth.io.files import open_regular

BLOCK = 1 << 18
#: one token: a string, a bracket, or a bare literal (commas and colons are separators)
_TOKEN = re.compile(rb'[ \t\r\n,:]*(?:"((?:[^"\\]|\\.)*)"|([{}\[\]])|([^ \t\r\n,:{}\[\]"]+))')
#: a run of frame keys inside a shard's list
_KEYS = re.compile(rb'(?:[ \t\r\n,]*"id\d{6}_ex\d{2}_v\d{2}")+')
_IDENT = re.compile(rb'"id(\d{6})_')
_TAIL = re.compile(rb"[ \t\r\n]*")


class _Frame:
    __slots__ = ("kind", "n", "key", "path")

    def __init__(self, kind: bytes, path: tuple):
        self.kind, self.n, self.key, self.path = kind, 0, None, path


def read_plan(root) -> tuple[dict, dict[int, list[str]]]:
    """(the top-level scalar fields of ``root/dataset.json``, identity index -> the shard ids
    whose planned frames hold it, in file order). Raises SynthError (one line) for a file that
    cannot be read or is not a dataset.json."""
    p = Path(root) / DATASET_FILE
    fix = "restore it or render into a new --out directory"

    def bad(why: str) -> SynthError:
        return SynthError(f"dataset.json is damaged: {why}", str(p), fix)

    try:
        fd, st = open_regular(p, follow_symlinks=False)
    except (OSError, ValueError) as e:
        why = e.strerror if isinstance(e, OSError) else str(e)
        raise SynthError(f"dataset.json cannot be read ({why})", str(p), fix) from None
    top: dict = {}
    planned: dict[int, list[str]] = {}
    stack: list[_Frame] = []
    done = expected = False
    try:
        if st.st_size > MAX_DATASET_JSON_BYTES:
            raise SynthError(f"dataset.json is {st.st_size} bytes, more than the {MAX_DATASET_JSON_BYTES} allowed",
                             str(p), fix)
        buf, pos, eof = b"", 0, False
        while True:
            if not eof and len(buf) - pos < BLOCK // 2:
                more = os.read(fd, BLOCK)
                buf, pos, eof = buf[pos:] + more, 0, not more
            c = stack[-1] if stack else None
            if c is not None and c.kind == b"[" and len(c.path) == 2 and c.path[0] == "expected":
                m = _KEYS.match(buf, pos)
                if m is not None and m.end() == len(buf) and not eof:
                    more = os.read(fd, BLOCK)
                    buf, pos, eof = buf[pos:] + more, 0, not more
                    continue
                if m is not None:
                    ids = {int(x) for x in _IDENT.findall(buf, m.start(), m.end())}
                    for i in ids:
                        s = planned.setdefault(i, [])
                        if not s or s[-1] != c.path[1]:
                            s.append(c.path[1])
                    c.n += 1
                    pos = m.end()
                    continue
            m = _TOKEN.match(buf, pos)
            if (m is None or m.end() == len(buf)) and not eof:
                more = os.read(fd, BLOCK)
                buf, pos, eof = buf[pos:] + more, 0, not more
                continue
            if m is None:
                if done and _TAIL.fullmatch(buf, pos):
                    break
                raise bad("it ends early or is not JSON" if not done else "text after its end")
            if done:
                raise bad("text after its end")
            pos = m.end()
            string, bracket, literal = m.group(1), m.group(2), m.group(3)
            if bracket in (b"}", b"]"):
                if c is None or (c.kind == b"{") != (bracket == b"}") or (c.kind == b"{" and c.n % 2):
                    raise bad("its brackets do not match")
                stack.pop()
                done = not stack
                continue
            if c is None:
                if bracket != b"{":
                    raise bad("it is not a JSON object")
                stack.append(_Frame(b"{", ()))
                continue
            if c.kind == b"{" and c.n % 2 == 0:  # a key
                if string is None:
                    raise bad("an object key is not a string")
                c.key = json.loads(b'"' + string + b'"')
                c.n += 1
                continue
            c.n += 1
            name = c.key if c.kind == b"{" else None
            if bracket is not None:
                if len(stack) > 64:
                    raise bad("nested too deep")
                stack.append(_Frame(bracket, c.path + (name,)))
                expected = expected or (c.path == () and name == "expected" and bracket == b"{")
            elif len(c.path) == 2 and c.path[0] == "expected":
                raise bad(f"bad frame key {(string or literal or b'').decode('utf-8', 'replace')[:40]!r} in shard "
                          f"{c.path[1]}")
            elif len(stack) == 1:
                try:
                    top[name] = json.loads(b'"' + string + b'"' if string is not None else literal)
                except ValueError:
                    raise bad(f"the value of {name!r} is not JSON") from None
    except ValueError as e:  # UnicodeDecodeError and JSONDecodeError of a key
        raise bad(str(e)[:120]) from None
    finally:
        os.close(fd)
    if top.get("format") != DATASET_FORMAT or not isinstance(top.get("plan_hash"), str) or not expected:
        raise SynthError(f"dataset.json is not a {DATASET_FORMAT} file", str(p), fix)
    return top, planned


__all__ = ["read_plan"]
