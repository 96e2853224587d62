"""How long ``synth plan`` takes: imports, one identity, 1,500 identities (docs/performance.md,
"`synth plan`: speed").

    .venv/bin/python benchmarks/plan_speed.py [--runs 3] [--large 1500] [--seed 7]

Each case runs the real command in a fresh process (``python -m synth.cli.main plan ...``)
``--runs`` times and prints the best wall time and the CPU time (user + system, the forked
planning processes included) of that run, with the load average before it: on a machine
shared with other jobs, wall time grows with the load while CPU time stays. The imports are
timed with ``python -X importtime`` (the modules a 1-identity plan loads, largest first), and
the script says whether the slow optional imports (colour-science, scipy.stats, matplotlib)
were loaded.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SLOW = ("colour", "scipy.stats", "matplotlib")


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(":")}


def timed(cmd: list[str]) -> tuple[float, float, str]:
    """(wall s, CPU s of the process and its children, stdout) of one run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=_env(), cwd=ROOT)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{p.stderr}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), p.stdout


def plan_case(work: Path, identities: int, seed: int | None, jobs: int | None, runs: int) -> dict:
    best = None
    for r in range(runs):
        out = work / f"p{identities}_{jobs}_{r}"
        cmd = [sys.executable, "-m", "synth.cli.main", "plan", "--identities", str(identities), "--out", str(out), "-q"]
        cmd += ["--seed", str(seed)] if seed is not None else []
        cmd += ["--jobs", str(jobs)] if jobs is not None else []
        load = os.getloadavg()[0]
        wall, cpu, stdout = timed(cmd)
        shutil.rmtree(out, ignore_errors=True)
        if best is None or wall < best["wall"]:
            best = {"wall": wall, "cpu": cpu, "load": load, "hash": stdout.strip()[:16]}
    return best


def imports(work: Path, top: int = 8) -> tuple[float, list[tuple[str, float]], list[str]]:
    """Total import time of a 1-identity plan (s), its largest top-level imports, and which of
    :data:`SLOW` it loaded."""
    out = work / "imports"
    p = subprocess.run([sys.executable, "-X", "importtime", "-m", "synth.cli.main", "plan", "--identities", "1",
                        "--out", str(out), "-q"], capture_output=True, text=True, env=_env(), cwd=ROOT)
    shutil.rmtree(out, ignore_errors=True)
    rows = []  # (name with its indentation, cumulative s)
    for line in p.stderr.splitlines():
        if line.startswith("import time:") and "cumulative" not in line:
            _, cum_us, name = line.removeprefix("import time:").split("|")
            rows.append((name[1:], int(cum_us) / 1e6))
    top_level = [(n, s) for n, s in rows if not n.startswith(" ")]
    names = {n.strip() for n, _ in rows}
    total = sum(s for _, s in top_level)
    return total, sorted(top_level, key=lambda x: -x[1])[:top], [m for m in SLOW if m in names]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--large", type=int, default=1500, help="identities of the large plan")
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="plan_speed_") as tmp:
        work = Path(tmp)
        total, top, slow = imports(work)
        cases = [("1 identity, default --jobs", 1, None, None),
                 (f"{a.large:,} identities --seed {a.seed}, default --jobs", a.large, a.seed, None),
                 (f"{a.large:,} identities --seed {a.seed}, --jobs 1", a.large, a.seed, 1)]
        res = [(name, plan_case(work, n, seed, jobs, a.runs)) for name, n, seed, jobs in cases]
    print(f"imports of a 1-identity plan: {total:.2f} s (python -X importtime, top level); largest: "
          + ", ".join(f"{n} {s:.2f}" for n, s in top))
    print(f"slow optional imports loaded: {', '.join(slow) or 'none'} (of {', '.join(SLOW)})")
    print(f"\n{os.cpu_count()} CPUs; best of {a.runs} runs\n")
    print("| plan | wall s | CPU s (user + sys) | load average before | plan hash |\n|---|---|---|---|---|")
    for name, r in res:
        print(f"| {name} | {r['wall']:.2f} | {r['cpu']:.2f} | {r['load']:.1f} | {r['hash']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
