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
	@echo "make verify   print the verification table (docs/verification.md)"
	@echo "make validate bundle-scale virtual experiments against published laws into docs/validation.md"
	@echo "make bench    benchmarks (docs/benchmarks.md)"
	@echo "make test-benchmarks  the checks of the developer scripts in benchmarks/"
	@echo "make fast-settings  paper-40 fast settings vs the study settings (fiberpipe study, ≈ 3 min)"
	@echo "make fast-ensemble  paper-40's fastest settings within 2 %, ensemble against ensemble, and the modal step's (≈ 14 min)"
	@echo "make yarn-100-accuracy  the fast settings against the study settings on a 100-fiber yarn, against the seed spread (≈ 12 min of CPU)"
	@echo "make fast-400 the 400-fiber specimen compacted at the study settings and with mass scaling 100 (≈ 35 min with the specimen, two cores)"
	@echo "make docs     build the documentation site into site/ (mkdocs-material, the docs extra)"

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

# the bundle-scale validation cases, full variants, three seeds, into docs/validation.md (CPU per case
# in docs/validation.md: within 15 min except case 5, about 18 min)
.PHONY: validate
validate: setup
	$(FP) validate --out runs/validation --docs docs/validation.md

bench-imaging: setup
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(PY) -m fiberpipe.benchmarks.bench_imaging

bench-solver: setup
	$(PY) -m fiberpipe.benchmarks.bench_solver

# imaging on real and large scans: the real CT sample with default settings, the harder phantom
# family (20 seeds, fibretracker beside), slab-by-slab segment of a 1000 x 2000 x 2000 uint16 volume
.PHONY: bench-real-ct bench-hard-phantoms bench-segment-large
bench-real-ct: setup
	$(PY) benchmarks/bench_real_ct.py

bench-hard-phantoms: setup
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(PY) benchmarks/bench_hard_phantoms.py --seeds 0-19

bench-segment-large: setup
	$(PY) benchmarks/bench_segment_large.py --shape 1000 2000 2000 --slab 32

# segment, skeletonize and trace of a 1000 x 2000 x 2000 uint16 volume (8 GB) chunk by chunk, peak memory per pass
.PHONY: bench-large-volume
bench-large-volume: setup
	$(PY) benchmarks/bench_large_volume.py --shape 1000 2000 2000 --slab 32 --block 64

# the pipeline's own stages (fiberpipe run, chunks.mode: on) on the same volume, peak memory per stage
.PHONY: bench-large-volume-stages
bench-large-volume-stages: setup
	$(PY) benchmarks/bench_large_volume.py --shape 1000 2000 2000 --slab 32 --passes stage-segment stage-skeletonize stage-trace

# the dense-composite family (v_f 0.45-0.6, r 2.5-5 voxels, CNR 2-5, misaligned, wavy, rings, cupping, a cross ply), 10 seeds, fibretracker beside
.PHONY: bench-dense-phantoms
bench-dense-phantoms: setup
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(PY) benchmarks/bench_dense_phantoms.py --seeds 0-9

# touching pairs at r = 5.5 voxels, 24 volumes; the structure-tensor package against fiberpipe's orientation
.PHONY: bench-touching-pairs bench-structure-tensor
bench-touching-pairs: setup
	$(PY) benchmarks/bench_touching_pairs.py --seeds 0-11

bench-structure-tensor: setup
	$(PY) -m pip install --quiet structure-tensor
	$(PY) benchmarks/bench_structure_tensor.py

# the real cross-ply CT example (qim3d's fibers_150x150x150.tif, fetched with pip download), pictures into docs/img
.PHONY: bench-cross-ply
bench-cross-ply: setup
	$(PY) benchmarks/bench_cross_ply.py --pictures docs/img

.PHONY: bench-contact bench-pyelastica fast-settings docs config-reference
bench-contact: setup
	$(PY) -m fiberpipe.benchmarks.bench_contact

bench-pyelastica: setup
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(PY) -m fiberpipe.benchmarks.bench_pyelastica

# the headline benchmarks in one run (solver, contact, PyElastica, paper-40, imaging, threads) into
# docs/benchmarks.md; ~10 min on an idle machine
bench: setup
	$(PY) -m pip install --quiet -e '.[test,bench]'
	$(FP) bench

# developer measurements, scripts of benchmarks/ (outside the package): paper-40's solver profile,
# against a reference checkout (REFERENCE=path with its own .venv), the largest stable step; the
# threads (docs/benchmarks.md); minutes each, behind these targets only
.PHONY: profile-paper40 bench-reference stable-step bench-threads step-energy three-beam-energy test-benchmarks
REFERENCE ?= ../wt-base
profile-paper40: setup
	$(PY) benchmarks/paper40_states.py runs/bench/p40.npz 138728 708000
	$(PY) benchmarks/bench_profile.py runs/bench/p40_138728.npz runs/bench/p40_708000.npz

# the same states sampled per thread and per compiled function with Linux perf (docs/benchmarks.md,
# "The step per thread, sampled"; needs perf and kernel.perf_event_paranoid <= 2)
.PHONY: perf-profile
perf-profile: setup
	test -f runs/bench/p40_708000.npz || $(PY) benchmarks/paper40_states.py runs/bench/p40.npz 138728 708000
	$(PY) benchmarks/perf_profile.py --state runs/bench/p40_708000.npz --threads 1 --steps 6000
	NUMBA_NUM_THREADS=2 $(PY) benchmarks/perf_profile.py --state runs/bench/p40_708000.npz --threads 2 --steps 6000
	NUMBA_NUM_THREADS=2 $(PY) benchmarks/perf_profile.py --state runs/bench/p40_138728.npz --threads 2 --steps 6000

# this code against $(REFERENCE) in one process, blocks of steps alternated from paper-40's
# compacted state (docs/benchmarks.md, "A change against the code before it, in one process")
.PHONY: bench-inprocess
bench-inprocess: setup
	test -f runs/bench/p40_708000.npz || $(PY) benchmarks/paper40_states.py runs/bench/p40.npz 138728 708000
	$(PY) benchmarks/bench_inprocess.py --reference $(REFERENCE) --state runs/bench/p40_708000.npz --threads 1 --steps 500
	$(PY) benchmarks/bench_inprocess.py --reference $(REFERENCE) --state runs/bench/p40_708000.npz --threads 2 --steps 500

bench-reference: setup
	$(PY) benchmarks/bench_ab.py --reference $(REFERENCE) --until 12ms --spans 10
	$(PY) benchmarks/bench_ab.py --reference $(REFERENCE) --spans 10

stable-step: setup
	$(PY) benchmarks/paper40_states.py runs/bench/p40.npz 0 708000
	$(PY) benchmarks/bench_stable_step.py runs/bench/p40_0.npz --span 2e-3
	$(PY) benchmarks/bench_stable_step.py runs/bench/p40_708000.npz --span 0.5e-3 --fixed-penalties --factors 0.8 0.85 0.9 0.95 1.0

# energy the time step creates in the six-fiber scene at 1000 N/m, against dt_safety (docs/contact.md)
step-energy: setup
	$(PY) benchmarks/bench_step_energy.py --load 3 30 300 1000 --seeds 4
	$(PY) benchmarks/bench_step_energy.py --law hertz_oriented --load 1000 --onset-fraction 0.004 0.012 --seeds 4
	$(PY) benchmarks/bench_step_energy.py --law hertz_parallel --dt-safety 0.9 0.8 0.7 0.6 0.45 --seeds 4
	$(PY) benchmarks/bench_step_energy.py --law linear --dt-safety 0.9 0.8 0.7 0.6 0.45 --penalty-factor 0.1 0.05 --seeds 4

# where the undamped 3-beam case's energy goes, against dt_safety and the law (docs/verification.md)
three-beam-energy: setup
	$(PY) benchmarks/bench_three_beam_energy.py --dt-safety 0.9 0.45 0.225

bench-threads: setup
	NUMBA_NUM_THREADS=2 $(PY) -m fiberpipe.benchmarks.bench_threads --fibers 160 640

# the scripts' own checks (seconds; not part of make test)
test-benchmarks: setup
	$(PY) -m pytest -q benchmarks

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
	$(PY) tools/results_doc.py --runs runs/reproduce

studies: setup
	for s in configs/studies/*.yaml; do $(FP) study $$s --out runs/studies/$$(basename $$s .yaml) || exit 1; done
	$(PY) tools/accuracy_cost_doc.py --runs runs/studies --out docs/accuracy-cost.md

# paper-40's fast settings against the study settings (configs/studies/paper40-fast-settings.yaml)
fast-settings: setup
	$(FP) study configs/studies/paper40-fast-settings.yaml --out runs/studies/paper40-fast-settings

# paper-40's fastest settings within 2 % against the study settings, ensemble against ensemble, with
# their wall times (docs/benchmarks.md, "Fast settings"; ≈ 14 min on one core)
.PHONY: fast-ensemble
fast-ensemble: setup
	$(PY) benchmarks/bench_fast_ensemble.py --out runs/bench/fast-ensemble --runs 2 \
		--setting "study:" \
		--setting "modes:solver.stable_step=modes,solver.dt_safety=0.85" \
		--setting "ms100-modes:solver.mass_scaling=100,scene.damping.alpha=1e3 1/s,solver.stable_step=modes,solver.dt_safety=0.85" \
		--setting "ms100:solver.mass_scaling=100,scene.damping.alpha=1e3 1/s" \
		--setting "ms25:solver.mass_scaling=25,scene.damping.alpha=4e3 1/s"

# the documentation site (docs/ and the generated config reference) into site/
docs: setup config-reference
	$(PY) -m pip install --quiet -e '.[docs]'
	$(PY) -m mkdocs build --strict --site-dir site

config-reference: setup
	( cat docs/config.head.md; echo; $(PY) -c 'from fiberpipe.config import reference_markdown; print(reference_markdown())' ) > docs/config.md.tmp
	mv docs/config.md.tmp docs/config.md

clean:
	rm -rf runs .pytest_cache site

# virtual specimens and the fit of the study's curve (docs/specimen.md, docs/fit.md)
.PHONY: specimen-400 study-fit
specimen-400: setup
	$(FP) specimen configs/specimens/bundle-400.yaml --out runs/specimens/bundle-400

# yarns of 1000 and 4000 of the study's fibers: the specimen packed, then compacted at the fast
# settings on two threads (docs/benchmarks.md, "Virtual specimens")
.PHONY: yarn-1000 yarn-4000
yarn-1000 yarn-4000: yarn-%: setup
	$(FP) specimen configs/specimens/yarn-$*.yaml --out runs/specimens/yarn-$*
	NUMBA_NUM_THREADS=2 $(FP) run runs/specimens/yarn-$*/config.yaml --out runs/yarn-$*

# the writers and post on 24 synthetic frames of the 4000-fiber yarn (docs/benchmarks.md)
.PHONY: bench-output-4000
bench-output-4000: setup
	$(FP) specimen configs/specimens/yarn-4000.yaml --out runs/specimens/yarn-4000
	$(PY) benchmarks/bench_output_scale.py runs/specimens/yarn-4000 --out runs/bench-output-4000

# accuracy at scale: the fast settings' curve on a 100-fiber sub-bundle of the yarn against the
# study settings' on the same specimens (seeds 0 and 1), and the fast curve's spread over specimen seeds 0-3
# (docs/benchmarks.md, "Fast settings"; one core, ≈ 12 min of CPU, most of it the study settings' runs)
YARN100_SEEDS := 0 1 2 3
.PHONY: yarn-100-accuracy
yarn-100-accuracy: setup
	for seed in $(YARN100_SEEDS); do $(FP) specimen configs/specimens/yarn-100.yaml --seed $$seed \
		--out runs/specimens/yarn-100-s$$seed || exit 1; done
	NUMBA_NUM_THREADS=1 $(PY) benchmarks/bench_fast_ensemble.py --out runs/bench/yarn-100-accuracy --runs 1 --window-mm 0.2378 \
		--reference-specimens 2 $(foreach seed,$(YARN100_SEEDS),--config runs/specimens/yarn-100-s$(seed)/config.yaml) \
		--setting "study:solver.mass_scaling=1,scene.damping.alpha=1e5 1/s,solver.stable_step=element,solver.dt_safety=0.95" \
		--setting "fast:"

.PHONY: bench-400
bench-400: specimen-400
	NUMBA_NUM_THREADS=1 $(PY) benchmarks/bench_bundle_cost.py runs/specimens/bundle-400/config.yaml

# the 400-fiber specimen compacted at the study's settings and with mass scaling 100 (alpha / 100),
# two threads each (docs/benchmarks.md, "Headline figures"; ≈ 30 min on two cores)
.PHONY: fast-400
fast-400: specimen-400
	$(FP) study configs/studies/bundle-400/fast-settings.yaml --out runs/studies/bundle400-fast-settings

.PHONY: bench-400-threads
bench-400-threads: specimen-400
	NUMBA_NUM_THREADS=2 $(PY) -m fiberpipe.benchmarks.bench_threads --config runs/specimens/bundle-400/config.yaml --steps 200 --rounds 6

# the spool radius of the study-like specimen fitted to the study's curve as its text describes it
# (data-samples/paper-40-fit/target.csv); each evaluation builds and settles a specimen and compacts it
# (11-15 min on one core), 3 evaluations; the range brackets Gutowski's estimate (β ≈ 46: R ≈ 85 mm)
study-fit: setup
	$(FP) fit configs/specimens/paper-40.yaml --target data-samples/paper-40-fit/target.csv \
	    --param "specimen.bow.spool_radius=40 mm:160 mm" --budget 3 --out runs/fits/paper-40-spool

# the study's contact models on the fitted specimen (configs/specimens/paper-40-fitted.yaml, the radius
# study-fit finds) over three seeds, and the fit section of docs/results.md (≈ 1 h on one core)
.PHONY: reproduce-fit
reproduce-fit: study-fit
	$(PY) tools/fit_prediction.py --config configs/specimens/paper-40-fitted.yaml --fit runs/fits/paper-40-spool \
	    --seeds 0 1 2 --out runs/fits/paper-40-fitted --doc docs/results.md
reproduce: reproduce-fit

# the study's compaction predicted from its own statistics, nothing fitted (configs/specimens/study-prediction.yaml,
# docs/results.md): SEEDS=N its first N seeds (default 8), FAST=1 without the study-settings runs of two seeds
.PHONY: study-prediction study-sensitivity
study-prediction: setup
	$(PY) tools/study_prediction.py --out runs/study-prediction --figure docs/img/study_prediction.png \
	    $(if $(SEEDS),--seeds $(SEEDS)) $(if $(FAST),--fast-only) --doc docs/results.md \
	    --command "make study-prediction$(if $(SEEDS), SEEDS=$(SEEDS))$(if $(FAST), FAST=1)"

# each unknown of the study in turn on the prediction's first four seeds (SEEDS=N to change), the tornado
# plot and the table of docs/results.md; ONLY="bow-4m vf-35" runs those variants alone
study-sensitivity: study-prediction
	$(PY) tools/study_sensitivity.py --prediction runs/study-prediction --out runs/study-sensitivity \
	    --seeds $(or $(SEEDS),4) --doc docs/results.md --figure docs/img/study_sensitivity.png $(if $(ONLY),--only $(ONLY))

# the bow radius and v_f0 fitted to the study's curve points on a grid of four-seed ensembles (reusing the
# sensitivity's runs), then the parallel and oblique 6° models on the fitted family; docs/results.md
.PHONY: study-fit-ensemble
study-fit-ensemble: study-sensitivity
	$(PY) tools/study_fit.py --prediction runs/study-prediction --sensitivity runs/study-sensitivity \
	    --out runs/study-fit --seeds $(or $(SEEDS),4) --doc docs/results.md --figure docs/img/study_fit.png \
	    $(foreach g,$(GRID),--grid $(g)) $(if $(COLLECT),--collect)
