"""synth.plan.parallel.fork_map: same results for any job count, and no hang when the parent
has a SIGTERM handler of its own (it used to wait forever in Pool.terminate)."""

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

from synth.plan.parallel import chunks, fork_map

ROOT = Path(__file__).resolve().parents[2]


def test_results_do_not_depend_on_jobs():
    items = list(range(7))
    assert fork_map(lambda x: x * x, items, 1) == fork_map(lambda x: x * x, items, 3) == [x * x for x in items]


def test_chunks_cover_the_range():
    for n, parts in [(10, 3), (2, 5), (1, 1), (7, 7)]:
        c = chunks(n, parts)
        assert c[0][0] == 0 and c[-1][1] == n and all(a < b for a, b in c)
        assert all(c[k][1] == c[k + 1][0] for k in range(len(c) - 1))


def test_no_hang_with_a_parent_sigterm_handler(tmp_path):
    """The old code hung within a few hundred calls (children inherited the handler and ignored
    Pool.terminate's SIGTERM while blocked on the task queue); run in its own process group so
    that a hang is killed and reported, not inherited by the test run."""
    code = textwrap.dedent("""
        import signal, sys
        sys.path.insert(0, sys.argv[1])
        from synth.plan.parallel import fork_map
        signal.signal(signal.SIGTERM, lambda *a: None)  # e.g. a command's graceful shutdown
        for _ in range(300):
            assert fork_map(lambda x: x + 1, list(range(6)), 2) == list(range(1, 7))
        print("ok")
    """)
    out = tmp_path / "out.txt"
    with open(out, "w") as f:
        proc = subprocess.Popen([sys.executable, "-c", code, str(ROOT)], stdout=f, stderr=subprocess.STDOUT,
                                start_new_session=True)
        try:
            rc = proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            raise AssertionError("fork_map hung (parent with a SIGTERM handler)") from None
    assert rc == 0 and out.read_text().strip() == "ok", out.read_text()
