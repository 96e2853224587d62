"""Starting or resuming a run: everything is checked before anything is written.

``RUN/`` holds ``config.toml`` (the resolved config), ``run.json`` (dataset, code layout,
identities, batch), ``checkpoints/`` (:mod:`prior.train.checkpoint`), ``metrics.jsonl`` and
``tb/`` (:mod:`prior.train.logs`). A fresh run refuses a ``RUN`` that already has checkpoints
(``--resume`` continues it); a resumed run takes its config from its newest checkpoint (only
``[train]`` keys and ``--steps`` may change) and refuses a dataset whose head model,
resolution, codes or identities differ from the checkpoint's.

The dataset is read through the prepare pass (:mod:`prior.data.prepare`: rank 0 writes the
records of new shards, the other ranks wait and read them); pixels are streamed later
(:class:`prior.data.Loader`, built by the trainer).
"""

from __future__ import annotations

import dataclasses
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prior.data.prepare import Table, build_table, trim_heap
from prior.data.prepare import prepare as prepare_pass
from prior.data.sources import ShardDamaged, Source, frame_meta, open_source, read_shard
from prior.train import checkpoint as ckpt
from prior.train import config as run_config
from prior.train.setup import Dist, fit_scene
from synth.io import atomic_write_bytes, atomic_write_json
from synth.errors import SynthError

CONFIG_FILE = "config.toml"
RUN_FILE = "run.json"


@dataclass
class RunSetup:
    run_dir: Path
    dataset: Path
    cfg: run_config.RunConfig
    table: Table
    resume_from: ckpt.Checkpoint | None
    source: Source | None = None
    prepare_dir: Path | None = None


def _with_steps(cfg, steps):
    if steps is None:
        return cfg
    if steps < 1:
        raise SynthError(f"--steps {steps} must be at least 1", "--steps", "pass a positive number of steps")
    return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, steps=int(steps)))


def prepare(dataset, run_dir, *, preset: str | None = None, config_path=None, sets=(), steps: int | None = None,
            resume: bool = False, progress=None, dist: Dist | None = None) -> RunSetup:
    """Resolve the config, run the prepare pass over the dataset (a directory, or shard paths /
    brace patterns) and check it against a resumed checkpoint."""
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise SynthError("run path exists and is not a directory", str(run_dir), "pass a directory to --out")
    found = ckpt.latest(run_dir)
    resumed = None
    if resume:
        if found is None:
            raise SynthError("nothing to resume: the run has no checkpoint", str(run_dir),
                             "drop --resume to start a new run there")
        if preset is not None or config_path is not None:
            raise SynthError("--preset and --config cannot change a resumed run", str(run_dir),
                             "drop them (the run keeps its config; --set train.KEY=VALUE and --steps may change)")
        resumed = ckpt.load(found)
        cfg = _with_steps(run_config.with_sets(resumed.config, sets, allowed=("train",)), steps)
        if cfg.train.steps < resumed.step:
            raise SynthError(f"--steps {cfg.train.steps} is below the checkpoint's step {resumed.step}", "--steps",
                             "pass a larger number of steps")
    else:
        if found is not None:
            raise SynthError("run already has checkpoints", str(run_dir),
                             "pass --resume to continue it, or choose another --out")
        cfg = _with_steps(run_config.load(preset or "small", config_path, sets), steps)
    d = cfg.data
    source = open_source(dataset)
    if resumed is not None:
        _check_like_run(source, resumed)
    prep_dir = _prepare_dir(source, run_dir)
    res = _prepare_all(source, prep_dir, dist or Dist(), progress)
    table = build_table(res, joints=tuple(d.joints), margin=d.bounds_margin, holdout_views=d.holdout_views,
                        planned=source.planned_identities, where=source.describe())
    del res
    trim_heap()
    if resumed is not None:
        if table.layout != resumed.layout:
            raise SynthError(f"dataset codes {table.layout.to_dict()} differ from the checkpoint's "
                             f"{resumed.layout.to_dict()}", source.describe(),
                             "resume with the dataset the run was trained on (or start a new run)")
        if not np.array_equal(table.info.identity_index, resumed.identities.identity_index):
            raise SynthError(f"dataset has identities {table.info.identity_index.tolist()[:8]}..., the "
                             f"checkpoint {resumed.identities.identity_index.tolist()[:8]}...", source.describe(),
                             "resume with the dataset the run was trained on (or start a new run)")
        old = resumed.identities
        keep = old.radius > 0  # the run's own bounds, exactly, for every identity it had
        for k in ("centre", "radius", "front_K", "front_c2w", "front_size"):
            getattr(table.info, k)[keep] = getattr(old, k)[keep]
    else:
        av = table.available
        cfg = fit_scene(cfg, table.info.centre[av], table.info.radius[av])
        cfg = run_config.validate(cfg, "fitted scene")
    return RunSetup(run_dir, source.root or source.paths[0], cfg, table, resumed, source, prep_dir)


def _check_like_run(source: Source, resumed: ckpt.Checkpoint) -> None:
    """Refuse (one line, before anything is written) a dataset of another head model or
    resolution than the resumed run's, from its first committed frame's JSON."""
    for ref in source.committed():
        try:
            key, jb, _ = next(read_shard(ref))
            meta = frame_meta(jb, key)
        except (ShardDamaged, StopIteration):
            continue
        hm = {k: meta.get("model", {}).get(k) for k in ("name", "sha256")}
        if resumed.head_model and hm != resumed.head_model:
            raise SynthError(f"dataset frames are of head model {hm.get('name')!r}, which differs from the "
                             f"checkpoint's {resumed.head_model.get('name')!r}", source.describe(),
                             "resume with the dataset the run was trained on (or start a new run)")
        img = meta.get("image") or {}
        trained = resumed.identities.front_size[resumed.identities.radius > 0]
        if len(trained) and [img.get("width"), img.get("height")] != trained[0].tolist():
            raise SynthError(f"dataset frames are {img.get('width')}x{img.get('height')}, which differs from the "
                             f"checkpoint's {trained[0][0]}x{trained[0][1]}", source.describe(),
                             "resume with the dataset the run was trained on (or start a new run)")
        return


def _prepare_dir(source: Source, run_dir: Path) -> Path:
    """Beside the dataset (``DATASET/.prior/prepare``) where it can be written, else in the run."""
    d = source.default_prepare_dir()
    p = d
    while not p.exists() and p != p.parent:
        p = p.parent
    return d if os.access(p, os.W_OK) else Path(run_dir) / "prepare"


def _prepare_all(source: Source, prep_dir: Path, dist: Dist, progress):
    """The prepare pass: rank 0 writes the records, every other rank then reads them."""
    err = None
    if dist.main:
        try:
            res = prepare_pass(source, prep_dir, warn=warn_line, progress=progress, workers=os.cpu_count() or 1)
        except SynthError as e:
            err = e
    if dist.enabled:
        import torch

        flag = torch.tensor([1.0 if err is not None else 0.0])
        torch.distributed.broadcast(flag, 0)
        if flag.item() and err is None:
            raise SynthError("rank 0 could not prepare the dataset", source.describe(), "see rank 0's message")
    if err is not None:
        raise err
    if not dist.main:
        res = prepare_pass(source, prep_dir, write_merged=False)  # rank 0 wrote the merged table
    return res


def warn_line(line: str) -> None:
    """One warning line on stderr (a skipped shard)."""
    print(f"synth: warning: {line}", file=sys.stderr, flush=True)


def write_run_files(s: RunSetup, world: int, bf16: bool | None = None) -> None:
    """``config.toml`` and ``run.json`` of a run (rank 0, after every check passed); ``bf16``:
    whether bf16 autocast is on (what ``train.bf16`` resolved to on this machine)."""
    s.run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(s.run_dir / CONFIG_FILE, run_config.to_toml(s.cfg).encode("utf-8"))
    tb, t, d = s.table, s.cfg.train, s.cfg.data
    H, W = tb.size
    per_identity = int(tb.frames.max()) * H * W * (4 * np.dtype(d.pixel_dtype).itemsize + 4)
    atomic_write_json(s.run_dir / RUN_FILE, {
        "dataset": s.source.describe() if s.source is not None else str(s.dataset), "layout": tb.layout.to_dict(),
        "identities": tb.info.identity_index.tolist(), "committed_identities": int((tb.frames > 0).sum()),
        "frames": int(tb.frames.sum()), "image_size": [H, W], "ranks": world, "prepare_dir": str(s.prepare_dir),
        "rays_per_step": s.cfg.rays_per_step, "batch": [t.identities_per_batch, t.views_per_identity,
                                                        t.pixels_per_view], "grad_accum": t.grad_accum,
        "bf16": t.bf16 if bf16 is None else bf16, "buffer_identities": d.buffer_identities, "buffer_bytes_per_identity_max": per_identity})
