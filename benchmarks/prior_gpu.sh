#!/usr/bin/env bash
# The prior's GPU check, prepared to run in under 8 minutes on one H200 (needs only torch and
# numpy: Python 3.11/3.12, torch 2.11-2.13). Paper-size training rays/s in bf16, eager and
# torch.compile'd; FLOPs and the fraction of the bf16 peak; peak memory; CUDA vs CPU forward
# agreement; then few-shot fitting: fine-tuning steps/s at 4,096 rays per step and the projected
# 50,000 steps, and the time to render one 1024x1024 view at fewer samples against the error
# (benchmarks/prior_gpu_fit.py). Figures go to stdout, $OUT/prior_gpu.json and
# $OUT/prior_gpu_fit.json (OUT defaults to /tmp/prior_gpu).
#
#   bash benchmarks/prior_gpu.sh            # on the GPU machine
#   bash benchmarks/prior_gpu.sh --dry      # CPU smoke test of the same script
set -euo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] && [ -z "${PYTHON:-}" ] && PY=.venv/bin/python
OUT=${OUT:-/tmp/prior_gpu}
mkdir -p "$OUT"
"$PY" -c "import sys, torch, numpy; print('python', sys.version.split()[0], 'torch', torch.__version__, 'numpy', numpy.__version__, 'cuda', torch.cuda.is_available())"
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,clocks.max.sm --format=csv || true
# up to 16,384 rays per step (1/8 of the paper's 131,072-ray batch; halved until a step fits in
# memory); 20 timed steps after 5 warm-up, eager then compiled
# (each part has its own time limit, and the second runs even if the first fails: under 8 minutes in all)
timeout 270 "$PY" benchmarks/prior_gpu.py --rays 16384 --iters 20 --warmup 5 --out "$OUT/prior_gpu.json" "$@" \
    || echo "prior_gpu.py failed or timed out (exit $?)"
# fine-tuning (paper preset, 4,096 rays, float32 and bf16: 5 warm-up + 20 timed steps each) and
# 1024x1024 renders at 128/128/128, 64/64/64, 32/32/32 and 128/64/32 samples per level
timeout 190 "$PY" benchmarks/prior_gpu_fit.py --iters 20 --warmup 5 --size 1024 --out "$OUT/prior_gpu_fit.json" "$@"
