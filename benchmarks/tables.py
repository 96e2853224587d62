"""Markdown tables as the benchmarks print them: a header line, its rule and one line per row."""

from __future__ import annotations

from typing import Iterable, Sequence


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[object]], align: str = "") -> str:
    """``header`` and ``rows`` (one cell each per column) as a Markdown table, without a final
    newline. ``align``: one letter per column, ``r`` for a right-aligned column (``---:``), any
    other (or none) for the default ``---``. An empty cell prints as ``| |``."""
    def line(cells: Sequence[object]) -> str:
        return "|" + "|".join(f" {c} " if str(c) else " " for c in cells) + "|"

    rule = "|" + "|".join("---:" if a == "r" else "---" for a in align.ljust(len(header))) + "|"
    return "\n".join([line(header), rule, *(line(r) for r in rows)])
