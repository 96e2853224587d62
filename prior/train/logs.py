"""What a run reports (rank 0 only): a rich progress bar on a terminal, plain lines otherwise,
``RUN/metrics.jsonl`` (one JSON object per logged step, read by ``synth prior info``) and
TensorBoard scalars and preview images in ``RUN/tb``."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from synth.io import atomic_write_bytes

METRICS_FILE = "metrics.jsonl"
TB_DIR = "tb"


def read_metrics(run_dir) -> list[dict]:
    p = Path(run_dir) / METRICS_FILE
    if not p.is_file():
        return []
    out = []
    for line in p.read_text(encoding="utf-8").splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:  # a line cut by a crash
            continue
    return out


def _eta(seconds: float) -> str:
    s = int(max(seconds, 0))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


class RunLog:
    def __init__(self, run_dir, *, total: int, start: int, enabled: bool = True, tty: bool | None = None,
                 tensorboard: bool = True):
        self.run_dir, self.total, self.start, self.enabled = Path(run_dir), total, start, enabled
        self.tty = sys.stdout.isatty() if tty is None else tty
        self.t0, self.last = time.perf_counter(), None
        self.tb = self.progress = None
        if not enabled:
            return
        # a resumed run forgets what was logged after its checkpoint
        kept = [m for m in read_metrics(run_dir) if int(m.get("step", 0)) <= start]
        atomic_write_bytes(self.run_dir / METRICS_FILE, "".join(json.dumps(m) + "\n" for m in kept).encode())
        self._metrics = open(self.run_dir / METRICS_FILE, "a", encoding="utf-8")
        if tensorboard:
            from torch.utils.tensorboard import SummaryWriter

            self.tb = SummaryWriter(str(self.run_dir / TB_DIR), purge_step=start)
        if self.tty:
            from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

            self.progress = Progress(TextColumn("step {task.completed}/{task.total}"), BarColumn(),
                                     TextColumn("{task.fields[info]}"), TimeRemainingColumn())
            self.task = self.progress.add_task("train", total=total, completed=start, info="")
            self.progress.start()

    def advance(self, step: int) -> None:
        """``step`` steps are complete."""
        if self.progress is not None:
            self.progress.update(self.task, completed=step)

    def log(self, step: int, metrics: dict) -> None:
        """Report the metrics of completed step ``step``."""
        if not self.enabled:
            return
        now = time.perf_counter()
        rate = (step - self.start) / max(now - self.t0, 1e-9)
        metrics = {"step": step, **metrics, "eta_s": round((self.total - step) / max(rate, 1e-9), 1)}
        self._metrics.write(json.dumps(metrics) + "\n")
        self._metrics.flush()
        if self.tb is not None:
            for k, v in metrics.items():
                if isinstance(v, (int, float)) and k not in ("step", "eta_s"):
                    self.tb.add_scalar(f"train/{k}", v, step)
        info = (f"loss {metrics['loss']:.4f}  psnr {metrics['psnr']:.2f} dB  acc_fg {metrics['acc_fg']:.3f}  "
                f"{metrics['rays_per_s']:.0f} rays/s  {metrics['stage']}")
        if self.progress is not None:
            self.progress.update(self.task, completed=step, info=info)
        else:
            print(f"step {step}/{self.total}  {info}  eta {_eta(metrics['eta_s'])}", flush=True)

    def message(self, text: str) -> None:
        if not self.enabled:
            return
        if self.progress is not None:
            self.progress.console.print(text)
        else:
            print(text, flush=True)

    def image(self, tag: str, img: np.ndarray, step: int) -> None:
        """``img`` (H, W, 3) uint8."""
        if self.tb is not None:
            self.tb.add_image(tag, img, step, dataformats="HWC")

    def close(self) -> None:
        if not self.enabled:
            return
        if self.progress is not None:
            self.progress.stop()
        if self.tb is not None:
            self.tb.close()
        self._metrics.close()
