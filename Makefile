# fiberpipe: reproducible set-up, demo, tests, verification and benchmarks.
# `make demo` and `make test` work on a fresh clone: both depend on `setup`.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
FP     := $(VENV)/bin/fiberpipe
export NUMBA_NUM_THREADS ?= 1
export MPLBACKEND ?= Agg

.PHONY: setup demo test test-all verify bench bench-imaging bench-solver clean help

help:
	@echo "make setup    create .venv and install fiberpipe with its test extras"
	@echo "make demo     run configs/quickstart.yaml on the bundled sample (runs/quickstart)"
	@echo "make test     run the default test suite"
	@echo "make verify   print the verification table (SPEC section 8)"
	@echo "make bench    benchmarks (docs/benchmarks.md)"

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $@

setup: $(VENV)/.installed

demo: setup
	$(FP) run configs/quickstart.yaml --out runs/quickstart

test: setup
	$(PY) -m pytest -q

test-all: setup
	$(PY) -m pytest -q -m ""

verify: setup
	$(PY) -m fiberpipe.verification

bench-imaging: setup
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(PY) benchmarks/bench_imaging.py

bench-solver: setup
	$(PY) benchmarks/bench_solver.py

bench: bench-solver bench-imaging

clean:
	rm -rf runs .pytest_cache
