# Two entry points for a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP_RUN := $(VENV)/.installed-run
STAMP_DEV := $(VENV)/.installed-dev

.PHONY: demo test lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP_RUN): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(STAMP_DEV): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@ $(STAMP_RUN)

demo: $(STAMP_RUN)
	$(BIN)/stablemarks demo --out results/demo

test: $(STAMP_DEV)
	$(BIN)/python -m pytest -q --numprocesses=auto --maxprocesses=4

lint: $(STAMP_DEV)
	$(BIN)/ruff check .

bench: $(STAMP_RUN)
	$(BIN)/stablemarks bench

clean:
	rm -rf $(VENV) results build *.egg-info src/*.egg-info
