"""The error boundary of the command line (docs/reliability.md): whatever a command raises because
of its input or its environment ends as one line on stderr,

    synth: error: <what> (<where>); <what to do>

and the documented exit code (README, "Exit codes"): :class:`synth.errors.SynthError` and its
subclasses carry their own (1 incomplete or defects, 2 usage or input, 3 worker failed, 4 disk
full); usage errors of the parser are 2; operating-system errors (``OSError``: read-only or
full file systems, permissions, missing files), undecodable text (``UnicodeError``), input
nested too deeply (``RecursionError``), a NUL byte in a path (``ValueError`` from the OS
layer) and ``MemoryError`` are translated by :func:`translate`; Ctrl-C is 130. Anything else is
a bug in synth and keeps its traceback.

:func:`run` applies it to a typer app: ``synth`` (synth.cli.main) and ``python -m prior.cli`` (for
torchrun) use it.
"""

from __future__ import annotations

import errno
import os
import sys

import typer

#: What to do about an operating-system error, by errno (the line's "what" is its strerror).
_FIXES = (
    ("write somewhere writable (another --out or -o)", errno.EROFS),
    ("check the permissions, or write somewhere else", errno.EACCES, errno.EPERM),
    ("check the path", errno.ENOENT, errno.ENOTDIR, errno.ELOOP),
    ("pass a file, not a directory", errno.EISDIR),
    ("use a shorter path", errno.ENAMETOOLONG),
    ("choose a new or empty path", errno.EEXIST, errno.ENOTEMPTY),
    ("raise the limit (ulimit -n) and rerun", errno.EMFILE),
    ("check the disk (dmesg), then rerun", errno.EIO),
)
_FIX = {code: fix for fix, *codes in _FIXES for code in codes}


def _where(e: OSError) -> str | None:
    names = [os.fsdecode(n) for n in (e.filename, e.filename2) if n is not None]
    return " -> ".join(names) or None


def _file_in_traceback(e: BaseException) -> str | None:
    """Best effort for errors that name no file (a decoding error, input nested too deeply):
    the file being read where it was raised, i.e. the innermost frame holding an open file or
    a path."""
    import io
    from pathlib import PurePath

    frames = []
    tb = e.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    for fr in reversed(frames):
        for v in fr.f_locals.values():
            if isinstance(v, io.IOBase) and isinstance(getattr(v, "name", None), str):
                return v.name
            if isinstance(v, PurePath):
                return str(v)
    return None


def _printable(text: str) -> str:
    """One line, control characters (a NUL, a newline) and undecodable bytes escaped."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def translate(e: BaseException):
    """The :class:`synth.errors.SynthError` that stands for ``e`` (an error of the input or the
    environment), or ``None`` when ``e`` is a bug."""
    from synth.errors import SynthError, disk_full, is_disk_full

    if isinstance(e, SynthError):
        return e
    if isinstance(e, OSError):
        if is_disk_full(e):
            return disk_full(_where(e) or ".", e)
        if e.strerror or e.errno:
            what = e.strerror or os.strerror(e.errno)
            what = what[:1].lower() + what[1:]
        else:
            what = str(e) or type(e).__name__
        return SynthError(what, _where(e), _FIX.get(e.errno, "check the path and the file system"))
    if isinstance(e, UnicodeError):
        reason = getattr(e, "reason", str(e))
        return SynthError(f"text is not valid UTF-8 ({reason})", _file_in_traceback(e),
                          "save the file as UTF-8 (and use UTF-8 paths in configuration files)")
    if isinstance(e, RecursionError):
        return SynthError("input nested too deeply to read", _file_in_traceback(e), "check the file")
    if isinstance(e, MemoryError):
        return SynthError("out of memory", None, "free memory or ask for less (fewer identities, views, workers)")
    if isinstance(e, ValueError) and "null" in str(e) and ("byte" in str(e) or "character" in str(e)):
        return SynthError("a path contains a NUL byte", None, "remove the NUL (\\0) from the path in the "
                          "configuration or asset files")
    return None


def _usage_error(e):
    """The parser's usage error (exit 2) as one line naming the command."""
    from synth.errors import SynthError

    ctx = getattr(e, "ctx", None)
    cmd = ctx.command_path if ctx is not None else "synth"
    return SynthError(e.format_message().replace("\n", " "), cmd, f"see `{cmd} --help`")


def run(app: typer.Typer, argv: list[str] | None = None, prog_name: str = "synth") -> int:
    """Run a typer app with this boundary: one line and the documented exit code for every
    error of the input or the environment (module docstring); returns the exit code."""
    for stream in (sys.stdout, sys.stderr):  # paths with undecodable bytes print escaped, never raise
        try:
            stream.reconfigure(errors="backslashreplace")
        except (AttributeError, ValueError):
            pass
    try:
        from typer._click.exceptions import ClickException
    except ImportError:  # older typer: plain click
        from click import ClickException
    try:
        rc = app(args=argv, prog_name=prog_name, standalone_mode=False)
    except typer.Exit as e:
        return e.exit_code
    except (typer.Abort, KeyboardInterrupt):
        print("synth: interrupted", file=sys.stderr)
        return 130
    except ClickException as e:
        if not e.format_message():  # no arguments: the help was printed
            return e.exit_code
        err = _usage_error(e)
    except Exception as e:
        err = translate(e)
        if err is None:
            raise
    else:
        return rc if isinstance(rc, int) else 0
    print(f"synth: error: {_printable(str(err))}", file=sys.stderr)
    return err.exit_code

