"""`synth render` argument errors: one line, exit 2, nothing written."""

from __future__ import annotations

from synth.cli.main import main


def test_bad_arguments_give_one_line_and_write_nothing(tmp_path, capsys):
    cases = [
        (["render", "-n", "1", "--preset", "bogus", "--out", str(tmp_path / "a")], "render.preset"),
        (["render", "--plan", str(tmp_path / "nope"), "--out", str(tmp_path / "b")], "no plan.json"),
        (["render", "--out", str(tmp_path / "c")], "missing --identities"),
        (["render", "--plan", str(tmp_path), "-n", "2", "--out", str(tmp_path / "d")], "planning options"),
    ]
    for argv, needle in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == []
