#!/usr/bin/env bash
# The README's main job on the embedded default model. Until `synth render` is wired to the
# plan, it builds (first run) and describes the default model and samples a few heads.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-demo_out}
SYNTH=.venv/bin/synth
$SYNTH model info
rm -rf "$OUT/heads"
$SYNTH model sample --n 6 --seed 0 --out "$OUT/heads"
echo "demo: sampled heads (OBJ + codes.json) in $OUT/heads"
