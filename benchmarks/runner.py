"""How a benchmark script ends: its ``main()``'s exit code, and bad input as one line with exit 2."""

from __future__ import annotations

import sys
from typing import Callable, NoReturn


def run_cli(main: Callable[[], int]) -> NoReturn:
    """``sys.exit(main())``; a :class:`synth.errors.SynthError` (bad input) prints one line to stderr
    and exits 2, with no traceback."""
    from synth.errors import SynthError

    try:
        sys.exit(main())
    except SynthError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
