"""Streaming training data: a bounded buffer of decoded identities per rank, refilled ahead of use.

Rank ``r`` of ``w`` owns the latent ids ``m`` with ``m % w == r`` (so ranks read disjoint
identities; with one shard per identity, as ``synth render`` writes them, disjoint shards).
Per epoch ``e`` it visits its committed identities in an order drawn from (seed, e, r); it holds
at most ``data.buffer_identities`` of them decoded (0 = all), and the sampler
(:mod:`prior.data.sampler`) draws each step's identities among those held.

Swapping (after every step, :meth:`Loader.advance`): an identity is *due* once
``data.views_per_load`` x (its training frames) views were drawn from it since it was loaded;
each due identity (lowest latent id first) is replaced by the next identity of the epoch
order that is not held. When the order is used up, the next epoch starts with a new order over
the identities committed by then (dataset directories are listed again, at most every
``data.refresh_steps`` steps; newly committed shards get their prepare record first), and only
if some identity is not held: a buffer that holds every identity never swaps.

Everything the buffer does is a function of the state saved in checkpoints
(:meth:`Loader.state_dict`: epoch, order, position, held identities, draw counts, skipped
shards), so a resumed run holds, and draws from, exactly what it would have. A background
thread decodes the next ``data.read_ahead`` identities of the order while training runs
(:meth:`Loader._prefetch`); a swap waits for it only when it is behind.

A shard that cannot be read as its manifest says is skipped with one warning line naming it,
counted (``skipped_shards`` in the run's metrics), and not read again by this run.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Callable

import numpy as np

from prior.data.codes import CodeLayout
from prior.data.prepare import Table, build_table, prepare, record_meta, trim_heap
from prior.data.sources import ShardDamaged, Source, frame_meta, read_shard
from synth.dataset.reader import decode_frame
from synth.errors import SynthError

#: first word of the epoch-order seeds
EPOCH_STREAM = 0xE90C


@dataclass
class IdentityData:
    """One identity's frames, decoded (frames in (shard, key) order)."""

    latent: int
    keys: list[str]
    rgba: np.ndarray  # (F, H, W, 4) premultiplied colour and alpha (float16: the EXR's HALF values exactly)
    K: np.ndarray  # (F, 3, 3) float64
    c2w: np.ndarray  # (F, 4, 4) float64
    codes: np.ndarray  # (F, C) float32
    expression: np.ndarray  # (F,) int64
    view: np.ndarray  # (F,) int64
    train: np.ndarray  # (F,) bool: False for held-out views
    fg_offsets: np.ndarray  # (F + 1,) int64 into fg_pixels
    fg_pixels: np.ndarray  # flat (row * W + col) indices of foreground pixels, int32

    @cached_property
    def train_frames(self) -> np.ndarray:
        return np.nonzero(self.train)[0]

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in (self.rgba, self.K, self.c2w, self.codes, self.expression, self.view,
                                          self.train, self.fg_offsets, self.fg_pixels)))


def load_identity(table: Table, m: int, *, holdout_views: int, pixel_dtype: str = "float16") -> IdentityData:
    """Decode every frame of latent id ``m`` from its shards. Raises ShardDamaged (naming the shard)."""
    ident = int(table.info.identity_index[m])
    H, W = table.size
    layout: CodeLayout = table.layout
    keys, rgba, K, c2w, codes, ex, vw, fg = [], [], [], [], [], [], [], []
    for ref in table.shards_of.get(m, []):
        try:
            for key, jb, eb in read_shard(ref, ident):
                meta = frame_meta(jb, key)
                hm = {k: meta.get("model", {}).get(k) for k in ("name", "sha256")}
                if hm != table.head_model:
                    raise ShardDamaged(f"frame {key} was rendered with head model {hm.get('name')!r}, the run's is "
                                       f"{table.head_model.get('name')!r}")
                try:
                    f = decode_frame(jb, eb, key=key, shard=ref.shard, where=f"{ref.path}:{key}")
                except SynthError as e:
                    raise ShardDamaged(f"frame {key}: {e.what}") from None
                if (f.height, f.width) != (H, W):
                    raise ShardDamaged(f"frame {key} is {f.width}x{f.height}, the run's frames are {W}x{H}")
                keys.append(key)
                rgba.append(f.rgba.astype(pixel_dtype))
                K.append(f.K)
                c2w.append(f.camera_to_world)
                codes.append(layout.code(f))
                ex.append(f.expression_index)
                vw.append(f.view_index)
                fg.append(np.flatnonzero(f.alpha.reshape(-1) > 0).astype(np.int32))
        except ShardDamaged as e:
            raise ShardDamaged(f"skipping damaged shard {ref.shard} ({ref.path}): {e}") from None
    if not keys:
        raise ShardDamaged(f"skipping identity {ident}: its shards hold none of its frames")
    ex_a, vw_a = np.asarray(ex, np.int64), np.asarray(vw, np.int64)
    train = np.ones(len(keys), bool)
    if holdout_views:
        for e in np.unique(ex_a):
            sel = np.nonzero(ex_a == e)[0]
            if len(sel) <= holdout_views:
                raise SynthError(f"identity {ident} expression {e} has {len(sel)} views, not more than "
                                 f"data.holdout_views = {holdout_views}", str(table.shards_of[m][0].path),
                                 "lower data.holdout_views or render more views")
            train[sel[np.argsort(vw_a[sel], kind="stable")[-holdout_views:]]] = False
    offsets = np.concatenate([[0], np.cumsum([len(x) for x in fg])]).astype(np.int64)
    return IdentityData(m, keys, np.stack(rgba), np.stack(K), np.stack(c2w), np.stack(codes), ex_a, vw_a, train,
                        offsets, np.concatenate(fg))


class Loader:
    """The buffer of one rank (see the module docstring)."""

    def __init__(self, source: Source, table: Table, *, seed: int, rank: int = 0, world: int = 1,
                 buffer_identities: int = 0, views_per_load: float = 4.0, read_ahead: int = 2,
                 refresh_steps: int = 1000, holdout_views: int = 0, pixel_dtype: str = "float16",
                 prepare_dir: Path | None = None, margin: float = 0.05, warn: Callable[[str], None] = print):
        self.source, self.table, self.seed = source, table, int(seed)
        self.rank, self.world = int(rank), int(world)
        self.capacity = int(buffer_identities)
        self.reuse, self.refresh_steps = float(views_per_load), int(refresh_steps)
        self.holdout, self.dtype = int(holdout_views), pixel_dtype
        self.prepare_dir, self.margin, self.warn = prepare_dir, float(margin), warn
        self.read_ahead = int(read_ahead)
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="prior-read-ahead") if read_ahead else None
        self.pending: dict[int, Future] = {}
        self.held: dict[int, IdentityData] = {}
        self.counts: dict[int, int] = {}
        self.bad: set[str] = set()
        self.skipped: list[str] = []
        self.epoch, self.order, self.pos, self.listed_at = -1, [], 0, 0
        self.step = 0

    # ------------------------------------------------------------------ which identities
    def mine(self) -> list[int]:
        """This rank's latent ids with committed frames whose shards are not known damaged."""
        t = self.table
        return [int(m) for m in t.available if m % self.world == self.rank
                and not any(r.shard in self.bad for r in t.shards_of.get(int(m), []))]

    def _epoch_order(self, epoch: int, ids: list[int]) -> list[int]:
        rng = np.random.default_rng([EPOCH_STREAM, self.seed, epoch, self.rank])
        return [ids[i] for i in rng.permutation(len(ids))]

    def _refresh(self) -> None:
        """List the committed shards again and prepare the new ones (dataset directories)."""
        if self.source.root is None or self.prepare_dir is None:
            return
        known = {r.shard for refs in self.table.shards_of.values() for r in refs}
        refs = self.source.committed()
        if not any(r.shard not in known and r.shard not in self.bad for r in refs):
            return
        res = prepare(self.source, self.prepare_dir, refs=[r for r in refs if r.shard not in self.bad],
                      warn=self._skip_line, write_merged=self.rank == 0)
        self.bad |= set(res.skipped_shards)
        t = self.table
        for k in reversed(range(len(res.records))):  # a new shard unlike the run's frames: skipped, one line
            meta, ref = record_meta(res.records[k]), res.refs[k]
            if meta["head_model"] != t.head_model or tuple(meta["size"]) != (t.size[1], t.size[0]) \
                    or tuple(meta["code_sizes"]) != (t.layout.identity_size, t.layout.expression_size):
                self.bad.add(ref.shard)
                self._skip_line(f"skipping shard {ref.shard} ({ref.path}): its frames are "
                                f"{meta['size'][0]}x{meta['size'][1]} of head model "
                                f"{meta['head_model'].get('name')!r}, the run's {t.size[1]}x{t.size[0]} of "
                                f"{t.head_model.get('name')!r}")
                del res.records[k], res.refs[k]
        try:
            table = build_table(res, joints=self.table.layout.joints, margin=self.margin,
                                holdout_views=self.holdout, planned=self.table.info.identity_index.tolist(),
                                where=self.source.describe())
        except SynthError as e:
            self._skip_line(f"new shards not taken in: {e.what}")
            return
        finally:
            del res
            trim_heap()
        if not np.array_equal(table.info.identity_index, self.table.info.identity_index):
            self._skip_line("new shards not taken in: the dataset's plan changed")
            return
        keep = self.table.frames > 0  # identities already trained keep their bounds (the run's, exactly)
        for k in ("centre", "radius", "front_K", "front_c2w", "front_size"):
            getattr(table.info, k)[keep] = getattr(self.table.info, k)[keep]
        self.table = table

    def _skip_line(self, line: str) -> None:
        self.skipped.append(line)
        self.warn(line)

    # ------------------------------------------------------------------ loading
    def _load(self, m: int) -> IdentityData:
        return load_identity(self.table, m, holdout_views=self.holdout, pixel_dtype=self.dtype)

    def _prefetch(self) -> None:
        if self.pool is None:
            return
        want = [m for m in self.order[self.pos:] if m not in self.held][:self.read_ahead]
        for m in list(self.pending):
            if m not in want:
                self.pending.pop(m).cancel()
        for m in want:
            if m not in self.pending:
                self.pending[m] = self.pool.submit(self._load, m)

    def _take(self, m: int) -> bool:
        """Hold latent id ``m``; False (one warning line) when its shard is damaged."""
        fut = self.pending.pop(m, None)
        try:
            data = fut.result() if fut is not None else self._load(m)
        except ShardDamaged as e:
            for r in self.table.shards_of.get(m, []):
                self.bad.add(r.shard)
            self._skip_line(str(e))
            return False
        self.held[m] = data
        self.counts[m] = 0
        return True

    def _next(self) -> int | None:
        """Load the next identity of the order (starting a new epoch when it is used up and
        some identity is not held); returns its id or None."""
        for _ in range(2):
            while self.pos < len(self.order):
                m = self.order[self.pos]
                self.pos += 1
                if m not in self.held and not any(r.shard in self.bad for r in self.table.shards_of.get(m, [])) \
                        and self._take(m):
                    return m
            if self.epoch >= 0 and self.step - self.listed_at >= self.refresh_steps:
                self._refresh()
                self.listed_at = self.step
            ids = [m for m in self.mine() if m not in self.held]
            if not ids:
                return None
            self.epoch += 1
            self.order, self.pos = self._epoch_order(self.epoch, self.mine()), 0
        return None

    def start(self) -> None:
        """Fill the buffer (a fresh run)."""
        if not self.mine():
            raise SynthError(f"rank {self.rank} of {self.world} has no committed identity (the dataset has "
                             f"{len(self.table.available)})", self.source.describe(),
                             "use at most as many ranks as committed identities, or wait for the render")
        self.epoch, self.order, self.pos = 0, self._epoch_order(0, self.mine()), 0
        self._fill()

    def _fill(self) -> None:
        cap = self.capacity or len(self.mine())
        self._prefetch()
        while len(self.held) < cap:
            if self.pos >= len(self.order) or self._next() is None:
                break
            self._prefetch()
        if not self.held:
            raise SynthError(f"rank {self.rank} could read none of its identities", self.source.describe(),
                             "run `synth validate` on the dataset")

    @property
    def slots(self) -> np.ndarray:
        """Held latent ids, ascending (the sampler draws among them)."""
        return np.array(sorted(self.held), np.int64)

    def advance(self, drawn: np.ndarray, views: int) -> None:
        """After a step: count the views drawn per identity (``drawn``: latent ids, one per
        identity draw, ``views`` views each), then swap the due identities."""
        self.step += 1
        for m in np.asarray(drawn).tolist():
            self.counts[m] = self.counts.get(m, 0) + views
        for m in sorted(self.held):
            if self.counts[m] >= self.reuse * max(int(self.held[m].train.sum()), 1):
                nxt = self._next()
                if nxt is None:
                    break
                if self.capacity:  # a buffer of every identity grows instead
                    del self.held[m], self.counts[m]
        self._prefetch()

    @property
    def nbytes(self) -> int:
        """Bytes of decoded frames held (the buffer; read-ahead not included)."""
        return sum(d.nbytes for d in self.held.values())

    # ------------------------------------------------------------------ checkpoint state
    def state_dict(self) -> dict:
        return {"epoch": self.epoch, "order": list(self.order), "pos": self.pos, "held": sorted(self.held),
                "counts": [self.counts[m] for m in sorted(self.held)], "bad": sorted(self.bad),
                "skipped": list(self.skipped), "listed_at": self.listed_at, "step": self.step,
                "rank": self.rank, "world": self.world}

    def load_state_dict(self, s: dict) -> None:
        """Hold exactly what the saved loader held (decoded again), in the same epoch and place."""
        self.bad = set(s["bad"])
        self.epoch, self.order, self.pos = int(s["epoch"]), [int(x) for x in s["order"]], int(s["pos"])
        self.listed_at, self.step = int(s["listed_at"]), int(s["step"])
        self.skipped = [str(x) for x in s["skipped"]]
        for m, c in zip(s["held"], s["counts"]):
            if not self._take(int(m)):
                raise SynthError(f"identity {int(self.table.info.identity_index[int(m)])} held at the checkpoint "
                                 "cannot be read now", self.source.describe(), "restore its shard or start a new run")
            self.counts[int(m)] = int(c)
        self._prefetch()

    def close(self) -> None:
        if self.pool is not None:
            for f in self.pending.values():
                f.cancel()
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None


__all__ = ["EPOCH_STREAM", "IdentityData", "Loader", "load_identity"]
