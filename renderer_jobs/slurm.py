"""The ``slurm`` backend: the batches as one Slurm job array, submitted with ``submitit``.

``synth render --backend slurm [--slurm-partition P] [--slurm-time MIN] [--cpus-per-task C]
[--gpus-per-task G] [--array-parallelism N]``: one array task per batch. Each task runs its
batch in a fresh worker process (:func:`renderer_jobs.spawn.run_batch`), retrying a crashed
worker in place up to ``--retries`` times. A task is *checkpointable*: when Slurm preempts it
or its time limit nears (submitit's ``USR2`` signal), it is requeued with the same batch and
the requeued task resumes from the frames staged. Logs: submitit's per task under
``DIR/logs/<run>/submitit/``, the worker's per attempt under ``DIR/logs/<run>/``; the
controller follows the latter for events (:mod:`renderer_jobs.remote`).

Task states come from ``squeue`` (also for finished tasks, which Slurm lists for
``MinJobAge`` seconds), so no accounting database is needed. A task cancelled with
``scancel`` ends its batch as a failure; rerunning ``synth render`` renders what is left.
The dataset directory must be on storage every node sees at the same path.
"""

from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path

import submitit

from renderer_jobs.backend import Backend, Job
from renderer_jobs.remote import RemoteRun
from renderer_jobs.spawn import STALL_TIMEOUT_S, run_batch, worker_env
from synth.errors import SynthError

#: squeue states after which an array task runs no more.
FINAL_STATES = {"COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY", "BOOT_FAIL",
                "DEADLINE", "SPECIAL_EXIT"}


class SlurmBatchTask(submitit.helpers.Checkpointable):
    """One array task: its batch, a crashed worker retried in place. Checkpointable: on
    preemption or an approaching time limit submitit requeues it with the same arguments."""

    def __call__(self, dataset: str, plan_dir: str, shards: list[str], batch: int, log_dir: str, retries: int,
                 stall_timeout: float) -> int:
        while True:
            end = run_batch(Path(dataset), Path(plan_dir), shards, batch, Path(log_dir), retries, None,
                            stall_timeout)
            if not end.retry:
                return end.returncode


def squeue_states(job_id: str) -> dict[str, str] | None:
    """``{"JOB_TASK": STATE}`` for every task of an array job Slurm still lists; ``None`` when
    squeue does not answer (the caller asks again later)."""
    try:
        p = subprocess.run(["squeue", "-h", "-r", "--states=all", "-j", job_id, "-o", "%i|%T"],
                           capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if p.returncode != 0:
        return None
    out = {}
    for line in p.stdout.splitlines():
        tid, _, state = line.strip().partition("|")
        if tid:
            out[tid] = state.split()[0] if state else ""
    return out


@dataclass
class SlurmOptions:
    partition: str | None = None
    time_min: int | None = None  # time limit per task, minutes
    cpus_per_task: int = 1
    gpus_per_task: int = 0
    array_parallelism: int | None = None  # tasks running at once (None: as Slurm allows)


class SlurmRun(RemoteRun):
    poll_s = 1.0

    def __init__(self, job: Job, opts: SlurmOptions, stall_timeout: float):
        super().__init__(job)
        ex = submitit.SlurmExecutor(folder=job.log_dir / "submitit" / "%j")
        params = dict(cpus_per_task=opts.cpus_per_task, job_name="synth-render", signal_delay_s=120,
                      setup=[f"export PYTHONPATH={worker_env()['PYTHONPATH']}"])
        if opts.partition:
            params["partition"] = opts.partition
        if opts.time_min:
            params["time"] = int(opts.time_min)
        if opts.gpus_per_task:
            params["gpus_per_node"] = int(opts.gpus_per_task)
        if opts.array_parallelism:
            params["array_parallelism"] = int(opts.array_parallelism)
        ex.update_parameters(**params)
        batches = list(job.batches)
        task = SlurmBatchTask()
        try:
            jobs = ex.map_array(task, [str(job.dataset)] * len(batches), [str(job.plan_dir)] * len(batches),
                                [list(b.shards) for b in batches], [b.index for b in batches],
                                [str(job.log_dir)] * len(batches), [job.retries] * len(batches),
                                [stall_timeout] * len(batches))
        except (subprocess.CalledProcessError, FileNotFoundError, OSError) as e:
            raise SynthError(f"sbatch failed ({str(e).splitlines()[0] if str(e) else type(e).__name__})", "slurm",
                             "check that Slurm works here (sinfo) and the --slurm-* options") from None
        self.tasks = {j.job_id: b.index for j, b in zip(jobs, batches)}  # "123_4" -> batch
        self.array_id = jobs[0].job_id.split("_")[0] if jobs else ""
        self._open = dict(self.tasks)

    def _ended_tasks(self) -> dict[int, str]:
        if not self._open:
            return {}
        states = squeue_states(self.array_id)
        if states is None:
            return {}
        out = {}
        for tid, batch in list(self._open.items()):
            state = states.get(tid, "GONE")
            if state in FINAL_STATES or state == "GONE":
                del self._open[tid]
                out[batch] = f"slurm task {tid} {state}"
        return out

    def _cancel_tasks(self) -> None:
        if self.array_id:
            subprocess.run(["scancel", self.array_id], capture_output=True, timeout=60)


class SlurmBackend(Backend):
    name = "slurm"

    def __init__(self, opts: SlurmOptions | None = None, stall_timeout: float = STALL_TIMEOUT_S):
        self.opts = opts or SlurmOptions()
        self.stall_timeout = stall_timeout

    def submit(self, job: Job) -> SlurmRun:
        return SlurmRun(job, self.opts, self.stall_timeout)
