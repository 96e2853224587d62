"""What ``synth validate`` reports: :class:`Defect` (one finding), :class:`Report` (all of
them for a dataset) and :class:`DefectsFound` (the error that makes the CLI exit 1).

Shared by :mod:`synth.dataset.validate` (shards and frames) and
:mod:`synth.dataset.validate_index` (the index and the commit records).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from synth.errors import SynthError


class DefectsFound(SynthError):
    """Validation found defects: the CLI exits with code 1 (not 2: the input was usable)."""

    exit_code = 1


@dataclass(frozen=True)
class Defect:
    shard: str | None
    key: str | None
    kind: str
    message: str

    def line(self) -> str:
        where = "/".join(p for p in (self.shard, self.key) if p) or "dataset"
        return f"{where}: {self.kind}: {self.message}"


@dataclass
class Report:
    root: str
    defects: list[Defect] = field(default_factory=list)
    warnings: list[Defect] = field(default_factory=list)
    shards_expected: int = 0
    frames_expected: int = 0
    shards_checked: int = 0
    frames_checked: int = 0
    hashed: bool = True
    digest: str | None = None  # index.json's digest over every committed manifest

    @property
    def ok(self) -> bool:
        return not self.defects

    def to_json(self) -> dict:
        d = asdict(self)
        d["ok"] = self.ok
        return d
