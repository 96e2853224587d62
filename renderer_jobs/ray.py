"""The ``ray`` backend: one Ray core task per batch (``synth render --backend ray``).

Without ``--ray-address`` a local Ray runtime is started for the run (no set-up) and shut
down after it; with one, the run joins that cluster (``ray start --head`` on one machine,
``ray start --address HEAD:6379`` on the others; every node needs this synth installed and
the dataset directory at the same path, e.g. on shared storage).

Each task runs its batch in a fresh worker process (:func:`renderer_jobs.spawn.run_batch`:
parent-death signal, watchdog, log under ``DIR/logs/``). A task whose worker crashed raises
:class:`WorkerCrashed` and Ray runs it again (``retry_exceptions``); a task whose Ray worker
process died is rerun by Ray too (``max_retries``); both count against ``--retries``. The
rerun skips the shards committed meanwhile and keeps the frames staged. Tasks ask for one
CPU (``cpus_per_task``) and, when the cluster has GPUs, one GPU: Ray then sets
``CUDA_VISIBLE_DEVICES`` for the task, which the worker inherits. Events reach the
controller through the logs (:mod:`renderer_jobs.remote`).
"""

from __future__ import annotations

import os
from pathlib import Path

import ray

from renderer_jobs.backend import Backend, Job
from renderer_jobs.remote import RemoteRun
from renderer_jobs.spawn import STALL_TIMEOUT_S, run_batch, worker_env
from synth.errors import SynthError


class WorkerCrashed(RuntimeError):
    """A batch's worker crashed and attempts remain: raised in the task so Ray retries it."""


def render_batch_task(dataset: str, plan_dir: str, shards: list[str], batch: int, log_dir: str, retries: int,
                      stall_timeout: float) -> int:
    """The body of one Ray task: one attempt of a batch. Returns the worker's exit status."""
    end = run_batch(Path(dataset), Path(plan_dir), shards, batch, Path(log_dir), retries, None, stall_timeout)
    if end.retry:
        raise WorkerCrashed(f"worker for {','.join(shards)} exited with code {end.returncode}")
    return end.returncode


def _runtime_env() -> dict:
    """What every task needs in its environment: this checkout on the import path and the
    SYNTH_* settings of the controller (e.g. SYNTH_LEASE_SECONDS)."""
    env = worker_env({k: v for k, v in os.environ.items() if k.startswith("SYNTH_")})
    return {"env_vars": {k: env[k] for k in ("PYTHONPATH",) + tuple(k for k in env if k.startswith("SYNTH_"))
                         if k != "SYNTH_PARENT_PID"}}


class RayRun(RemoteRun):
    def __init__(self, job: Job, backend: RayBackend):
        super().__init__(job)
        gpus = 1 if ray.cluster_resources().get("GPU", 0) > 0 else 0
        task = ray.remote(render_batch_task).options(
            max_retries=job.retries, retry_exceptions=[WorkerCrashed], num_cpus=backend.cpus_per_task, num_gpus=gpus)
        self.refs = {task.remote(str(job.dataset), str(job.plan_dir), list(b.shards), b.index, str(job.log_dir),
                                 job.retries, backend.stall_timeout): b.index for b in job.batches}
        self._open = dict(self.refs)

    def _ended_tasks(self) -> dict[int, str]:
        if not self._open:
            return {}
        ready, _ = ray.wait(list(self._open), num_returns=len(self._open), timeout=0)
        out = {}
        for ref in ready:
            batch = self._open.pop(ref)
            try:
                out[batch] = f"exit status {ray.get(ref)}"
            except Exception as e:  # RayTaskError, WorkerCrashedError, TaskCancelledError, ...
                out[batch] = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
        return out

    def _cancel_tasks(self) -> None:
        for ref in list(self._open):
            try:
                ray.cancel(ref, force=True)  # kills the task's process; its worker dies with it
            except Exception:  # already finished
                pass


class RayBackend(Backend):
    """``address``: a running cluster to join (``None``: start a local runtime with ``workers``
    CPUs, default all). ``cpus_per_task``: CPUs each task asks for."""

    name = "ray"

    def __init__(self, address: str | None = None, workers: int | None = None, cpus_per_task: float = 1.0,
                 stall_timeout: float = STALL_TIMEOUT_S):
        self.address, self.workers, self.cpus_per_task = address, workers, cpus_per_task
        self.stall_timeout = stall_timeout
        self.connected = False

    def _connect(self) -> None:
        if self.connected:
            return
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no network calls home
        kw = dict(runtime_env=_runtime_env(), log_to_driver=False, configure_logging=False)
        try:
            if self.address:
                ray.init(address=self.address, **kw)
            else:
                ray.init(num_cpus=self.workers or os.cpu_count(), include_dashboard=False, **kw)
        except (ConnectionError, RuntimeError, ValueError) as e:
            where = self.address or "local runtime"
            raise SynthError(f"cannot start or join Ray ({str(e).splitlines()[0]})", where,
                             "check --ray-address (host:port of a running `ray start --head`)") from None
        self.connected = True

    def submit(self, job: Job) -> RayRun:
        self._connect()
        return RayRun(job, self)

    def close(self) -> None:
        if self.connected:
            ray.shutdown()  # a local runtime stops; a cluster keeps running
            self.connected = False
