"""Datasets for the reliability tests, made without Blender: a real plan (``synth plan`` on the
toy model) whose shards are committed with fake frames through the dataset API, so that
``synth render`` with the same arguments finds it complete, ``synth validate`` passes, and a
test can damage it in one precise way. Also the tampering those tests need."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

from tests.support import fake_frames as ff

#: Plan settings of the fake datasets: 1 expression and 2 views per identity, one shard each.
SETS = ["dataset.expressions_per_identity=1", "dataset.views_per_expression=2", 'render.preset="ci"']
SEED = 7


def render_args(n: int, model: Path, out: Path) -> list[str]:
    """``synth render`` arguments that give the plan of :func:`fake_render`."""
    args = ["render", "--identities", str(n), "--model", str(model), "--seed", str(SEED), "--out", str(out)]
    for s in SETS:
        args += ["--set", s]
    return args


def fake_render(out: Path, model: Path, n: int = 2, shards: list[str] | None = None) -> Path:
    """Plan ``n`` identities into ``out/plan`` and commit every (or the given) shard with fake
    frames, as ``synth render`` would lay the dataset out. Returns ``out``."""
    from renderer_jobs.submit import prepare_plan
    from synth.dataset.shards import open_dataset
    from synth.plan.io import load_plan

    pdir = prepare_plan(out, n, None, SETS, SEED, model)
    plan = load_plan(pdir)
    ds = open_dataset(out, plan.plan_hash, plan.expected(), meta={"plan_dir": "plan"})
    ff.render_dataset(ds, shards=shards)
    return out


def writable_copy(src: Path, dst: Path) -> Path:
    """A copy of a dataset whose committed files may be edited."""
    shutil.copytree(src, dst, symlinks=True)
    for p in dst.rglob("*"):
        if not p.is_symlink():
            os.chmod(p, 0o755 if p.is_dir() else 0o644)
    return dst


def first_frame(root: Path, shard: str = "shard_000000") -> tuple[Path, Path]:
    """(the shard directory, the first frame JSON in it)."""
    sd = root / "shards" / shard
    return sd, sorted(p for p in sd.glob("id*.json"))[0]


def reseal(shard_dir: Path, name: str) -> None:
    """Update the manifest entry of ``name`` to the file's current bytes (what a tamperer who
    wants ``synth validate`` to pass would do)."""
    data = (shard_dir / name).read_bytes()
    man = shard_dir / "manifest.json"
    m = json.loads(man.read_text())
    m["files"][name] = {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}
    os.chmod(man, 0o644)
    man.write_text(json.dumps(m, indent=1))


def tamper_frame(root: Path, shard: str = "shard_000000") -> Path:
    """Edit a committed frame's JSON (its size changes) and reseal its manifest entry."""
    sd, js = first_frame(root, shard)
    os.chmod(js, 0o644)
    fj = json.loads(js.read_text())
    fj["seed"] = fj["seed"] + 1000
    js.write_text(json.dumps(fj) + "   ")
    reseal(sd, js.name)
    return js
