"""The conditional Mip-NeRF-360-style face field of Cafca (Sec. 3.2; supplementary "Prior
Model Details").

Every MLP layer sees its input concatenated with the per-ray conditioning
``cond = codes || w`` (``codes`` = beta || psi from the dataset, ``w`` the learned latent).
A layer on a concatenation is a sum of one linear map per part (:class:`MultiLinear`), so
the per-ray parts (conditioning, view direction) are multiplied once per ray and
broadcast over the samples: the same function and parameter count as a concatenation,
fewer FLOPs.

- Proposal MLP (``proposal_depth`` x ``proposal_width``): density only; evaluated at each
  proposal level (one MLP shared by the levels unless ``distinct_proposal``).
- NeRF MLP (``nerf_depth`` x ``nerf_width``, encoded position re-injected at
  ``skip_layer``): density; a normals head (trunk -> 3); colour from a linear bottleneck
  and one view-conditioned ReLU layer.

Predicted normals: the head predicts the density-gradient direction, i.e. the *negative*
normal as in the paper; ``normals_pred = -normalize(head)`` so predicted and analytic
normals (``-grad density``) both point outwards and agree on a well-trained surface.

Precision: the MLPs run under whatever autocast the caller sets (bf16 on CUDA); their
outputs are cast to float32, and encoding, resampling and compositing are float32 ops.
Initialisation: He-uniform weights (bound sqrt(6 / fan_in)), zero biases, from a
generator seeded by ``ModelConfig.init_seed``.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence

import torch
from torch import nn
from torch.nn import functional as F

from . import encoding, render
from .codebook import Codebook
from .config import ModelConfig, SamplingConfig
from .rays import RayBundle


def _he_uniform_(weight: torch.Tensor, fan_in: int, generator: torch.Generator) -> None:
    bound = math.sqrt(6.0 / fan_in)
    with torch.no_grad():
        weight.uniform_(-bound, bound, generator=generator)


def _dense(in_dim: int, out_dim: int, generator: torch.Generator) -> nn.Linear:
    layer = nn.Linear(in_dim, out_dim)
    _he_uniform_(layer.weight, in_dim, generator)
    nn.init.zeros_(layer.bias)
    return layer


class MultiLinear(nn.Module):
    """A linear layer on the concatenation of several inputs: ``b + sum_k W_k x_k``.
    Inputs may be (N, S, d_k) or per-ray (N, 1, d_k); they broadcast. The He bound uses
    the total fan-in, as for the concatenated layer. ``blocks[k]`` maps input k."""

    def __init__(self, in_dims: Sequence[int], out_dim: int, generator: torch.Generator):
        super().__init__()
        fan_in = sum(in_dims)
        self.blocks = nn.ModuleList(nn.Linear(d, out_dim, bias=(k == 0)) for k, d in enumerate(in_dims))
        for block in self.blocks:
            _he_uniform_(block.weight, fan_in, generator)
        nn.init.zeros_(self.blocks[0].bias)

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        y = self.blocks[0](inputs[0])
        for block, x in zip(self.blocks[1:], inputs[1:]):
            y = y + block(x)
        return y


class Trunk(nn.Module):
    """ReLU MLP of ``depth`` conditioned layers; the input is re-injected at ``skip_layer``
    (0 = never)."""

    def __init__(self, in_dim: int, cond_dim: int, width: int, depth: int, skip_layer: int,
                 generator: torch.Generator):
        super().__init__()
        self.skip_layer = skip_layer
        layers = []
        for i in range(depth):
            dims = [in_dim if i == 0 else width]
            if i == skip_layer and i > 0:
                dims.append(in_dim)
            layers.append(MultiLinear([*dims, cond_dim], width, generator))
        self.layers = nn.ModuleList(layers)

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        h = x
        for i, layer in enumerate(self.layers):
            h = F.relu(layer(h, x, cond) if (i == self.skip_layer and i > 0) else layer(h, cond))
        return h


class ProposalMLP(nn.Module):
    """Raw (pre-activation) density (N, S) of a proposal level."""

    def __init__(self, cfg: ModelConfig, cond_dim: int, generator: torch.Generator):
        super().__init__()
        self.trunk = Trunk(encoding.ipe_dim(cfg.pos_levels), cond_dim, cfg.proposal_width,
                           cfg.proposal_depth, 0, generator)
        self.density = _dense(cfg.proposal_width, 1, generator)

    def forward(self, enc: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        return self.density(self.trunk(enc, cond))[..., 0]


class NerfMLP(nn.Module):
    """Raw density (N, S), raw colour (N, S, 3) and the raw normals head (N, S, 3)."""

    def __init__(self, cfg: ModelConfig, cond_dim: int, generator: torch.Generator):
        super().__init__()
        w = cfg.nerf_width
        self.trunk = Trunk(encoding.ipe_dim(cfg.pos_levels), cond_dim, w, cfg.nerf_depth,
                           cfg.skip_layer, generator)
        self.density = _dense(w, 1, generator)
        self.normals = _dense(w, 3, generator)
        self.bottleneck = _dense(w, cfg.bottleneck_width, generator)
        #: inputs: bottleneck, encoded view direction (the "view branch"), conditioning
        self.view = MultiLinear([cfg.bottleneck_width, encoding.dir_enc_dim(cfg.dir_levels), cond_dim],
                                cfg.view_width, generator)
        self.rgb = _dense(cfg.view_width, 3, generator)

    def forward(self, enc: torch.Tensor, dir_enc: torch.Tensor, cond: torch.Tensor):
        h = self.trunk(enc, cond)
        v = F.relu(self.view(self.bottleneck(h), dir_enc, cond))
        return self.density(h)[..., 0], self.rgb(v), self.normals(h)


class PriorField(nn.Module):
    """The conditional field with its proposal sampler and codebook.

    ``code_dim``: size of the per-ray ``codes`` (beta || psi) read from the dataset;
    ``num_latents``: rows of the ``w`` codebook (training identities).
    """

    def __init__(self, model_cfg: ModelConfig, sampling_cfg: SamplingConfig, code_dim: int,
                 num_latents: int):
        super().__init__()
        model_cfg.validate()
        sampling_cfg.validate()
        if code_dim < 0:
            raise ValueError(f"code_dim = {code_dim} must be >= 0")
        self.model_cfg, self.sampling_cfg = model_cfg, sampling_cfg
        self.code_dim = int(code_dim)
        self.cond_dim = self.code_dim + model_cfg.latent_dim
        gen = torch.Generator().manual_seed(int(model_cfg.init_seed))
        num_prop = len(sampling_cfg.proposal_samples) if model_cfg.distinct_proposal else 1
        self.proposal = nn.ModuleList(ProposalMLP(model_cfg, self.cond_dim, gen) for _ in range(max(num_prop, 1)))
        self.nerf = NerfMLP(model_cfg, self.cond_dim, gen)
        self.codebook = Codebook(num_latents, model_cfg.latent_dim, model_cfg.latent_init_std, gen)
        self.register_buffer("scene_center", torch.tensor(model_cfg.scene_center, dtype=torch.float32),
                             persistent=False)

    def param_groups(self) -> dict[str, list[nn.Parameter]]:
        """Parameters per MLP, for per-MLP gradient clipping."""
        return {"proposal": list(self.proposal.parameters()), "nerf": list(self.nerf.parameters()),
                "codebook": list(self.codebook.parameters())}

    def view_branch_parameters(self) -> list[nn.Parameter]:
        """The weights that process the encoded view direction (target of the view L2)."""
        return [self.nerf.view.blocks[1].weight]

    def _encode(self, means: torch.Tensor, variances: torch.Tensor) -> torch.Tensor:
        r = float(self.model_cfg.scene_radius)
        return encoding.integrated_pos_enc((means - self.scene_center) / r, variances / (r * r),
                                           self.model_cfg.pos_levels)

    def _density(self, raw: torch.Tensor) -> torch.Tensor:
        return F.softplus(raw.float() + self.model_cfg.density_bias)

    def forward(self, rays: RayBundle, *, train_frac: float | torch.Tensor = 1.0, randomized: bool = False,
                background: torch.Tensor | None = None, compute_normals: bool = False,
                generator: torch.Generator | None = None) -> dict:
        """Render the N rays of ``rays`` (:class:`prior.rays.RayBundle`); ``docs/prior-model.md``
        lists the keys of the returned dict.

        The bundle's ``latents``, if given, replace the codebook lookup of its ``latent_ids``;
        its ``radii`` None means thin rays. ``train_frac`` in [0, 1] drives the proposal
        annealing; pass it as a 0-d tensor under torch.compile (a Python float is a constant: one
        recompile per value).
        """
        n = rays.origins.shape[0]
        if randomized and generator is None:
            raise ValueError("randomized sampling needs a torch.Generator (no global RNG)")
        codes, latents = rays.codes, rays.latents
        if latents is None:
            if rays.latent_ids is None:
                raise ValueError("PriorField needs latent_ids or latents")
            latents = self.codebook(rays.latent_ids)
        if codes.shape != (n, self.code_dim) or latents.shape != (n, self.model_cfg.latent_dim):
            raise ValueError(f"codes {tuple(codes.shape)} / latents {tuple(latents.shape)} do not "
                             f"match ({n}, {self.code_dim}) / ({n}, {self.model_cfg.latent_dim})")
        cond = torch.cat([codes.float(), latents.float()], dim=-1)[:, None, :]
        origins, directions = rays.origins.float(), rays.directions.float()
        near, far = render.ray_bounds(rays.near, rays.far)
        radii = torch.zeros_like(near) if rays.radii is None else rays.radii.float()
        dir_enc = encoding.pos_enc(directions, self.model_cfg.dir_levels)[:, None, :]
        levels = self.sampling_cfg.samples_per_level
        jitter = (render.draw_jitter(n, self.sampling_cfg, generator, origins.device) if randomized
                  else [None] * len(levels))
        s, w = render.initial_intervals(n, origins.device)
        history = []
        for level in range(len(levels) - 1):
            s = render.resample(level, s, w, self.sampling_cfg, train_frac=train_frac, jitter=jitter[level])
            t = render.s_to_t(s, near, far)
            enc = self._encode(*encoding.frustum_gaussians(origins, directions, t, radii))
            raw = self.proposal[min(level, len(self.proposal) - 1)](enc, cond)
            w = render.alpha_weights(self._density(raw), t)
            history.append((s, w))
        s = render.resample(len(levels) - 1, s, w, self.sampling_cfg, train_frac=train_frac,
                            jitter=jitter[-1])
        t = render.s_to_t(s, near, far)
        out = self._nerf_level(origins, directions, t, radii, dir_enc, cond, compute_normals)
        w = render.alpha_weights(self._density(out.pop("raw_density")), t)
        history.append((s, w))
        acc = w.sum(dim=-1)
        rgb = render.composite(w, out.pop("rgb_samples"))
        if background is not None:
            rgb = rgb + (1 - acc)[:, None] * background.float()
        out.update(rgb=rgb, acc=acc, depth=render.expected_depth(w, t, acc), weights=w, t=t, s=s,
                   history=history, normals_pred=render.composite(w, out["sample_normals_pred"]))
        if compute_normals:
            out["normals_analytic"] = render.composite(w, out["sample_normals_analytic"])
        return out

    def _nerf_level(self, origins, directions, t, radii, dir_enc, cond, compute_normals: bool) -> dict:
        outer_grad = torch.is_grad_enabled()
        means, variances = encoding.frustum_gaussians(origins, directions, t, radii)
        ctx = torch.enable_grad() if compute_normals else contextlib.nullcontext()
        with ctx:
            if compute_normals:
                means = means.detach().requires_grad_(True)
            raw, rgb_raw, normals_raw = self.nerf(self._encode(means, variances), dir_enc, cond)
            raw, rgb_raw, normals_raw = raw.float(), rgb_raw.float(), normals_raw.float()
            out = {}
            if compute_normals:
                out["sample_normals_analytic"] = render.analytic_normals(raw, means, create_graph=outer_grad)
        if not outer_grad:
            raw, rgb_raw, normals_raw = raw.detach(), rgb_raw.detach(), normals_raw.detach()
            out = {k: v.detach() for k, v in out.items()}
        pad = self.model_cfg.rgb_padding
        out.update(raw_density=raw, rgb_samples=torch.sigmoid(rgb_raw) * (1 + 2 * pad) - pad,
                   sample_normals_pred=-render.normalize(normals_raw))
        return out


def num_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())
