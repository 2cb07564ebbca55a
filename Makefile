PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# pytest-xdist workers for `make unit` (0: one process). Each module runs on one worker
# (--dist loadscope: its module fixtures are built once), handed out in collection order
# (--no-loadscope-reorder: tests/conftest.py puts the longest first), and each worker's BLAS
# on one thread (two workers on two cores; threaded BLAS under contention spins).
WORKERS ?= 2
SERIAL_BLAS := OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1

.PHONY: install demo showcase test lint typecheck unit slow fuzz bench clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

# the newcomer's demo (target: within 90 s on a 2-core machine; 70 s measured); `make
# showcase`: the markerless calibration (structure from motion; target: within 6 min, 5 min
# 15 s measured)
demo: install
	$(BIN)/python -m sample_data_gen.demo demo_out

showcase: install
	$(BIN)/python -m sample_data_gen.demo demo_out --only markerless

lint: install
	$(BIN)/ruff check acs_cli sample_data_gen tests benchmarks examples
	$(BIN)/ruff format --check acs_cli sample_data_gen tests benchmarks examples

typecheck: install
	$(BIN)/mypy

# `make test` leaves out the statistical studies (the `slow` marker: an estimator's stds
# against its error spread over many seeded trials); `make slow` runs them
unit: install
	$(SERIAL_BLAS) $(BIN)/pytest -q -n $(WORKERS) --dist loadscope --no-loadscope-reorder -m "not slow"

slow: install
	$(SERIAL_BLAS) $(BIN)/pytest -q -n $(WORKERS) --dist loadscope --no-loadscope-reorder -m slow

test: lint typecheck unit

# the property tests (Hypothesis's `hypothesis` marker) with fresh randomness and ten times the
# examples; `make test` runs them derandomized (tests/hypothesis_profiles.py)
fuzz: install
	HYPOTHESIS_PROFILE=fuzz $(SERIAL_BLAS) $(BIN)/pytest -q -m hypothesis -n $(WORKERS)

bench: install
	$(BIN)/python benchmarks/bench_estimators.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache .hypothesis demo_out
