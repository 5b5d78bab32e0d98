# Two commands for a fresh clone:  `make setup` then `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup install demo test lint

setup: install demo

install:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c constraints.txt -e '.[all]'
	$(BIN)/python -m vlr.precompile   # numba's kernels compiled once, not in the first run

# The main job on the embedded defaults, on a budget of seconds: the sim identifies its grasp
# of the apple and prints the estimates beside the truth, then the commands to try next.
demo:
	$(BIN)/vlr demo --out runs/setup

test:
	$(BIN)/python -m pytest -q

lint:
	$(BIN)/ruff check .
