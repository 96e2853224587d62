"""Compare two rendered datasets frame by frame: frame JSON (timing and host fields ignored)
and EXR pixels (every channel, bit for bit).

    .venv/bin/python scripts/compare_datasets.py A B [--ignore render.device ...]

Prints one line per differing frame and a summary; exit 0 when identical, 1 otherwise.
Used to show that a refactor leaves the data unchanged.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path

import numpy as np

#: Fields that legitimately differ between two runs of the same plan.
DEFAULT_IGNORE = ("render_seconds", "timing", "host", "hostname", "pid", "created", "software")


def _frames(root: Path) -> dict[str, Path]:
    return {p.stem: p for p in sorted((root / "shards").glob("*/*.json")) if p.name != "manifest.json"}


def _strip(obj, ignore: set[str], prefix: str = ""):
    if isinstance(obj, dict):
        return {k: _strip(v, ignore, f"{prefix}{k}.") for k, v in obj.items()
                if k not in ignore and f"{prefix}{k}" not in ignore}
    if isinstance(obj, list):
        return [_strip(v, ignore, prefix) for v in obj]
    return obj


def _diff_json(a, b, path: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{path}{k}: only in {'B' if k not in a else 'A'}")
            else:
                out += _diff_json(a[k], b[k], f"{path}{k}.")
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        out = []
        for i, (x, y) in enumerate(zip(a, b)):
            out += _diff_json(x, y, f"{path}{i}.")
        return out
    return [] if a == b else [f"{path.rstrip('.')}: {str(a)[:60]} != {str(b)[:60]}"]


def _channels(path: Path) -> dict[str, np.ndarray]:
    import OpenEXR

    f = OpenEXR.File(io.BytesIO(path.read_bytes()), separate_channels=True)
    return {k: np.asarray(c.pixels) for k, c in f.channels().items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--ignore", nargs="*", default=[], help="extra JSON keys or dotted paths to ignore")
    args = ap.parse_args(argv)
    ignore = set(DEFAULT_IGNORE) | set(args.ignore)
    fa, fb = _frames(args.a), _frames(args.b)
    bad = 0
    for key in sorted(set(fa) | set(fb)):
        if key not in fa or key not in fb:
            print(f"{key}: only in {'B' if key not in fa else 'A'}")
            bad += 1
            continue
        ja = _strip(json.loads(fa[key].read_bytes()), ignore)
        jb = _strip(json.loads(fb[key].read_bytes()), ignore)
        problems = _diff_json(ja, jb)
        ca, cb = _channels(fa[key].with_suffix(".exr")), _channels(fb[key].with_suffix(".exr"))
        if sorted(ca) != sorted(cb):
            problems.append(f"EXR channels {sorted(ca)} != {sorted(cb)}")
        else:
            for ch in sorted(ca):
                if ca[ch].dtype != cb[ch].dtype or ca[ch].tobytes() != cb[ch].tobytes():
                    problems.append(f"EXR channel {ch} differs")
        if problems:
            bad += 1
            print(f"{key}: " + "; ".join(problems[:5]) + (f" (+{len(problems) - 5} more)" if len(problems) > 5 else ""))
    n = len(set(fa) | set(fb))
    print(f"{n - bad}/{n} frames identical (JSON ignoring {sorted(ignore)}; EXR pixels bit for bit)")
    return 0 if bad == 0 and n > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
