# fiberpipe: reproducible set-up, demo, tests, verification and benchmarks.
# `make demo` and `make test` work on a fresh clone: both depend on `setup`.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
FP     := $(VENV)/bin/fiberpipe
export NUMBA_NUM_THREADS ?= 1
export MPLBACKEND ?= Agg

.PHONY: setup demo test test-all verify bench bench-imaging bench-solver reproduce studies clean help

help:
	@echo "make setup    create .venv and install fiberpipe with its test extras"
	@echo "make demo     run configs/quickstart.yaml on the bundled sample (runs/quickstart)"
	@echo "make test     run the default test suite"
	@echo "make verify   print the verification table (SPEC section 8)"
	@echo "make bench    benchmarks (docs/benchmarks.md)"
	@echo "make fast-settings  paper-40 fast settings vs the study settings (≈ 15 min)"
	@echo "make contact-ensemble  the study's contact models over 8 paper-40 specimens (≈ 25 min on 2 cores)"
	@echo "make law-branch  the contact law's own effect: every law from the same state at U = 0.95 mm (≈ 40 min on 2 busy cores)"

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

.PHONY: bench-contact bench-pyelastica fast-settings contact-ensemble law-branch
bench-contact: setup
	$(PY) benchmarks/bench_contact.py

bench-pyelastica: setup
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(PY) benchmarks/bench_pyelastica.py

# every figure of SPEC section 10 in one run (solver, contact, PyElastica, paper-40, imaging)
# into docs/benchmarks.md; ~10 min on an idle machine
bench: setup
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(FP) bench

# The study's cases in batch (make -j2 reproduce runs them in parallel), then one comparison.
REPRO_CONFIGS := paper-40 paper-40/parallel paper-40/oblique-6 paper-40/alpha-0 paper-40/alpha-1e4 \
                 paper-40/compaction paper-40/compaction-parallel paper-40/compaction-oblique-6 \
                 paper-40/compaction-identified paper-40/compaction-blend
REPRO_RUNS := $(addprefix runs/reproduce/,$(subst /,-,$(REPRO_CONFIGS)))

# a run that diverges keeps its diagnosis and last good frames; the batch goes on (results.md lists it)
runs/reproduce/%: setup
	-$(FP) --quiet run configs/$(subst paper-40-,paper-40/,$*).yaml --out $@

reproduce: $(REPRO_RUNS)
	$(FP) compare $(REPRO_RUNS) --out runs/reproduce/comparison
	$(PY) -m fiberpipe.verification three_beam_static rearrangement | tee runs/reproduce/three_beam.md
	$(PY) benchmarks/results_doc.py --runs runs/reproduce

studies: setup
	for s in configs/studies/*.yaml; do $(FP) study $$s --out runs/studies/$$(basename $$s .yaml) || exit 1; done
	$(PY) benchmarks/accuracy_cost_doc.py --runs runs/studies --out docs/accuracy-cost.md

# paper-40's fast settings against the study settings (issue 7; ≈ 12 min on one core)
fast-settings: setup
	NUMBA_NUM_THREADS=1 $(PY) benchmarks/fast_settings.py --save runs/fast_settings --out runs/fast_settings/table.md

contact-ensemble: setup
	NUMBA_NUM_THREADS=1 $(PY) benchmarks/contact_ensemble.py --seeds 0-7 --jobs 2 --out runs/contact_ensemble/table.md

# the same specimens, every law continued from one state (benchmarks/law_branch.py)
law-branch: setup
	NUMBA_NUM_THREADS=1 $(PY) benchmarks/law_branch.py --seeds 0-7 --jobs 2

clean:
	rm -rf runs .pytest_cache

# virtual specimens and the fit of the study's curve (docs/specimen.md, docs/fit.md)
.PHONY: specimen-400 study-fit
specimen-400: setup
	$(FP) specimen configs/specimens/bundle-400.yaml --out runs/specimens/bundle-400

# the spool radius of the study-like specimen fitted to the study's curve as its text describes it
# (data-samples/paper-40-fit/target.csv); each evaluation builds and settles a specimen and compacts it
# (≈ 8 min on one core), 8 evaluations
study-fit: setup
	$(FP) fit configs/specimens/paper-40.yaml --target data-samples/paper-40-fit/target.csv \
	    --param "specimen.bow.spool_radius=40 mm:400 mm" --budget 8 --out runs/fits/paper-40-spool
