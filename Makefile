PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test lint typecheck unit fuzz bench clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: install
	$(BIN)/python -m sample_data_gen.demo demo_out

lint: install
	$(BIN)/ruff check acs_cli sample_data_gen tests benchmarks
	$(BIN)/ruff format --check acs_cli sample_data_gen tests benchmarks

typecheck: install
	$(BIN)/mypy

unit: install
	$(BIN)/pytest -q

test: lint typecheck unit

# the property tests (Hypothesis's `hypothesis` marker) with fresh randomness and ten times the
# examples; `make test` runs them derandomized (tests/hypothesis_profiles.py)
fuzz: install
	HYPOTHESIS_PROFILE=fuzz $(BIN)/pytest -q -m hypothesis

bench: install
	$(BIN)/python benchmarks/bench_estimators.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache .hypothesis demo_out
