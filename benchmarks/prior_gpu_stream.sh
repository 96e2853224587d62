#!/usr/bin/env bash
# Training rays/s on one GPU fed by the streaming loader against the in-memory one (issue 38's GPU
# check; about 3 minutes on one H200). Writes a synthetic tar dataset (benchmarks/prior_scale.py
# write: IDS identities x 13 expressions x 30 views at 32^2), then trains the paper preset for STEPS
# steps of 8 identities x 8 views x PIX pixels, once with every identity decoded
# (data.buffer_identities=0) and once streaming with a buffer of 2 identities swapped after one
# pass over their frames (views_per_load=1), and prints the steady-state rays/s of each (the
# median of the log windows after the first). Needs torch, numpy and synth's core requirements.
#
#   bash benchmarks/prior_gpu_stream.sh          # on the GPU machine (OUT defaults to /tmp/prior_gpu)
#   bash benchmarks/prior_gpu_stream.sh --dry    # CPU smoke test: small preset, 4 steps, 16 pixels
set -uo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] && [ -z "${PYTHON:-}" ] && PY=.venv/bin/python
OUT=${OUT:-/tmp/prior_gpu}
WORK=${WORK:-/tmp/prior_gpu_stream}
IDS=${IDS:-8} STEPS=${STEPS:-60} PIX=${PIX:-256} DEVICE=cuda PRESET=paper LOG=10
if [ "${1:-}" = "--dry" ]; then IDS=2 STEPS=4 PIX=16 DEVICE=cpu PRESET=small LOG=2; fi
mkdir -p "$OUT" "$WORK"
[ -f "$WORK/ds$IDS/dataset.json" ] || timeout 90 "$PY" benchmarks/prior_scale.py write --identities "$IDS" --out "$WORK/ds$IDS" \
    || { echo "writing the dataset failed (exit $?)"; exit 1; }
failed=0
for buf in 0 2; do
    rm -rf "$WORK/run$buf" "$OUT/stream_buf$buf.jsonl"  # no figures of an earlier run stand in for this one
    timeout 90 "$PY" -m prior.cli train "$WORK/ds$IDS" --out "$WORK/run$buf" --preset "$PRESET" --device "$DEVICE" \
        --steps "$STEPS" --set data.buffer_identities=$buf --set data.views_per_load=1 \
        --set train.identities_per_batch=8 --set train.views_per_identity=8 --set train.pixels_per_view="$PIX" \
        --set train.log_every=$LOG --set train.checkpoint_every=100000 --set train.preview_every=0 \
        || { echo "training with buffer $buf failed or timed out (exit $?)"; failed=1; }
    cp "$WORK/run$buf/metrics.jsonl" "$OUT/stream_buf$buf.jsonl" 2>/dev/null || true
done
"$PY" - "$OUT" "$IDS" "$PIX" <<'EOF'
import json, statistics, sys
from pathlib import Path
out, ids, pix = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
print(f"\n| loader ({ids} identities) | rays/step | steady rays/s (median of windows after the first) | windows |")
print("|---|---|---|---|")
rows = {}
for buf, name in (("0", "in memory (buffer 0 = all)"), ("2", "streaming, buffer 2")):
    f = out / f"stream_buf{buf}.jsonl"
    recs = [json.loads(l) for l in f.read_text().splitlines()] if f.exists() else []
    rates = [r["rays_per_s"] for r in recs[1:]]
    med = statistics.median(rates) if rates else float("nan")
    rows[buf] = med
    print(f"| {name} | {64 * pix:,} | {med:,.0f} | {len(rates)} |")
if rows.get("0") and rows.get("2"):
    print(f"\nstreaming / in memory: {rows['2'] / rows['0']:.3f}")
json.dump(rows, open(out / "prior_gpu_stream.json", "w"))
EOF
exit $failed
