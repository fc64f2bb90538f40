# Two entry points do all set-up on a fresh machine: `make run` and `make test`.
# torch is installed first, pinned to a CPU build; use another with
#   make run TORCH_SPEC="torch==2.13.0 --index-url https://download.pytorch.org/whl/cu124"
PYTHON ?= python3
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
PYTEST_ARGS ?=
# test processes (pytest-xdist; 0: none). One file per process (--dist loadfile), so a
# module's shared fixtures (a multirun, a scratch pipeline project) are built once.
TEST_WORKERS ?= 2
XDIST = -n $(TEST_WORKERS) --dist loadfile
BIN := $(VENV)/bin
STAMP := $(VENV)/.cdpr-installed

.PHONY: install run test test-pipeline test-slow bench bench-models bench-detection lint clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet $(TORCH_SPEC)
	$(BIN)/python -m pip install --quiet -e '.[dev,pipeline]'
	touch $(STAMP)

## install: the virtual environment only (what every other target does first)
install: $(STAMP)

## run: the staged pipeline (dvc.yaml) on the default virtual lab with one hidden effect:
## params.yaml from conf/, then `dvc repro` under one MLflow parent run (`cdpr repro`);
## a second run does nothing unless inputs changed. ARGS="profile=paper" for the paper's sizes
ARGS ?=
run: $(STAMP)
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/cdpr repro $(ARGS)

## test: the fast test suite (what CI runs), on TEST_WORKERS processes
test: $(STAMP)
	$(BIN)/python -m pytest $(XDIST) $(PYTEST_ARGS)

## test-pipeline: the end-to-end pipeline tests (cdpr repro profile=tiny in scratch copies):
## on the virtual lab, then ingesting the shipped foreign rig and the shipped EMPS data
## (the two files side by side, one process each; each repro's wall time is printed)
test-pipeline: $(STAMP)
	$(BIN)/python -m pytest -m slow $(XDIST) tests/stages/test_pipeline_e2e.py \
		tests/stages/test_pipeline_ingest_e2e.py --durations=3 $(PYTEST_ARGS)

## test-slow: every slow end-to-end test
test-slow: $(STAMP)
	$(BIN)/python -m pytest -m slow $(XDIST) $(PYTEST_ARGS)

## bench: benchmark scripts (figures quoted in the README)
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_simulator.py
	$(BIN)/python benchmarks/bench_diagnose.py
	$(BIN)/python benchmarks/bench_emps.py

## bench-detection: detection and false-alarm rates of `cdpr diagnose` and the smallest
## magnitude of each hidden effect it detects reliably (about an hour on 2 cores)
bench-detection: $(STAMP)
	$(BIN)/python benchmarks/bench_detection.py

## bench-models: train every trajectory predictor on the default dataset (about an hour
## on 2 cores) and print the table quoted in the README
bench-models: $(STAMP)
	$(BIN)/python benchmarks/bench_models.py

lint: $(STAMP)
	$(BIN)/ruff check cdpr_pipeline tests benchmarks

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache dvc_plots
