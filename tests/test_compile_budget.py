"""The compile budget (``tests/_compile_budget.py``) fails a run that compiles more programs
than its limit, and passes one within it: a small suite run in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

_SUITE = """
import jax
import jax.numpy as jnp
import numpy as np

def test_three_programs():
    x = np.arange(3.0)
    for f in (jnp.sin, jnp.cos, jnp.tanh):
        jax.jit(f)(x).block_until_ready()
"""


def _run(tmp_path: Path, budget: int) -> subprocess.CompletedProcess:
    (tmp_path / "test_small.py").write_text(_SUITE)
    env = {
        **os.environ,
        "PYTHONPATH": str(Path(__file__).parent),
        "JAXLIE_GEO_TEST_PROGRAM_BUDGET": str(budget),
        "JAX_ENABLE_COMPILATION_CACHE": "false",
    }
    cmd = [sys.executable, "-m", "pytest", "-p", "_compile_budget", "-q", "-p", "no:cacheprovider"]
    return subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)


def test_budget_fails_a_run_beyond_it_and_passes_one_within(tmp_path):
    over = _run(tmp_path, budget=2)
    assert over.returncode == 1, over.stdout + over.stderr
    assert "1 passed" in over.stdout
    assert "total: 3 programs" in over.stdout
    assert "more than its budget of 2: fails the run" in over.stdout
    within = _run(tmp_path, budget=3)
    assert within.returncode == 0, within.stdout + within.stderr
    assert "total: 3 programs" in within.stdout
    assert "test_small.py" in within.stdout  # the modules with the most compile time
