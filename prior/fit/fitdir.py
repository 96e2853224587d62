"""A fit directory (the ``--out`` of ``synth prior fit``): what ``render`` and ``eval`` need.

```
FIT/fit.json            format, prior run (checkpoint, step, head model), head model used, fit config,
                        inputs (path, size, synth frame indices), cameras (K, world_to_camera,
                        camera_to_world per input), conditioning codes per input (beta || psi) and
                        their layout, ray bounds (sphere), the prior's image size, pretrained or not
FIT/weights.safetensors the fine-tuned field (``model.*``) and the latent ``latent`` (w); metadata:
                        format tag, the prior's run config (JSON), the code layout (JSON)
FIT/report.json         landmark fit (energy, residuals, convergence), inversion and fine-tuning
                        losses, times
FIT/report.md           the same for people
```

The whole directory is written under a temporary name and renamed into place
(:func:`synth.io.atomic_dir`): a fit that fails or is interrupted leaves nothing.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from prior.data.codes import CodeLayout
from prior.train import config as run_config
from synth.errors import SynthError

FORMAT = "synth-prior-fit/1"
FIT_FILE, WEIGHTS_FILE, REPORT_JSON, REPORT_MD = "fit.json", "weights.safetensors", "report.json", "report.md"


@dataclass
class FittedFace:
    path: Path
    info: dict  # fit.json
    model: torch.nn.Module  # PriorField, eval mode
    latent: torch.Tensor  # (latent_dim,)
    layout: CodeLayout

    @property
    def codes(self) -> np.ndarray:
        """(V, C) conditioning code of each input image."""
        return np.asarray(self.info["codes"], np.float32)

    @property
    def render_chunk(self) -> int:
        """Rays per chunk when rendering whole images (the fit config's ``fit.render_chunk``)."""
        return int(self.info["config"]["fit"]["render_chunk"])

    @property
    def K(self) -> np.ndarray:
        return np.asarray([c["K"] for c in self.info["cameras"]], np.float64)

    @property
    def world_to_camera(self) -> np.ndarray:
        return np.asarray([c["world_to_camera"] for c in self.info["cameras"]], np.float64)

    @property
    def camera_to_world(self) -> np.ndarray:
        return np.asarray([c["camera_to_world"] for c in self.info["cameras"]], np.float64)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the input images."""
        c = self.info["cameras"][0]
        return int(c["width"]), int(c["height"])

    @property
    def centre(self) -> np.ndarray:
        return np.asarray(self.info["bounds"]["centre"], np.float64)

    @property
    def radius(self) -> float:
        return float(self.info["bounds"]["radius"])


def weights_bytes(model: torch.nn.Module, latent: torch.Tensor, run_cfg, layout: CodeLayout) -> bytes:
    from safetensors.torch import save

    tensors = {f"model.{k}": v.detach().to("cpu").contiguous() for k, v in model.state_dict().items()}
    tensors["latent"] = latent.detach().to("cpu").float().contiguous()
    meta = {"format": FORMAT, "config": json.dumps(run_cfg.to_dict()), "layout": json.dumps(layout.to_dict())}
    return save(tensors, metadata=meta)


def _refuse(path: Path, what: str):
    raise SynthError(what, str(path), "pass the --out directory of `synth prior fit` (fit again if it was damaged)")


def load_fit(path, device="cpu") -> FittedFace:
    """Read a fit directory; missing, truncated or foreign files are refused (one line)."""
    from safetensors import SafetensorError
    from safetensors.torch import load as st_load

    from prior.train.checkpoint import _metadata
    from prior.train.setup import build_model

    path = Path(path)
    if not (path / FIT_FILE).is_file():
        _refuse(path, "not a fit directory (no fit.json)")
    try:
        info = json.loads((path / FIT_FILE).read_text(encoding="utf-8"))
        data = (path / WEIGHTS_FILE).read_bytes()
        tensors, meta = st_load(data), _metadata(data)
    except FileNotFoundError:
        _refuse(path / WEIGHTS_FILE, "fit weights missing")
    except (SafetensorError, ValueError, RuntimeError, UnicodeDecodeError) as e:
        _refuse(path, f"fit files unreadable (truncated or foreign: {str(e).splitlines()[0][:80]})")
    if info.get("format") != FORMAT or meta.get("format") != FORMAT:
        _refuse(path, f"not a prior fit (format {info.get('format')!r}, expected {FORMAT!r})")
    try:
        cfg = run_config.from_dict(json.loads(meta["config"]), str(path / WEIGHTS_FILE))
        layout = CodeLayout.from_dict(json.loads(meta["layout"]))
        latent = tensors.pop("latent")
        state = {k[len("model."):]: v for k, v in tensors.items() if k.startswith("model.")}
        model = build_model(cfg, layout.size, int(state["codebook.embedding.weight"].shape[0]), device)
        model.load_state_dict(state)
    except (KeyError, ValueError, TypeError, RuntimeError) as e:
        _refuse(path, f"fit weights lack or garble {str(e).splitlines()[0][:80]}")
    model.eval()
    return FittedFace(path, info, model, latent.to(device), layout)
