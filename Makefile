# Quick start: `make run` (main job) and `make test` (default test suite). Both create .venv on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# One BLAS thread: the twins' calibrations make many tiny matrix calls, which threaded BLAS slows down
# on a 2-core machine (measured 9 ms vs <1 ms per 8x8 expm when both cores are busy).
export OPENBLAS_NUM_THREADS ?= 1

.PHONY: run run-quick test test-heavy test-all lint bench bench-diagnosis fmus docs install clean floors floors-full lock

# Exact versions: requirements.lock holds every package of the environment the floors and stored rows were
# measured with (docs/regression-check.md); `make lock` refreshes it from pyproject.toml.
LOCK   := requirements.lock

$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# CPU build of torch first: an unpinned torch requirement would pull several GB of CUDA packages.
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -r $(LOCK)
	$(PY) -m pip install -q --no-deps -e .
	$(PY) -m pip check
	touch $(STAMP)

# A fresh environment resolved from pyproject.toml (test and lint extras), frozen into requirements.lock.
lock:
	rm -rf .lock-venv
	$(PYTHON) -m venv .lock-venv
	.lock-venv/bin/pip install -q --upgrade pip
	.lock-venv/bin/pip install -q torch==2.13.0
	.lock-venv/bin/pip install -q ".[test,lint]"
	{ echo "# Exact versions installed by make install (refresh: make lock; then re-measure the floors: make floors)."; \
	  .lock-venv/bin/pip freeze --exclude piezotwin; } > $(LOCK).tmp
	mv $(LOCK).tmp $(LOCK)
	rm -rf .lock-venv

install: $(STAMP)

run: $(STAMP)
	$(VENV)/bin/piezotwin run

run-quick: $(STAMP)
	$(VENV)/bin/piezotwin run --quick

# Two pytest-xdist workers (the CI machine's two cores), one test file at a time per worker (--dist loadfile): a
# file's module fixtures (trained models, a compiled FMU host, exported FMUs) are built once, as in a serial run.
# `make test-all` runs everything in one process. The checks of 10 s or more (marked `heavy`: whole diagnoses, the
# thesis's quick tier, compiled FMU hosts; 500 of the suite's 920 s of test time, measured 2026-12-02) are left to
# `make test-heavy`, which CI runs before `make test`: the everyday suite stays within its 5 minutes on two cores.
test: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile

test-heavy: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile -m heavy

test-all: $(STAMP)
	$(PY) -m pytest -q -m "not perf"

# The guards of every change (configuration in pyproject.toml, reasons in docs/development.md): ruff's lint rules,
# ruff's formatter (a file it would change fails) and mypy over the library and the CLI.
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy

bench: $(STAMP)
	mkdir -p docs/perf
	$(PY) -m pytest -q -m perf tests/perf --benchmark-enable --benchmark-only \
	  --benchmark-json=docs/perf/bench.json -p no:randomly
	$(PY) -m tests.perf.summarise docs/perf/bench.json -o docs/perf/summary.md

# The diagnosis benchmark's full set (benchmarks/settings/diagnosis_bench.toml): hours on two cores; resumes where
# it stopped (docs/diagnosis-benchmark/results.jsonl), then renders docs/diagnosis-benchmark.md.
bench-diagnosis: $(STAMP)
	$(VENV)/bin/piezotwin bench-diagnosis --workers 2

fmus: $(STAMP)
	$(VENV)/bin/piezotwin export-fmu cantilever -o fmus/cantilever.fmu
	$(VENV)/bin/piezotwin export-fmu acoustic -o fmus/acoustic.fmu

# Regenerate the CLI reference from the argument parser (tests/test_docs.py checks it is current).
docs: $(STAMP)
	$(PY) -m benchmarks.cli.clidoc -o docs/cli.md
	$(PY) -m benchmarks.cli records --render-only

clean:
	rm -rf $(VENV) report .pytest_cache .benchmarks

# Accuracy floors of the quick check, measured as CI meets them on any x86-64 CPU: the quick run with torch's
# generic, AVX2 and native kernels, each with 1 and 2 BLAS threads; then with each OpenBLAS kernel set a CPU may
# pick (OPENBLAS_CORETYPE, set for that run only; SkylakeX where the CPU has AVX-512); plus seeds 5-19 of the
# seeded identifiers. The worst value of each pair sets its floor (docs/regression-check.md). FLOORS_ARGS narrows
# it, e.g. FLOORS_ARGS="--identifiers oe,bj".
CORETYPES := Prescott Haswell Zen $(shell grep -qw avx512f /proc/cpuinfo 2>/dev/null && echo SkylakeX)
floors: $(STAMP)
	mkdir -p .floors
	for isa in default avx2 native; do for th in 1 2; do \
	  if [ $$isa = native ]; then e="env -u ATEN_CPU_CAPABILITY"; else e="env ATEN_CPU_CAPABILITY=$$isa"; fi; \
	  $$e OPENBLAS_NUM_THREADS=$$th $(VENV)/bin/piezotwin score --quick --json $(FLOORS_ARGS) \
	    > .floors/run_$${isa}_$${th}.json || exit 1; \
	done; done
	for ct in $(CORETYPES); do \
	  env OPENBLAS_CORETYPE=$$ct OPENBLAS_NUM_THREADS=1 $(VENV)/bin/piezotwin score --quick --json $(FLOORS_ARGS) \
	    > .floors/run_blas_$$ct.json || exit 1; \
	done
	$(VENV)/bin/piezotwin score --quick --json --seeds 5-19 $(FLOORS_ARGS) > .floors/extra_seeds.json
	$(VENV)/bin/piezotwin score --quick --update-baselines --from-runs .floors/run_*.json .floors/extra_seeds.json

# The full-mode floors (`score --check` without --quick) measured the same way: torch's kernel sets x 1 and 2 BLAS
# threads, then each OpenBLAS kernel set. Hours on two cores for every dataset: narrow it with FLOORS_ARGS, e.g.
# FLOORS_ARGS="--datasets cascaded-tanks,piezo-tue --identifiers narx-poly-sim,pnlss" (docs/regression-check.md).
floors-full: $(STAMP)
	mkdir -p .floors-full
	for isa in default avx2 native; do for th in 1 2; do \
	  if [ $$isa = native ]; then e="env -u ATEN_CPU_CAPABILITY"; else e="env ATEN_CPU_CAPABILITY=$$isa"; fi; \
	  $$e OPENBLAS_NUM_THREADS=$$th $(VENV)/bin/piezotwin score --json $(FLOORS_ARGS) \
	    > .floors-full/run_$${isa}_$${th}.json || exit 1; \
	done; done
	for ct in $(CORETYPES); do \
	  env OPENBLAS_CORETYPE=$$ct OPENBLAS_NUM_THREADS=1 $(VENV)/bin/piezotwin score --json $(FLOORS_ARGS) \
	    > .floors-full/run_blas_$$ct.json || exit 1; \
	done
	$(VENV)/bin/piezotwin score --update-baselines --from-runs .floors-full/run_*.json
