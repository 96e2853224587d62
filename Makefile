# The two commands a newcomer needs (each does its own set-up on a fresh machine):
#   make demo   - runs the main job on the embedded default model
#   make test   - runs the test suite
.PHONY: setup demo test test-fast bench
PY := .venv/bin/python
DEMO_OUT ?= demo_out

setup:
	@bash scripts/setup.sh

demo: setup
	@bash scripts/demo.sh $(DEMO_OUT)

test: setup
	@$(PY) -m pytest -n 2 -q

test-fast: setup
	@$(PY) -m pytest -q -m "not slow and not blender"

bench: setup
	@$(PY) benchmarks/model_eval.py
