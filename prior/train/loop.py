"""The training loop of the prior (Cafca Sec. 3.2): L1 + proposal loss, Adam with exponential
learning-rate decay, per-MLP gradient clipping, the two background stages, checkpoints.

Per step ``s`` (``train.steps`` in all): for each of ``grad_accum`` micro-batches, draw rays
(:class:`prior.data.RaySampler`, seeded by (seed, s, micro, rank)), render them with
stratified jitter from a generator seeded the same way, and back-propagate
``(L1 + proposal_weight * L_prop) / grad_accum``. The L1 target is the premultiplied colour plus
``(1 - alpha) * train.background`` while ``s < train.background_steps`` (stage "bg"), the
premultiplied colour (over black) afterwards (stage "nobg"); the model never adds a
background, so in stage "bg" empty space inside the bounds must get density. Rays that miss
their identity's bounding sphere are left out of the L1 mean.

Then the gradients are clipped per parameter group, checked (a non-finite loss or gradient
stops the run with the last good checkpoint kept), and Adam steps; then the rank's buffer of
identities may swap (:mod:`prior.data.stream`). Under torchrun the model is wrapped in DDP and
each rank draws from its own identities. Ctrl-C finishes the
current step, writes a checkpoint and exits with 130.
"""

from __future__ import annotations

import contextlib
import math
import signal
import sys
import time

import numpy as np
import torch

from prior import losses
from prior.data.sampler import RaySampler
from prior.precision import resolve_bf16
from prior.rays import RayBundle
from prior.data.stream import Loader
from prior.render_views import render_image, scaled_camera
from prior.train import checkpoint as ckpt
from prior.train.logs import RunLog
from prior.train.optim import build_optimizer, clip_per_group, learning_rate, set_learning_rate
from prior.train.run import RunSetup, write_run_files
from prior.train.setup import Dist, build_model
from prior.train.stats import LoggedStats, StepStats
from synth.appearance.srgb import srgb8
from synth.errors import SynthError

#: first word of the seeds of the stratified-sampling generators
JITTER_STREAM = 0x5A3F
INTERRUPTED = 130


def jitter_seed(seed: int, step: int, micro: int, rank: int) -> int:
    return int(np.random.SeedSequence([JITTER_STREAM, seed, step, micro, rank]).generate_state(1, np.uint64)[0])


class _StopFlag:
    """SIGINT sets ``hit`` (the step in flight finishes); a second SIGINT interrupts at once."""

    def __init__(self):
        self.hit = False
        self._old = None

    def __enter__(self):
        try:
            self._old = signal.signal(signal.SIGINT, self._handle)
        except ValueError:  # not the main thread: no handler
            self._old = None
        return self

    def _handle(self, *_):
        self.hit = True
        signal.signal(signal.SIGINT, signal.default_int_handler)

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)


class Trainer:
    def __init__(self, setup: RunSetup, device: torch.device, dist: Dist | None = None, *, tty=None,
                 tensorboard: bool = True):
        dist = dist or Dist()
        self.s, self.cfg, self.dev, self.dist = setup, setup.cfg, device, dist
        t, tb, d = self.cfg.train, setup.table, self.cfg.data
        per = dist.world * t.grad_accum
        if t.identities_per_batch % per:
            raise SynthError(f"train.identities_per_batch = {t.identities_per_batch} is not a multiple of ranks x "
                             f"grad_accum = {per}", "config", "change identities_per_batch or grad_accum")
        self.loader = Loader(setup.source, tb, seed=t.seed, rank=dist.rank, world=dist.world,
                             buffer_identities=d.buffer_identities, views_per_load=d.views_per_load,
                             read_ahead=d.read_ahead, refresh_steps=d.refresh_steps, holdout_views=d.holdout_views,
                             pixel_dtype=d.pixel_dtype, prepare_dir=setup.prepare_dir, margin=d.bounds_margin,
                             warn=self._warn)
        self.sampler = RaySampler(self.loader, seed=t.seed, identities=t.identities_per_batch // per,
                                  views=t.views_per_identity, pixels=t.pixels_per_view,
                                  foreground_fraction=t.foreground_fraction, rank=dist.rank)
        self.model = build_model(self.cfg, tb.layout.size, len(tb.info.identity_index), device)
        self.opt = build_optimizer(self.model, t)
        self.start, self.collapse_count = 0, 0
        loader_state = None
        if setup.resume_from is not None:
            rf = setup.resume_from
            self.model.load_state_dict(rf.model_state)
            state = ckpt.load_optimizer_state(rf)
            self.opt.load_state_dict(state["optimizer"])
            self.start = int(state["step"])
            self.collapse_count = int(state["trainer"].get("collapse_count", 0))
            torch.set_rng_state(state["torch_rng"])
            saved = state["trainer"].get("loader") or []
            if len(saved) == dist.world:
                loader_state = saved[dist.rank]
            elif dist.main:
                self._warn(f"the checkpoint's data order is of {len(saved) or 'another number of'} rank(s), this run "
                           f"has {dist.world}: the buffer starts afresh (batches differ from an uninterrupted run)")
        if loader_state is not None:
            self.loader.load_state_dict(loader_state)
        else:
            self.loader.start()
        self.fwd = self.ddp = self.model
        if dist.enabled:
            from torch.nn.parallel import DistributedDataParallel as DDP

            # the predicted-normals head gets no gradient from L1 + proposal (fine-tuning trains it)
            self.fwd = self.ddp = DDP(self.model, device_ids=[device.index] if device.type == "cuda" else None,
                                      find_unused_parameters=True)
        if t.compile:
            self.fwd = torch.compile(self.fwd)
        self.bf16, bf16_line = resolve_bf16(t.bf16, device, "train.bf16")
        self.bg = torch.tensor(t.background, dtype=torch.float32, device=device)
        self.last_saved = setup.resume_from.step if setup.resume_from is not None else None
        self.losses: dict = {}
        if dist.main:
            write_run_files(setup, dist.world, self.bf16)
        self.log = RunLog(setup.run_dir, total=t.steps, start=self.start, enabled=dist.main, tty=tty,
                          tensorboard=tensorboard)
        self.log.message(bf16_line)

    # ------------------------------------------------------------------ one step
    def _tensors(self, b) -> tuple[RayBundle, torch.Tensor]:
        """A sampler batch on the device: its rays and their premultiplied colour and alpha."""
        rays = RayBundle.from_numpy(b.origins, b.directions, b.near, b.far, b.codes, latent_ids=b.latent_ids,
                                    radii=b.radii, device=self.dev)
        return rays, torch.as_tensor(b.rgba, dtype=torch.float32).to(self.dev, non_blocking=True)

    def step(self, step: int) -> StepStats:
        """Forward and backward of every micro-batch of ``step``; returns their statistics."""
        t = self.cfg.train
        stage_bg = step < t.background_steps
        acc_n = t.grad_accum
        stats = StepStats.accumulator(self.dev)
        # a 0-d tensor under torch.compile (a float would be a constant: one recompile per step)
        frac = torch.tensor(step / t.steps, device=self.dev) if t.compile else step / t.steps
        for micro in range(acc_n):
            rays, rgba = self._tensors(self.sampler.batch(step, micro))
            gen = torch.Generator(device=self.dev).manual_seed(jitter_seed(t.seed, step, micro, self.dist.rank))
            sync = self.ddp.no_sync() if (self.dist.enabled and micro < acc_n - 1) else contextlib.nullcontext()
            with sync:
                with torch.autocast(self.dev.type, dtype=torch.bfloat16, enabled=self.bf16):
                    out = self.fwd(rays, train_frac=frac, randomized=True, generator=gen)
                alpha = rgba[:, 3]
                target = rgba[:, :3] + (1 - alpha)[:, None] * self.bg if stage_bg else rgba[:, :3]
                valid = rays.valid
                l1 = losses.l1_loss(out["rgb"], target, valid)
                prop = losses.proposal_loss(out["history"])
                loss = l1 + t.proposal_weight * prop
                (loss / acc_n).backward()
            with torch.no_grad():
                fg = valid * (alpha > 0.5).float()
                se = (((out["rgb"].float() - target) ** 2).mean(-1) * valid).sum()
                stats += StepStats(loss=loss.detach() / acc_n, l1=l1.detach() / acc_n, proposal=prop.detach() / acc_n,
                                   sq_err=se, fg_acc=(out["acc"].float() * fg).sum(), fg_rays=fg.sum(),
                                   valid_rays=valid.sum()).to_tensor()
        return StepStats.from_tensor(stats)

    # ------------------------------------------------------------------ loop
    def run(self, *, stop_at: int | None = None, deadline: float | None = None) -> int:
        """Train from the start step to ``train.steps``; stop early with a checkpoint at step
        ``stop_at`` or at the first step that ends after ``deadline`` (``time.perf_counter()``
        seconds; benchmarks). Returns 0, or 130 when interrupted by SIGINT."""
        t = self.cfg.train
        if self.start == 0 and self.last_saved is None:
            self._save(0)  # a good checkpoint to fall back to from the first step on
        window = (time.perf_counter(), self.start)
        rays_step = self.cfg.rays_per_step
        with _StopFlag() as stop:
            try:
                for step in range(self.start, t.steps):
                    set_learning_rate(self.opt, learning_rate(step, t))
                    stats = self.step(step)
                    self.sampler.step_done()
                    norms = clip_per_group(self.opt, t.grad_clip)
                    flags = torch.stack([(~torch.isfinite(torch.stack([stats.loss, *norms.values()]))).any().float(),
                                         torch.tensor(float(stop.hit), device=self.dev)])
                    if self.dist.enabled:
                        torch.distributed.all_reduce(flags, op=torch.distributed.ReduceOp.MAX)
                    bad, interrupted = flags.tolist()
                    if bad:
                        kept = f"the last good checkpoint (step {self.last_saved}) is kept" \
                            if self.last_saved is not None else "no checkpoint was written"
                        raise SynthError(f"training loss or gradient is not finite at step {step}", str(self.s.run_dir),
                                         f"{kept}; lower train.lr_init or check the dataset")
                    self.opt.step()
                    self.opt.zero_grad(set_to_none=True)
                    done = step + 1
                    self.log.advance(done)
                    if done % t.log_every == 0 or done == t.steps:
                        window = self._log(done, stats, norms, window, rays_step)
                    if self.dist.main and t.preview_every and done % t.preview_every == 0:
                        self._preview(done)
                    late = deadline is not None and time.perf_counter() > deadline
                    if self.dist.enabled and deadline is not None:  # every rank stops at the same step
                        late_t = torch.tensor(float(late), device=self.dev)
                        torch.distributed.all_reduce(late_t, op=torch.distributed.ReduceOp.MAX)
                        late = bool(late_t.item())
                    stopping = bool(interrupted) or done == stop_at or late
                    if done % t.checkpoint_every == 0 or done == t.steps or stopping:
                        self._save(done)
                    if stopping:
                        if interrupted:
                            self.log.message(f"interrupted: checkpoint of step {done} written; "
                                             f"continue with --resume")
                            return INTERRUPTED
                        return 0
            finally:
                self.log.close()
                self.loader.close()
        return 0

    def _log(self, done: int, stats, norms, window, rays_step):
        s = LoggedStats.of(stats, len(self.loader.skipped))
        spread = 0.0
        if self.dist.enabled:  # ranks must hold the same parameters (DDP): the spread of their sums
            with torch.no_grad():
                total = torch.stack([p.detach().double().sum() for p in self.model.parameters()]).sum().reshape(1)
            lo, hi = total.clone(), total.clone()
            torch.distributed.all_reduce(lo, op=torch.distributed.ReduceOp.MIN)
            torch.distributed.all_reduce(hi, op=torch.distributed.ReduceOp.MAX)
            spread = float(hi - lo)
            summed = s.to_tensor()
            torch.distributed.all_reduce(summed)
            s = LoggedStats.from_tensor(summed).mean_over_ranks(self.dist.world)
        vals = s.values()
        mse = vals["sq_err"] / max(vals["valid_rays"], 1)
        fg_n = vals["fg_rays"]
        acc_fg = vals["fg_acc"] / fg_n if fg_n > 0 else float("nan")
        now = time.perf_counter()
        rate = (done - window[1]) * rays_step / max(now - window[0], 1e-9)
        t = self.cfg.train
        stage = "bg" if done - 1 < t.background_steps else "nobg"
        self.losses = {"step": done, "loss": vals["loss"], "l1": vals["l1"], "proposal": vals["proposal"],
                       "psnr": -10 * math.log10(max(mse, 1e-12)), "acc_fg": acc_fg}
        metrics = {**self.losses, "lr": self.opt.param_groups[0]["lr"], "rays_per_s": rate,
                   "samples_per_s": rate * sum(self.cfg.sampling.samples_per_level), "stage": stage,
                   "skipped_shards": int(vals["skipped_shards"]), "epoch": self.loader.epoch, "param_spread": spread,
                   **{f"grad_norm_{k}": float(v) for k, v in norms.items()}}
        metrics.pop("step")
        self.log.log(done, metrics)
        if stage == "nobg" and fg_n > 0:
            self.collapse_count = self.collapse_count + 1 if acc_fg < t.collapse_acc else 0
            if self.collapse_count >= t.collapse_patience:
                kept = f"step {self.last_saved}" if self.last_saved is not None else "none"
                raise SynthError(f"the model collapsed: mean opacity over foreground pixels stayed below "
                                 f"{t.collapse_acc} for {t.collapse_patience} logged steps (step {done})",
                                 str(self.s.run_dir), f"last checkpoint kept: {kept}; start a new run with a longer "
                                                      "background stage (train.background_steps) or a lower lr_init")
        return time.perf_counter(), done

    def _warn(self, line: str) -> None:
        """One warning line (a skipped shard): in the run's log on rank 0, on stderr elsewhere."""
        text = f"synth: warning: {line}"
        if self.dist.main and getattr(self, "log", None) is not None:
            self.log.message(text)
        else:
            print(text, file=sys.stderr, flush=True)

    def _save(self, done: int) -> None:
        """Every rank: its loader state to rank 0; rank 0 writes the checkpoint."""
        states = [self.loader.state_dict()]
        if self.dist.enabled:
            states = [None] * self.dist.world
            torch.distributed.all_gather_object(states, self.loader.state_dict())
        if not self.dist.main:
            self.last_saved = done
            return
        t, tb = self.cfg.train, self.loader.table
        ckpt.save(self.s.run_dir, done, self.model, self.opt, self.cfg, tb.layout, tb.info,
                  losses=self.losses, trainer_state={"collapse_count": self.collapse_count, "loader": states},
                  dataset=str(self.s.dataset), keep=t.keep_checkpoints, head_model=tb.head_model)
        self.last_saved = done

    def _preview(self, done: int) -> None:
        """Prediction | ground truth of the first training view of up to 3 identities."""
        from PIL import Image

        tb, t = self.loader.table, self.cfg.train
        H, W = tb.size
        self.model.eval()
        try:
            for m in self.loader.slots[:3].tolist():
                d = self.loader.held[m]
                n = int(d.train_frames[0])
                size = t.preview_size
                K = scaled_camera(d.K[n], W, H, size)
                img = render_image(self.model, K, d.c2w[n], size, size, d.codes[n], m, tb.info.centre[m],
                                   float(tb.info.radius[m]), chunk=t.render_chunk, device=self.dev, bf16=self.bf16)
                gt = Image.fromarray(srgb8(d.rgba[n, ..., :3].astype(np.float32))).resize((size, size))
                self.log.image(f"preview/identity_{int(tb.info.identity_index[m])}",
                               np.concatenate([srgb8(img["rgb"]), np.asarray(gt)], axis=1), done)
        finally:
            self.model.train()
