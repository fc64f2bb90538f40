# Two entry points do all set-up on a fresh machine: `make run` and `make test`.
# torch is installed first, pinned to a CPU build; use another with
#   make run TORCH_SPEC="torch==2.13.0 --index-url https://download.pytorch.org/whl/cu124"
PYTHON ?= python3
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
# more pip install flags (CI: --no-compile, .ci/run)
PIP_FLAGS ?=
PYTEST_ARGS ?=
# test processes (pytest-xdist; 0: none). One file per process (--dist loadfile), so a
# module's shared fixtures (a multirun, a scratch pipeline project) are built once; files
# handed out in collection order, the end-to-end files first (tests/conftest.py), not
# xdist's default of the files with most tests first, which in one session with the fast
# files (make test-ci) would start the e2e files, a few tests of minutes each, last
TEST_WORKERS ?= 2
XDIST = -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder
BIN := $(VENV)/bin
STAMP := $(VENV)/.cdpr-installed

.PHONY: install run lock test test-ci test-golden test-pipeline test-slow bench bench-null \
	bench-pipeline bench-models bench-detection bench-test-draws lint clean

# compileall: the project's own bytecode, which pip leaves to the first import of an
# editable install; where PYTHONDONTWRITEBYTECODE is set, every process (each stage of a
# repro, each test worker) would compile it again (0.14 s of CPU for a diagnose's imports;
# the whole package takes 0.3 s once). A stale file is ignored once the source changes.
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet $(PIP_FLAGS) --upgrade pip
	$(BIN)/python -m pip install --quiet $(PIP_FLAGS) $(TORCH_SPEC)
	$(BIN)/python -m pip install --quiet $(PIP_FLAGS) -e '.[dev,pipeline]'
	$(BIN)/python -m compileall -q cdpr_pipeline > /dev/null
	touch $(STAMP)

## install: the virtual environment only (what every other target does first)
install: $(STAMP)

## run: the staged pipeline (dvc.yaml) on the default virtual lab with one hidden effect:
## params.yaml from conf/, then `dvc repro` under one MLflow parent run (`cdpr repro`);
## a second run does nothing unless inputs changed. ARGS="profile=paper" for the paper's sizes
ARGS ?=
# the pipeline's MLflow store: the project root's mlflow.db (MLflow's default is the working
# directory's); an MLFLOW_TRACKING_URI set in the environment wins
MLFLOW_TRACKING_URI ?= sqlite:///$(CURDIR)/mlflow.db
run: export MLFLOW_TRACKING_URI := $(MLFLOW_TRACKING_URI)
run: $(STAMP)
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/cdpr repro $(ARGS)

## lock: regenerate the committed dvc.lock honestly (a fast test keeps it in step with the
## code and params.yaml): the default pipeline, `dvc repro` on the committed params.yaml, in
## a scratch copy (LOCK_DIR) with its own MLflow store; its dvc.lock is copied back. About
## as long as a first `make run`. Run it after the last change to code a stage depends on.
LOCK_DIR ?= /tmp/cdpr-lock
lock: $(STAMP)
	rm -rf $(LOCK_DIR) && mkdir -p $(LOCK_DIR)
	cp -r dvc.yaml params.yaml .dvcignore cdpr_pipeline $(LOCK_DIR)/
	cd $(LOCK_DIR) && $(abspath $(BIN))/python -m dvc init --no-scm -q && \
		PATH="$(abspath $(BIN)):$$PATH" MLFLOW_TRACKING_URI="sqlite:///$(LOCK_DIR)/mlflow.db" \
		$(abspath $(BIN))/python -m dvc repro
	cp $(LOCK_DIR)/dvc.lock dvc.lock

## test: the fast test suite (what CI runs), on TEST_WORKERS processes
test: $(STAMP)
	$(BIN)/python -m pytest $(XDIST) $(PYTEST_ARGS)

## test-golden: the tests that compare with a record checked in (tests/stages/
## foreign_rig_diagnosis.json) again under other OpenBLAS kernels: Haswell and Prescott,
## and SkylakeX where /proc/cpuinfo reports AVX-512 (a kernel sums in another order; the
## record must hold on any machine). Only those tests, one process per kernel, all at
## once (each is one short single-threaded diagnosis); each kernel's output is printed
## when all are done, and any failure fails the target
GOLDEN_TESTS ?= tests/stages/test_diagnose_stage.py::test_foreign_rig_is_diagnosed
GOLDEN_KERNELS ?= Haswell Prescott $(shell grep -qw avx512f /proc/cpuinfo 2>/dev/null && echo SkylakeX)
test-golden: $(STAMP)
	@logs=$$(mktemp -d); pids=""; \
	for kernel in $(GOLDEN_KERNELS); do \
		OPENBLAS_CORETYPE=$$kernel $(BIN)/python -m pytest -n 0 -q -p no:cacheprovider \
			$(GOLDEN_TESTS) $(PYTEST_ARGS) > $$logs/$$kernel.log 2>&1 & pids="$$pids $$!"; \
	done; \
	status=0; for pid in $$pids; do wait $$pid || status=1; done; \
	for kernel in $(GOLDEN_KERNELS); do \
		echo "golden tests under OPENBLAS_CORETYPE=$$kernel"; cat $$logs/$$kernel.log; \
	done; \
	rm -rf $$logs; exit $$status

## test-pipeline: the end-to-end pipeline tests (cdpr repro profile=tiny in scratch copies):
## on the virtual lab (with a DVC push/clone/pull round trip), then ingesting the shipped
## foreign rig and the shipped EMPS data; and scaling out: DDP on 2 CPU processes, joblib
## and submitit_local sweeps; the wheel installed into a fresh venv, a diagnose killed
## mid-write: the tests marked e2e (the files side by side, one process each; each repro's
## wall time is printed)
test-pipeline: $(STAMP)
	$(BIN)/python -m pytest -m e2e $(XDIST) --durations=3 $(PYTEST_ARGS)

## test-ci: what CI runs: the fast suite and the end-to-end pipeline tests in one pytest
## session on TEST_WORKERS processes, the e2e files first: the workers share one start-up
## and the fast files fill in beside the long e2e ones (two sessions one after the other
## each ended with one worker idle)
test-ci: $(STAMP)
	$(BIN)/python -m pytest -m "not slow or e2e" $(XDIST) --durations=5 $(PYTEST_ARGS)

## test-slow: every slow end-to-end test
test-slow: $(STAMP)
	$(BIN)/python -m pytest -m slow $(XDIST) $(PYTEST_ARGS)

## bench: the quick benchmarks (a few minutes); each writes its section of
## docs/measurements.md (bench_diagnose.py: see its own docstring)
bench: $(STAMP)
	$(BIN)/python -m benchmarks.bench_simulator
	$(BIN)/python -m benchmarks.bench_diagnose
	$(BIN)/python -m benchmarks.bench_foreign_diagnose
	$(BIN)/python -m benchmarks.bench_emps

## bench-null: how often each of the diagnosis's tests fires on effect-free data
## (24 datasets, both simulators; several minutes)
bench-null: $(STAMP)
	$(BIN)/python -m benchmarks.bench_null_calibration

## bench-pipeline: the whole pipeline from nothing in a scratch copy, per stage
## (the default profile: about 20 minutes on 2 cores)
bench-pipeline: $(STAMP)
	$(BIN)/python -m benchmarks.bench_pipeline

## bench-detection: detection and false-alarm rates of `cdpr diagnose` and the smallest
## magnitude of each hidden effect it detects reliably (about an hour on 2 cores)
bench-detection: $(STAMP)
	$(BIN)/python -m benchmarks.bench_detection

## bench-test-draws: the pass rate of every random-draw test over 200 draws (DRAWS=N for
## another count; hours on 2 cores, see the script's docstring)
DRAWS ?= 200
bench-test-draws: $(STAMP)
	$(BIN)/python -m benchmarks.bench_test_draws --draws $(DRAWS) -n $(TEST_WORKERS)

## bench-models: train every trajectory predictor on the default dataset (about an hour
## on 2 cores); the dataset is simulated first if missing
bench-models: $(STAMP)
	test -d data/generated/lab || $(BIN)/cdpr simulate quiet=true
	$(BIN)/python -m benchmarks.bench_models

lint: $(STAMP)
	$(BIN)/ruff check cdpr_pipeline tests benchmarks

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache dvc_plots
