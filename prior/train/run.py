"""Starting or resuming a run: everything is checked before anything is written.

``RUN/`` holds ``config.toml`` (the resolved config), ``run.json`` (dataset, code layout,
identities, batch), ``checkpoints/`` (:mod:`prior.train.checkpoint`), ``metrics.jsonl`` and
``tb/`` (:mod:`prior.train.logs`). A fresh run refuses a ``RUN`` that already has checkpoints
(``--resume`` continues it); a resumed run takes its config from its newest checkpoint (only
``[train]`` keys and ``--steps`` may change) and refuses a dataset whose codes or identities
differ from the checkpoint's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prior.data.store import FrameStore, load_store
from prior.train import checkpoint as ckpt
from prior.train import config as run_config
from prior.train.setup import fit_scene
from synth.io import atomic_write_bytes, atomic_write_json
from synth.errors import SynthError

CONFIG_FILE = "config.toml"
RUN_FILE = "run.json"


@dataclass
class RunSetup:
    run_dir: Path
    dataset: Path
    cfg: run_config.RunConfig
    store: FrameStore
    resume_from: ckpt.Checkpoint | None


def _with_steps(cfg, steps):
    if steps is None:
        return cfg
    if steps < 1:
        raise SynthError(f"--steps {steps} must be at least 1", "--steps", "pass a positive number of steps")
    return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, steps=int(steps)))


def prepare(dataset, run_dir, *, preset: str | None = None, config_path=None, sets=(), steps: int | None = None,
            resume: bool = False, progress=None) -> RunSetup:
    """Resolve the config, load the dataset and check it against a resumed checkpoint."""
    run_dir, dataset = Path(run_dir), Path(dataset)
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
    store = load_store(dataset, joints=tuple(d.joints), holdout_views=d.holdout_views, margin=d.bounds_margin,
                       pixel_dtype=d.pixel_dtype, progress=progress)
    if resumed is not None:
        if store.layout != resumed.layout:
            raise SynthError(f"dataset codes {store.layout.to_dict()} differ from the checkpoint's "
                             f"{resumed.layout.to_dict()}", str(dataset),
                             "resume with the dataset the run was trained on (or start a new run)")
        if not np.array_equal(store.identities.identity_index, resumed.identities.identity_index):
            raise SynthError(f"dataset has identities {store.identities.identity_index.tolist()[:8]}..., the "
                             f"checkpoint {resumed.identities.identity_index.tolist()[:8]}...", str(dataset),
                             "resume with the dataset the run was trained on (or start a new run)")
        store.identities = resumed.identities  # the run's own bounds, exactly
    else:
        cfg = fit_scene(cfg, store.identities.centre, store.identities.radius)
        cfg = run_config.validate(cfg, "fitted scene")
    return RunSetup(run_dir, dataset, cfg, store, resumed)


def write_run_files(s: RunSetup, world: int, bf16: bool | None = None) -> None:
    """``config.toml`` and ``run.json`` of a run (rank 0, after every check passed); ``bf16``:
    whether bf16 autocast is on (what ``train.bf16`` resolved to on this machine)."""
    s.run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(s.run_dir / CONFIG_FILE, run_config.to_toml(s.cfg).encode("utf-8"))
    st, t = s.store, s.cfg.train
    atomic_write_json(s.run_dir / RUN_FILE, {
        "dataset": str(s.dataset.resolve()), "layout": st.layout.to_dict(),
        "identities": st.identities.identity_index.tolist(), "frames": len(st.keys),
        "training_frames": int(st.train.sum()), "image_size": list(st.size), "ranks": world,
        "rays_per_step": s.cfg.rays_per_step, "batch": [t.identities_per_batch, t.views_per_identity,
                                                        t.pixels_per_view], "grad_accum": t.grad_accum,
        "memory_bytes": st.nbytes, "bf16": t.bf16 if bf16 is None else bf16})
