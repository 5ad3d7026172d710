# Two commands for a fresh machine (see README "Quick start"):
#   make demo   set up .venv if missing, install with the example extras, run the main example
#   make test   set up .venv if missing, install with the test extras, lint, run the fast suite
# and every check: make test-full (what CI runs: both suites, the docs build, the notebooks).
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: demo lint test test-full bench accuracy docs clean

$(PY):
	$(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(VENV)/.installed-examples: pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[examples]"
	touch $@

$(VENV)/.installed-docs: pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[docs]"
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[test]"
	touch $@

demo: $(VENV)/.installed-examples
	$(PY) examples/pose_interpolation.py

# ruff (lint and format, configured in pyproject.toml) and the repository's rules (README
# length, stripped notebooks: tests/check_repository.py); both suites fail on a lint error.
lint: $(VENV)/.installed-test
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) tests/check_repository.py

# One pytest worker per core (pytest-xdist), at most 8: each is a process with its own jax
# and compile caches; compilation dominates the suite (tests/README.md). The workers share
# JAX's persistent compilation cache in out/jax-cache (tests/conftest.py), kept for the next
# run, so a rerun compiles little. `make test` is the fast suite (-m "not slow"): every
# module, group and dtype, values and first derivatives. `make test-full` adds the slow
# checks (tests/_suites.py: the same code paths at other dtypes, degrees, grids, batch
# shapes), the docs build and the notebooks. Each fails above its compile budget
# (tests/_compile_budget.py). From a fresh clone on 2 cores: `make test` 12 minutes
# (pytest 11), `make test-full` 39 (pytest 37, before least_squares); tests/README.md has the counts.
PYTEST := $(PY) -m pytest -n auto --maxprocesses 8 --dist worksteal

test: lint
	$(PYTEST) -m "not slow"

test-full: lint
	$(PYTEST)

# The benchmarks: each run replaces this machine's raw results and regenerates
# benchmarks/RESULTS.md and its plot (benchmarks/README.md).
bench: $(VENV)/.installed-test
	$(PY) -m benchmarks.run --save
	$(PY) -m benchmarks.run --dtype float64 --save
	$(PY) -m benchmarks.jacobians --save

accuracy: $(VENV)/.installed-test
	$(PY) -m benchmarks.accuracy --save

# The documentation site (mkdocs-material + mkdocstrings, docs/ and the docstrings): open
# out/site/index.html. Strict: a broken link or an unparsable docstring fails the build.
docs: $(VENV)/.installed-docs
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict -d out/site

clean:
	rm -rf $(VENV) out build *.egg-info
