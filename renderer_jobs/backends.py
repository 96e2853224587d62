"""The backends by name (``synth render --backend``), built from the command line's options."""

from __future__ import annotations

from renderer_jobs.backend import Backend
from synth.errors import SynthError
from synth.extras import require

NAMES = ("local", "ray", "slurm")


def make_backend(name: str, *, workers: int | None = None, stall_timeout: float | None = None,
                 ray_address: str | None = None, partition: str | None = None, time_min: int | None = None,
                 cpus_per_task: int = 1, gpus_per_task: int = 0, array_parallelism: int | None = None) -> Backend:
    """A backend: ``local`` (``workers`` processes here), ``ray`` (a local runtime with
    ``workers`` CPUs, or the cluster at ``ray_address``) or ``slurm`` (a job array). Building
    one starts nothing; a backend whose package (the ``farm`` extra) is missing is refused
    with one line (:func:`synth.extras.require`)."""
    from renderer_jobs.spawn import STALL_TIMEOUT_S

    stall = STALL_TIMEOUT_S if stall_timeout is None else stall_timeout
    if name == "local":
        from renderer_jobs.local import LocalBackend

        return LocalBackend(workers, stall_timeout=stall)
    if name == "ray":
        require("farm", ("ray",), "synth render --backend ray")
        from renderer_jobs.ray import RayBackend

        return RayBackend(ray_address, workers, cpus_per_task, stall)
    if name == "slurm":
        require("farm", ("submitit",), "synth render --backend slurm")
        from renderer_jobs.slurm import SlurmBackend, SlurmOptions

        return SlurmBackend(SlurmOptions(partition, time_min, cpus_per_task, gpus_per_task, array_parallelism), stall)
    raise SynthError(f"unknown backend {name!r}", "--backend", f"use one of {', '.join(NAMES)}")
