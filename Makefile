# Two commands for a fresh machine (see README "Quick start"):
#   make demo   set up .venv if missing, install with the example extras, run the main example
#   make test   set up .venv if missing, install with the test extras, run the whole suite
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: demo test bench accuracy docs clean

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

# One pytest worker per core (pytest-xdist), at most 8 (each is a process with its own jax
# and compile caches): compilation dominates the suite and XLA alone keeps about 1.3 of 2
# cores busy. On the 2-core CI VM, 626-741 s -> 447 s.
test: $(VENV)/.installed-test
	$(PY) -m pytest -n auto --maxprocesses 8 --dist worksteal

bench: $(VENV)/.installed-test
	$(PY) benchmarks/run.py

accuracy: $(VENV)/.installed-test
	$(PY) benchmarks/accuracy.py

# The API reference, generated from the docstrings: open out/docs/index.html.
docs: $(VENV)/.installed-docs
	$(PY) -m pdoc --docformat google --math -o out/docs jaxlie_geo

clean:
	rm -rf $(VENV) out build *.egg-info
