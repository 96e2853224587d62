"""The statistics of a training step by name, and their trip through the ranks' all-reduce.

A step accumulates :class:`StepStats` on the device (no host sync per micro-batch); the log
adds the rank's skipped shards (:class:`LoggedStats`), sums every field over the ranks with
one all-reduce of :meth:`to_tensor`, and averages the per-step means (:attr:`StepStats.MEANS`)
over the ranks. ``metrics.jsonl``'s loss, l1, proposal, psnr, acc_fg and skipped_shards come
from these fields.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import torch


@dataclass(frozen=True)
class StepStats:
    """0-d float32 tensors, summed over the micro-batches of a step."""

    loss: torch.Tensor  # L1 + proposal_weight * proposal, mean over micro-batches
    l1: torch.Tensor  # mean over micro-batches
    proposal: torch.Tensor  # mean over micro-batches
    sq_err: torch.Tensor  # sum over valid rays of the per-ray mean squared colour error
    fg_acc: torch.Tensor  # sum of the opacity over valid foreground rays (alpha > 0.5)
    fg_rays: torch.Tensor  # count of valid foreground rays
    valid_rays: torch.Tensor  # count of rays that cross their bounding sphere

    #: the fields that are means (averaged over ranks); the others are sums
    MEANS: ClassVar[tuple[str, ...]] = ("loss", "l1", "proposal")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    def to_tensor(self) -> torch.Tensor:
        """The fields as one (len(names()),) tensor, in the order of :meth:`names`."""
        return torch.stack([getattr(self, k) for k in self.names()])

    @classmethod
    def from_tensor(cls, t: torch.Tensor):
        return cls(*t.unbind())

    @classmethod
    def accumulator(cls, device) -> torch.Tensor:
        """Zeros to which a step adds each micro-batch's :meth:`to_tensor`."""
        return torch.zeros(len(cls.names()), device=device)

    def mean_over_ranks(self, world: int):
        """The ranks' summed stats with the :attr:`MEANS` divided by ``world``."""
        return dataclasses.replace(self, **{k: getattr(self, k) / world for k in self.MEANS})

    def values(self) -> dict[str, float]:
        """Every field as a Python float (one host sync)."""
        return dict(zip(self.names(), self.to_tensor().tolist()))


@dataclass(frozen=True)
class LoggedStats(StepStats):
    """A step's stats with the count of shards the rank's loader has skipped (summed over ranks)."""

    skipped_shards: torch.Tensor

    @classmethod
    def of(cls, stats: StepStats, skipped: int) -> "LoggedStats":
        tail = torch.tensor(float(skipped), device=stats.loss.device)
        return cls(**{k: getattr(stats, k) for k in StepStats.names()}, skipped_shards=tail)
