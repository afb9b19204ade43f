# Marionette: the two set-up commands are `make run` and `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
MOCAP_DIR ?= ../shared/mocap
DATASET ?= data/poses.npz
CONFIG ?= trainer/configs/default.toml
# make run HOST=… PORT=… on the command line; not read from the environment (tcsh exports
# HOST as the machine's name, some platforms PORT)
HOST := 127.0.0.1
PORT := 8000

.PHONY: help venv run test test-fast lint format lock dataset train export bench soak clean

help:
	@echo "make run    - create the venv, install, serve the bundled models on http://$(HOST):$(PORT) (make run PORT=8080)"
	@echo "make test   - create/update the venv, lint, type-check and run the whole test suite"
	@echo "make lint   - ruff + mypy"
	@echo "make dataset / train / bench - build the pose dataset, train the models, run benchmarks"

# The venv is (re)installed whenever pyproject.toml or constraints.txt changes, at the
# versions constraints.txt locks. torch is pinned to the CPU wheel available on this
# machine (pip finds it; uv does not).
$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c constraints.txt -e '.[service,train,dev]'
	touch $(STAMP)

# constraints.txt anew: a scratch venv of pyproject.toml's ranges alone (the project itself
# not built), frozen with its build tools (setuptools, which torch needs at run time; pip
# itself left out), the comment header kept, torch's local +cpu label dropped (so the pin
# reads as pyproject's).
# Then `make test`: the suite is what says the new versions are good.
lock:
	tmp="$$(mktemp -d)"; trap 'rm -rf "$$tmp"' EXIT; \
	$(PYTHON) -m venv "$$tmp/venv" && \
	"$$tmp/venv/bin/pip" install --quiet --upgrade pip && \
	"$$tmp/venv/bin/python" -c "import tomllib; p = tomllib.load(open('pyproject.toml', 'rb'))\
	['project']; e = p['optional-dependencies']; print('\n'.join(p['dependencies'] + e['service']\
	+ e['train'] + e['dev']))" > "$$tmp/requirements.txt" && \
	"$$tmp/venv/bin/pip" install --quiet -r "$$tmp/requirements.txt" && \
	"$$tmp/venv/bin/pip" freeze --all > "$$tmp/frozen.txt" && \
	{ grep '^#' constraints.txt; grep -viE '^pip==' "$$tmp/frozen.txt" \
	  | sed -E 's/\+cpu$$//'; } > "$$tmp/constraints.txt" && \
	mv "$$tmp/constraints.txt" constraints.txt

venv: $(STAMP)

run: $(STAMP)
	$(BIN)/pose-service --host $(HOST) --port $(PORT)

lint: $(STAMP)
	$(BIN)/ruff check core service trainer tests bench scripts
	$(BIN)/ruff format --check core service trainer tests bench scripts
	$(BIN)/mypy

format: $(STAMP)
	$(BIN)/ruff format core service trainer tests bench scripts
	$(BIN)/ruff check --fix core service trainer tests bench scripts

# Bytecode is written for the tests even where the environment says not to
# (PYTHONDONTWRITEBYTECODE): without it collection and each of the ~80 Python
# subprocesses the suite starts compile every module anew (~25 s of CPU a run).
# __pycache__ is ignored by git and by the image build (.dockerignore).
PYTEST := env -u PYTHONDONTWRITEBYTECODE $(BIN)/pytest
# Two processes (pytest-xdist), one per core, each given whole test files (--dist loadfile):
# a module's fixtures are set up once (a trained model, a server, the container image) and
# its tests run in file order (test_contract's volume check reads what its cases sent).
# Not loadgroup: with pytest 9.2 it groups nothing (pytest-xdist issue #1386).
# `make test XDIST=` runs in one process.
XDIST := -n 2 --dist loadfile

test: $(STAMP) lint
	$(PYTEST) $(XDIST)

test-fast: $(STAMP)
	$(PYTEST) $(XDIST) -m "not slow"

dataset: $(STAMP)
	$(BIN)/pose-trainer dataset --mocap $(MOCAP_DIR) --out $(DATASET)

train: $(STAMP)
	$(BIN)/pose-trainer train --config $(CONFIG)

# Accuracy and speed side by side: writes reports/report.md and its plots (<= 15 min).
bench: $(STAMP)
	test -f $(DATASET) || $(BIN)/pose-trainer dataset --mocap $(MOCAP_DIR) --out $(DATASET)
	$(BIN)/python -m bench --models models --dataset $(DATASET) --out reports
	$(BIN)/python -m bench.readme --report reports/report.md --readme README.md

# A bounded soak of the real service at saturation: 60 s, 32 connections; prints
# requests, errors and RSS (start, peak, end); fails on any error. Not part of `make test`.
soak: $(STAMP)
	$(BIN)/python -m tests.service.soak --seconds 60 --concurrency 32

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
