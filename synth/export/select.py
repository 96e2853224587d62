"""Which frames an export covers, and where it may write."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from synth.dataset.layout import parse_frame_key_env
from synth.dataset.reader import FrameRef, list_frames
from synth.errors import SynthError


def select_frames(source, *, shards: list[str] | None = None, identity: int | None = None,
                  expression: int | None = None, environment: int | None = None) -> list[FrameRef]:
    """The committed frames of a dataset (or the frames of one shard directory), optionally only
    those of some shards, one identity, one expression and/or one environment index, sorted by
    (shard, key)."""
    refs = list_frames(source, shards=shards)
    out = []
    for r in refs:
        i, e, k, _ = parse_frame_key_env(r.key)
        if (identity is None or i == identity) and (expression is None or e == expression) \
                and (environment is None or k == environment):
            out.append(r)
    if not out:
        what = ", ".join(f"{n} {v}" for n, v in (("identity", identity), ("expression", expression),
                                                  ("environment", environment)) if v is not None)
        raise SynthError(f"no committed frames{' of ' + what if what else ''}", str(source),
                         "check the indices (synth report DIR lists what is committed), or render first")
    return out


def check_new_output(out: Path, what: str) -> None:
    """An export writes into a new (or empty) path only: it never mixes with older files."""
    out = Path(out)
    if out.is_dir() and any(out.iterdir()):
        raise SynthError(f"{what} output directory is not empty", str(out), "pass a new or empty --out")
    if out.exists() and not out.is_dir():
        raise SynthError(f"{what} output exists and is not a directory", str(out), "pass a new --out directory")
    if not out.parent.is_dir():
        raise SynthError(f"the parent of the {what} output does not exist", str(out.parent), "create it first")


def png_bytes(array: np.ndarray) -> bytes:
    """PNG bytes; the mode follows the array (uint8 (H, W, 4): RGBA, uint8 (H, W): L, uint16: I;16)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(array)).save(buf, format="PNG")
    return buf.getvalue()
