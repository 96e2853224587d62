"""Checkpoints of a training run.

``RUN/checkpoints/step_NNNNNNNN.safetensors`` holds the model (``model.*``: the field and its
codebook) and what a run knows about its identities (``identities.*``: dataset identity
index per latent id, bounding spheres, front cameras, codes per (identity, expression)); its
metadata holds the format tag, the step, the run config (JSON), the code layout (JSON), the
last losses and the sha256 of the optimizer file. ``step_NNNNNNNN.optim.pt`` beside it holds
the Adam state and the trainer's own counters (``torch.load(weights_only=True)`` reads it).

Both files are written atomically (temp file, fsync, rename; the optimizer file first), so a
reader sees a complete checkpoint or none; the model file names the optimizer file's hash,
so a mismatched or damaged pair is refused, not silently used.
"""

from __future__ import annotations

import io
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from prior.data.codes import CodeLayout
from prior.data.identities import SAVED as SAVED_IDENTITY_FIELDS
from prior.data.identities import IdentityInfo
from prior.train import config as run_config
from synth.io import atomic_write_bytes, sha256_bytes
from synth.errors import SynthError

FORMAT = "synth-prior-checkpoint/1"
CHECKPOINT_DIR = "checkpoints"
_NAME = re.compile(r"^step_(\d{8})\.safetensors$")


@dataclass
class Checkpoint:
    path: Path
    step: int
    config: run_config.RunConfig
    layout: CodeLayout
    identities: IdentityInfo
    model_state: dict[str, torch.Tensor]
    losses: dict
    dataset: str
    #: the head model of the training frames (name, sha256), {} for checkpoints that predate it
    head_model: dict

    @property
    def optimizer_path(self) -> Path:
        return self.path.with_name(self.path.name.replace(".safetensors", ".optim.pt"))


def checkpoint_path(run_dir, step: int) -> Path:
    return Path(run_dir) / CHECKPOINT_DIR / f"step_{step:08d}.safetensors"


def list_checkpoints(run_dir) -> list[tuple[int, Path]]:
    d = Path(run_dir) / CHECKPOINT_DIR
    if not d.is_dir():
        return []
    return sorted((int(m.group(1)), d / n) for n in (p.name for p in d.iterdir()) if (m := _NAME.match(n)))


def latest(run_dir) -> Path | None:
    cks = list_checkpoints(run_dir)
    return cks[-1][1] if cks else None


def save(run_dir, step: int, model: torch.nn.Module, optimizer: torch.optim.Optimizer, cfg, layout: CodeLayout,
         identities: IdentityInfo, *, losses: dict, trainer_state: dict, dataset: str, keep: int,
         head_model: dict | None = None) -> Path:
    """Write the checkpoint of ``step`` (completed steps) and prune all but the ``keep`` newest."""
    from safetensors.torch import save as st_save

    path = checkpoint_path(run_dir, step)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    torch.save({"optimizer": optimizer.state_dict(), "step": int(step), "trainer": trainer_state,
                "torch_rng": torch.get_rng_state()}, buf)
    opt_bytes = buf.getvalue()
    tensors = {f"model.{k}": v.detach().to("cpu").contiguous() for k, v in model.state_dict().items()}
    tensors.update({f"identities.{k}": torch.from_numpy(np.ascontiguousarray(v)) for k, v in identities.arrays().items()})
    meta = {"format": FORMAT, "step": str(int(step)), "config": json.dumps(cfg.to_dict()),
            "layout": json.dumps(layout.to_dict()), "losses": json.dumps(losses), "dataset": str(dataset),
            "optimizer_sha256": sha256_bytes(opt_bytes), "head_model": json.dumps(head_model or {})}
    opt_path = path.with_name(path.name.replace(".safetensors", ".optim.pt"))
    atomic_write_bytes(opt_path, opt_bytes)
    atomic_write_bytes(path, st_save(tensors, metadata=meta))
    for _, old in list_checkpoints(run_dir)[:-keep]:
        old.with_name(old.name.replace(".safetensors", ".optim.pt")).unlink(missing_ok=True)
        old.unlink(missing_ok=True)
    return path


def _refuse(path: Path, what: str):
    raise SynthError(f"{what}", str(path), "pass a checkpoint written by `synth prior train`; if it was damaged, "
                                           "delete it and resume from an older one")


def load(path) -> Checkpoint:
    """Read a model checkpoint; truncated, foreign or inconsistent files are refused (SynthError)."""
    from safetensors import SafetensorError
    from safetensors.torch import load as st_load

    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise SynthError("checkpoint not found", str(path), "check the path") from None
    try:
        tensors = st_load(data)
        meta = _metadata(data)
    except (SafetensorError, ValueError, RuntimeError, json.JSONDecodeError, UnicodeDecodeError) as e:
        _refuse(path, f"not a readable safetensors checkpoint (truncated or foreign: {str(e).splitlines()[0][:80]})")
    if meta.get("format") != FORMAT:
        _refuse(path, f"not a prior checkpoint (format {meta.get('format')!r}, expected {FORMAT!r})")
    try:
        cfg = run_config.from_dict(json.loads(meta["config"]), str(path))
        layout = CodeLayout.from_dict(json.loads(meta["layout"]))
        ident = IdentityInfo(**{k: tensors.pop(f"identities.{k}").numpy() for k in SAVED_IDENTITY_FIELDS})
        step = int(meta["step"])
    except (KeyError, ValueError, TypeError) as e:
        _refuse(path, f"checkpoint lacks or garbles {e}")
    model_state = {k[len("model."):]: v for k, v in tensors.items() if k.startswith("model.")}
    return Checkpoint(path, step, cfg, layout, ident, model_state, json.loads(meta.get("losses", "{}")),
                      meta.get("dataset", ""), json.loads(meta.get("head_model", "{}")))


def _metadata(data: bytes) -> dict:
    """The ``__metadata__`` of a safetensors byte string (its JSON header)."""
    n = int.from_bytes(data[:8], "little")
    if not 2 <= n <= len(data) - 8:
        raise ValueError("bad header length")
    return json.loads(data[8:8 + n]).get("__metadata__") or {}


def load_optimizer_state(ckpt: Checkpoint) -> dict:
    """The optimizer file beside ``ckpt``, checked against the hash the model file records."""
    p = ckpt.optimizer_path
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        _refuse(p, "optimizer state missing beside the checkpoint")
    want = _metadata(ckpt.path.read_bytes()).get("optimizer_sha256")
    if sha256_bytes(data) != want:
        _refuse(p, "optimizer state does not match its checkpoint (damaged or from another step)")
    try:
        return torch.load(io.BytesIO(data), weights_only=True)
    except Exception as e:  # torch raises UnpicklingError / RuntimeError with long texts
        _refuse(p, f"optimizer state unreadable ({type(e).__name__})")
