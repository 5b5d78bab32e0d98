# Two commands for a fresh clone:  `make setup` then `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup install identify test lint

setup: install identify

install:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c constraints.txt -e '.[dev,cluster]'

# The main job on the embedded defaults: the sim identifies its grasp of the apple.
identify:
	$(BIN)/vlr identify --object apple --particles 6000 --max-iterations 10 --quiet \
		--out runs/setup

test:
	$(BIN)/python -m pytest -q

lint:
	$(BIN)/ruff check .
