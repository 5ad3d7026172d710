"""The compile budgets (``tests/_compile_budget.py``) fail a run that compiles more programs
than its suite's limit and pass one within it: a small suite run in a subprocess, as its
fast suite (``-m "not slow"``), as its full suite, and with an explicit limit."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Dict, Optional

_SUITE = """
import jax
import jax.numpy as jnp
import numpy as np
import pytest

def test_two_programs():
    x = np.arange(3.0)
    for f in (jnp.sin, jnp.cos):
        jax.jit(f)(x).block_until_ready()

@pytest.mark.slow
def test_one_more_program():
    jax.jit(jnp.tanh)(np.arange(3.0)).block_until_ready()
"""

_CONFTEST = """
import _compile_budget

def pytest_configure(config):
    config.addinivalue_line("markers", "slow: left out of the fast suite")
    _compile_budget.BUDGETS.update(fast={fast}, full={full})
"""


def _run(
    tmp_path: Path, *args: str, fast: int = 2, full: int = 3, env: Optional[Dict[str, str]] = None
) -> subprocess.CompletedProcess:
    (tmp_path / "test_small.py").write_text(_SUITE)
    (tmp_path / "conftest.py").write_text(_CONFTEST.format(fast=fast, full=full))
    environ = {
        **{k: v for k, v in os.environ.items() if k != "JAXLIE_GEO_TEST_PROGRAM_BUDGET"},
        "PYTHONPATH": str(Path(__file__).parent),
        "JAX_ENABLE_COMPILATION_CACHE": "false",
        **(env or {}),
    }
    cmd = [sys.executable, "-m", "pytest", "-p", "_compile_budget", "-p", "no:cacheprovider"]
    return subprocess.run(
        [*cmd, *args], cwd=tmp_path, env=environ, capture_output=True, text=True, timeout=120
    )


def test_each_suite_fails_beyond_its_budget_and_passes_within(tmp_path):
    over = _run(tmp_path, "-m", "not slow", fast=1)
    assert over.returncode == 1, over.stdout + over.stderr
    assert "1 passed" in over.stdout
    assert "total: 2 programs" in over.stdout and "(fast suite)" in over.stdout
    assert "more than its budget of 1: fails the run" in over.stdout
    within = _run(tmp_path, "-m", "not slow", fast=2)
    assert within.returncode == 0, within.stdout + within.stderr
    assert "test_small.py" in within.stdout  # the modules with the most compile time
    assert "test_small.py::test_two_programs" in within.stdout  # and the tests
    over = _run(tmp_path, full=2)
    assert over.returncode == 1, over.stdout + over.stderr
    assert "2 passed" in over.stdout
    assert "total: 3 programs" in over.stdout and "(full suite)" in over.stdout
    assert _run(tmp_path, full=3).returncode == 0


def test_a_partial_run_reports_and_an_explicit_limit_fails_it(tmp_path):
    partial = _run(tmp_path, "-k", "two", fast=1, full=1)
    assert partial.returncode == 0, partial.stdout + partial.stderr
    assert "not enforced on a partial run" in partial.stdout
    limited = _run(tmp_path, "-k", "two", env={"JAXLIE_GEO_TEST_PROGRAM_BUDGET": "1"})
    assert limited.returncode == 1, limited.stdout + limited.stderr
    assert "more than its budget of 1: fails the run" in limited.stdout
