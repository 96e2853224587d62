"""Where synth keeps caches. ``SYNTH_CACHE_DIR`` overrides the per-user cache directory."""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """The cache folder (created if missing): ``$SYNTH_CACHE_DIR``, else the platform's user cache."""
    env = os.environ.get("SYNTH_CACHE_DIR")
    if env:
        p = Path(env)
    else:
        from platformdirs import user_cache_dir

        p = Path(user_cache_dir("synth", appauthor=False))
    p.mkdir(parents=True, exist_ok=True)
    return p
