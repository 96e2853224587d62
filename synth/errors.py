"""User-facing errors: one clear line (what, where, what to do), exit code 2."""

from __future__ import annotations


class SynthError(Exception):
    """An error caused by the user's input or environment.

    The CLI prints ``str(err)`` as a single line and exits with code 2.
    """

    exit_code = 2

    def __init__(self, what: str, where: str | None = None, fix: str | None = None):
        self.what = what
        self.where = where
        self.fix = fix
        parts = [what]
        if where:
            parts.append(f"({where})")
        msg = " ".join(parts)
        if fix:
            msg += f"; {fix}"
        super().__init__(msg)


class ModelFormatError(SynthError):
    """A head-model file is malformed or inconsistent."""


class CodeError(SynthError, ValueError):
    """An identity/expression/pose array has the wrong shape or non-finite values."""
