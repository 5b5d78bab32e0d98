# Two commands for a fresh clone:  `make setup` then `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup install demo test lint

setup: install demo

install:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c constraints.txt -e '.[dev,cluster]'

demo:
	$(BIN)/vlr demo --object apple --seed 0

test:
	$(BIN)/python -m pytest -q

lint:
	$(BIN)/ruff check .
