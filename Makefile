# Every target sets itself up: the first use creates .venv and installs the package.
# `make test` / `make demo` / CI install the exact versions of requirements/lock.txt (the ones
# a green run proved); `make test-latest` installs the newest releases the ranges in
# pyproject.toml allow, into a separate .venv-latest, to see dependency drift coming.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
LOCK   := requirements/lock.txt
LATEST := .venv-latest

.PHONY: demo test test-all test-latest lint compare lock clean docs

$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -c $(LOCK) pip
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e '.[test,docs]'
	touch $(STAMP)

## main job: the papers' examples and the default solver comparison, written to report/
demo: $(STAMP)
	$(BIN)/optmodels demo --out report

## default test suite (no `slow` tests) plus the tools that hold the rules: the linter, the
## type checker ([tool.mypy] in pyproject.toml) and the import contracts of
## docs/architecture.md ([tool.importlinter]); pytest on 2 workers (pytest-xdist: CI has 2
## cores, and the suite is mostly subprocesses and single-threaded solves)
test: $(STAMP)
	$(BIN)/ruff check optmodels solvers_cmp tests
	$(BIN)/ruff format --check optmodels solvers_cmp tests
	$(BIN)/mypy
	$(BIN)/lint-imports
	$(BIN)/mkdocs build --strict --quiet
	$(BIN)/python -m pytest -n 2

## the user guide and API reference as a site in build/site (warnings are errors)
docs: $(STAMP)
	$(BIN)/mkdocs build --strict

## everything, including the long Monte Carlo / scaling runs
test-all: $(STAMP)
	$(BIN)/ruff check optmodels solvers_cmp tests
	$(BIN)/ruff format --check optmodels solvers_cmp tests
	$(BIN)/mypy
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -m ""

## the same tests against the newest releases of every dependency (no lock)
test-latest:
	$(PYTHON) -m venv $(LATEST)
	$(LATEST)/bin/python -m pip install --quiet --upgrade pip
	$(LATEST)/bin/python -m pip install --quiet --upgrade --upgrade-strategy eager -e '.[test]'
	$(LATEST)/bin/python -m pip freeze --exclude-editable > $(LATEST)/versions.txt
	$(LATEST)/bin/ruff check optmodels solvers_cmp tests
	$(LATEST)/bin/python -m pytest -p no:cacheprovider

## rewrite the lock from the current .venv (after a green `make test` with newer versions)
lock: $(STAMP)
	{ sed -n '1,3p' $(LOCK); $(BIN)/python -m pip freeze --exclude-editable --all \
	  | grep -v -e '^setuptools==' -e '^wheel=='; } > $(LOCK).new && mv $(LOCK).new $(LOCK)

lint: $(STAMP)
	$(BIN)/ruff check optmodels solvers_cmp tests
	$(BIN)/ruff format --check optmodels solvers_cmp tests
	$(BIN)/mypy
	$(BIN)/lint-imports

compare: $(STAMP)
	$(BIN)/optmodels compare --out report/compare

clean:
	rm -rf $(VENV) $(LATEST) report .pytest_cache
