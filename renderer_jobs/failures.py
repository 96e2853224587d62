"""What a run that failed prints before its one-line error: each distinct failure once.

Workers that fail for the same reason (every worker of a run on a full disk, every worker of an
install without bpy) report messages that differ only in shard ids, frame keys, paths and
numbers. :func:`group` puts them together by a *signature* with those parts blanked, and
:func:`report_lines` prints:

- one line per distinct failure: the shards and the first message, or, for the failure that
  becomes the final ``synth: error:`` line, only its shards when there are several (the message
  itself is that line, never printed twice);
- without ``quiet``, the end of each failed worker's log, less the lines already shown (its own
  ``synth worker: error:`` line repeats the message; "worker log abandoned" repeats for every
  worker on a full disk).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

#: Parts of a message that differ between workers failing alike.
_VARYING = re.compile(r"\S*/\S*|shard_\d+|id\d{6}_ex\d{2}(?:_en\d{2})?_v\d{2}|\d+(?:\.\d+)?")


@dataclass
class Failure:
    """One failure: a batch whose worker failed after its retries (``returncode``, log ``tail``),
    or an error a worker reported although it ended well (``returncode`` None)."""

    shards: tuple[str, ...]
    message: str
    returncode: int | None = None
    tail: tuple[str, ...] = ()


@dataclass
class Group:
    signature: str
    failures: list[Failure] = field(default_factory=list)

    @property
    def shards(self) -> list[str]:
        return sorted(s for f in self.failures for s in f.shards)

    @property
    def message(self) -> str:
        return self.failures[0].message


def signature(message: str) -> str:
    """``message`` with paths, shard ids, frame keys and numbers blanked."""
    return _VARYING.sub("_", message)


def group(failures: list[Failure]) -> list[Group]:
    """Failures by signature, each group's in shard order, the groups by their first shard (the
    order workers end in does not matter)."""
    out: dict[str, Group] = {}
    for f in sorted(failures, key=lambda f: f.shards):
        out.setdefault(signature(f.message), Group(signature(f.message))).failures.append(f)
    return sorted(out.values(), key=lambda g: g.shards)


def _shard_list(shards: list[str], most: int = 4) -> str:
    text = ", ".join(shards[:most])
    return text + (f" and {len(shards) - most} more" if len(shards) > most else "")


def report_lines(groups: list[Group], final: str, quiet: bool) -> list[str]:
    """The lines printed before the final error line ``final`` (see the module docstring)."""
    lines: list[str] = []
    shown: set[str] = {final}
    for g in groups:
        n = len(g.shards)
        if any(f.message == final for f in g.failures):
            if n > 1:
                lines.append(f"synth render: {n} shards failed alike: {_shard_list(g.shards)}")
        else:
            alike = f" ({len(g.failures)} workers alike)" if len(g.failures) > 1 else ""
            lines.append(f"synth render: {_shard_list(g.shards)}: {g.message}{alike}")
        shown.update(f.message for f in g.failures)
    if quiet:
        return lines
    seen_tail: set[str] = set()
    for g in groups:
        for f in g.failures:
            tail = [t for t in f.tail if t.strip() and t not in seen_tail
                    and not any(m in t for m in shown)]
            seen_tail.update(tail)
            if f.returncode is not None:
                lines.append(f"synth render: worker for {','.join(f.shards)} exited with code {f.returncode}"
                             + ("; its log ends:" if tail else ""))
            lines.extend(f"  {t}" for t in tail)
    return lines
