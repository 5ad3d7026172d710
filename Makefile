# Two commands for a fresh machine (see README "Quick start"):
#   make demo   set up .venv if missing, install with the example extras, run the main example
#   make test   set up .venv if missing, install with the test extras, lint, run the whole suite
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: demo lint test bench accuracy docs clean

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

# ruff (lint and format, configured in pyproject.toml); `make test` fails on a lint error.
lint: $(VENV)/.installed-test
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

# One pytest worker per core (pytest-xdist), at most 8: each is a process with its own jax
# and compile caches; compilation dominates the suite (tests/README.md). The workers share
# JAX's persistent compilation cache in out/jax-cache (tests/conftest.py), kept for the next
# run. From a fresh clone on 2 cores, `make test` takes 37 to 52 minutes, pytest 36 to 50
# (about 10,100 programs compiled, 2,900 to 4,000 s of compiling over both workers; the
# same programs compile up to 1.4x slower from one run to the next on a shared machine);
# the compile budget (tests/_compile_budget.py) fails a run above 12,000.
test: lint
	$(PY) -m pytest -n auto --maxprocesses 8 --dist worksteal

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
