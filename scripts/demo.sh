#!/usr/bin/env bash
# The README's main job on the embedded default model: render a small dataset at the
# `preview` preset (2 identities x 2 expressions x 6 views, 256x256, denoised), check it,
# and write a contact sheet. Rerunning resumes (committed shards are skipped).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-demo_out}
SYNTH=.venv/bin/synth
rc=0
$SYNTH render --identities 2 --expressions 2 --views 6 --preset preview --out "$OUT/dataset" || rc=$?
if [ "$rc" -eq 2 ] && [ -f "$OUT/dataset/dataset.json" ]; then
  # synth's own line says what was refused; the demo's way out is a new DEMO_OUT, not --out
  echo "demo: $OUT/dataset cannot be resumed by this version (the line above says why; an older model or plan); remove $OUT, or run: make demo DEMO_OUT=another_dir" >&2
fi
[ "$rc" -eq 0 ] || exit "$rc"
$SYNTH validate "$OUT/dataset"
for s in shard_000000 shard_000001; do
  $SYNTH preview "$OUT/dataset" --shard "$s" -o "$OUT/preview_$s.png"
done
echo "demo: dataset in $OUT/dataset, contact sheets $OUT/preview_shard_00000{0,1}.png"
