# Every target sets itself up: the first use creates .venv and installs the package.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: demo test test-all lint compare clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

## main job: the papers' examples and the default solver comparison, written to report/
demo: $(STAMP)
	$(BIN)/optmodels demo --out report

## default test suite (no `slow` tests) plus the linter
test: $(STAMP)
	$(BIN)/ruff check optmodels solvers_cmp tests
	$(BIN)/python -m pytest

## everything, including the long Monte Carlo / scaling runs
test-all: $(STAMP)
	$(BIN)/ruff check optmodels solvers_cmp tests
	$(BIN)/python -m pytest -m ""

lint: $(STAMP)
	$(BIN)/ruff check optmodels solvers_cmp tests
	$(BIN)/ruff format --check optmodels solvers_cmp tests

compare: $(STAMP)
	$(BIN)/optmodels compare --out report/compare

clean:
	rm -rf $(VENV) report .pytest_cache
