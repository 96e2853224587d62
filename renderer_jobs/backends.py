"""The backends by name (``synth render --backend``), built from the command line's options."""

from __future__ import annotations

from renderer_jobs.backend import Backend
from synth.errors import SynthError

NAMES = ("local", "ray", "slurm")


def make_backend(name: str, *, workers: int | None = None, stall_timeout: float | None = None,
                 ray_address: str | None = None, partition: str | None = None, time_min: int | None = None,
                 cpus_per_task: int = 1, gpus_per_task: int = 0, array_parallelism: int | None = None) -> Backend:
    """A backend: ``local`` (``workers`` processes here), ``ray`` (a local runtime with
    ``workers`` CPUs, or the cluster at ``ray_address``) or ``slurm`` (a job array)."""
    from renderer_jobs.spawn import STALL_TIMEOUT_S

    stall = STALL_TIMEOUT_S if stall_timeout is None else stall_timeout
    if name == "local":
        from renderer_jobs.local import LocalBackend

        return LocalBackend(workers, stall_timeout=stall)
    if name == "ray":
        try:
            from renderer_jobs.ray import RayBackend
        except ImportError as e:
            raise SynthError(f"the ray backend needs the ray package ({e})", "--backend ray",
                             "install it: pip install 'synth-faces[farm]' (ray==2.60.0)") from None
        return RayBackend(ray_address, workers, cpus_per_task, stall)
    if name == "slurm":
        try:
            from renderer_jobs.slurm import SlurmBackend, SlurmOptions
        except ImportError as e:
            raise SynthError(f"the slurm backend needs the submitit package ({e})", "--backend slurm",
                             "install it: pip install 'synth-faces[farm]' (submitit==1.5.4)") from None
        return SlurmBackend(SlurmOptions(partition, time_min, cpus_per_task, gpus_per_task, array_parallelism), stall)
    raise SynthError(f"unknown backend {name!r}", "--backend", f"use one of {', '.join(NAMES)}")
