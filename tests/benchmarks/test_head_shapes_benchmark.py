"""benchmarks/head_shapes.py runs: a before/after row per measure, and the silhouette figure."""

from __future__ import annotations

from benchmarks import head_shapes


def test_the_benchmark_prints_a_row_pair_per_measure_and_writes_the_figure(tmp_path, capsys):
    fig = tmp_path / "heads.png"
    assert head_shapes.main(["--identities", "60", "--seed", "0", "--figure", str(fig)]) == 0
    out = capsys.readouterr().out
    rows = [r for r in out.splitlines() if r.startswith("| ") and ("| before |" in r or "| after |" in r)]
    assert len(rows) == 12 and all(r.endswith("0.00 % |") for r in rows if "| after |" in r)
    assert "after 0.0 %" in out and fig.stat().st_size > 10_000
