"""Building what a run needs: the model, the scene sphere, the device and the process group."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import numpy as np
import torch

from prior.train.config import RunConfig
from synth.errors import SynthError


def build_model(cfg: RunConfig, code_dim: int, num_latents: int, device="cpu"):
    from prior.model import PriorField

    return PriorField(cfg.model, cfg.sampling, code_dim, num_latents).to(device)


def fit_scene(cfg: RunConfig, centre: np.ndarray, radius: np.ndarray) -> RunConfig:
    """``cfg`` with model.scene_center / scene_radius set to a sphere holding every identity's
    bounding sphere (centre of their box, farthest reach), when data.fit_scene is on."""
    if not cfg.data.fit_scene:
        return cfg
    lo, hi = (centre - radius[:, None]).min(0), (centre + radius[:, None]).max(0)
    c = 0.5 * (lo + hi)
    r = float((np.linalg.norm(centre - c, axis=1) + radius).max())
    model = dataclasses.replace(cfg.model, scene_center=tuple(float(x) for x in c), scene_radius=r)
    return dataclasses.replace(cfg, model=model)


def resolve_device(name: str) -> torch.device:
    if name == "cuda" and not torch.cuda.is_available():
        raise SynthError("CUDA is not available on this machine", "--device cuda", "use --device cpu")
    if name not in ("cpu", "cuda"):
        raise SynthError(f"unknown device {name!r}", "--device", "use cpu or cuda")
    return torch.device(name)


@dataclass
class Dist:
    """This process's place in a torchrun job (rank 0 of 1 without torchrun)."""

    rank: int = 0
    world: int = 1
    local_rank: int = 0
    #: a process group is up (torchrun), even of one process
    enabled: bool = False

    @property
    def main(self) -> bool:
        return self.rank == 0


def init_distributed(device: torch.device) -> Dist:
    """Join the process group that torchrun describes in the environment (RANK, WORLD_SIZE,
    LOCAL_RANK, MASTER_ADDR/PORT): NCCL on CUDA, gloo on CPU. Without torchrun: rank 0 of 1."""
    env = os.environ
    if "RANK" not in env or "WORLD_SIZE" not in env:
        return Dist()
    d = Dist(int(env["RANK"]), int(env["WORLD_SIZE"]), int(env.get("LOCAL_RANK", 0)), True)
    import torch.distributed as dist

    if not dist.is_initialized():
        if device.type == "cuda":
            torch.cuda.set_device(d.local_rank)
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo", rank=d.rank, world_size=d.world)
    return d


def device_for(d: Dist, device: torch.device) -> torch.device:
    return torch.device("cuda", d.local_rank) if device.type == "cuda" else device


def shutdown_distributed(wait_for_peers: bool = False) -> None:
    """Leave the process group. After a run that ended normally every rank first waits for
    the others (rank 0 may still be writing the last checkpoint), so no rank tears down its
    connections while a peer still uses them; after an error nobody waits (a peer may be gone)."""
    import gc

    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        if wait_for_peers and dist.get_world_size() > 1:
            dist.barrier()
        gc.collect()  # DDP reducers still holding the group go first
        dist.destroy_process_group()
