"""Run jaxlie 1.5's own test suite against jaxlie_geo (``import jaxlie_geo as jaxlie``).

    python -m benchmarks.jaxlie_suite                 # against jaxlie_geo
    python -m benchmarks.jaxlie_suite --target jaxlie # the same harness against jaxlie itself
    python -m benchmarks.jaxlie_suite --sdist PATH    # a jaxlie-1.5.x .tar.gz already at hand

Kept out of our test suite because it downloads jaxlie's source distribution from the
package registry (``pip download jaxlie==1.5.* --no-binary :all:``). The sdist ships the
test modules but not the helper module they import (``tests/utils.py``), so this script
writes one, below: float64 (x64 on), groups and batch shapes as parameters, hypothesis
seeding NumPy's global generator, elements from ``sample_uniform``, comparisons by
``numpy.testing.assert_allclose`` (1e-8), a central-difference Jacobian. A ``conftest.py``
calls ``jaxlie_geo.interop.install_as_jaxlie()``, so every jaxlie module name (``jaxlie``,
``jaxlie.manifold``, ``jaxlie.hints``, ``jaxlie.utils``) is jaxlie_geo's.

Left out: ``test_jac_left.py``, which calls jaxlie's private ``_SO3_jac_left``, and the
timing test (``test_jlog_runtime``), whose thresholds are for another machine. Run with
``--target jaxlie`` first: the harness itself must pass there. Extra arguments after ``--``
go to pytest (for example ``-- -n 2``).
"""

from __future__ import annotations

import argparse
import glob
import os
import subprocess
import sys
import tarfile
import tempfile

HELPERS = '''"""Test helpers for jaxlie's test modules (written by jaxlie_geo's
benchmarks/jaxlie_suite.py)."""
import numpy as onp
import jax
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxlie

GROUPS = [jaxlie.SO2, jaxlie.SE2, jaxlie.SO3, jaxlie.SE3]
BATCH_AXES = [(), (1,), (3, 1, 2, 1)]
# Double precision, which the tests' tolerances (down to 1e-5 on Jacobians) and the
# central differences below need.
jax.config.update("jax_enable_x64", True)
RTOL = ATOL = 1e-8


def general_group_test(f=None, max_examples=30):
    """Parametrise ``f(Group, batch_axes)`` over every group and batch shape; hypothesis
    seeds NumPy's global generator (``sample_transform`` and the tests draw from it)."""
    if f is None:
        return lambda f: general_group_test(f, max_examples=max_examples)

    def run(Group, batch_axes, _random_module):
        return f(Group, batch_axes)

    run.__name__ = f.__name__
    run.__doc__ = f.__doc__
    run = settings(deadline=None, max_examples=max_examples)(
        given(_random_module=st.random_module())(run))
    run = pytest.mark.parametrize("batch_axes", BATCH_AXES, ids=str)(run)
    return pytest.mark.parametrize("Group", GROUPS, ids=lambda G: G.__name__)(run)


def general_group_test_faster(f=None, max_examples=5):
    return general_group_test(f, max_examples=max_examples)


def sample_transform(Group, batch_axes=(), dtype=None):
    key = jax.random.PRNGKey(onp.random.randint(0, 2**31 - 1))
    if dtype is None:
        return Group.sample_uniform(key, batch_axes=batch_axes)
    return Group.sample_uniform(key, batch_axes=batch_axes, dtype=dtype)


def assert_arrays_close(*arrays, rtol=RTOL, atol=ATOL):
    first = onp.asarray(arrays[0])
    for other in arrays[1:]:
        onp.testing.assert_allclose(first, onp.asarray(other), rtol=rtol, atol=atol)


def assert_transforms_close(a, b):
    """Same parameters, a quaternion's sign aside (q and -q are one rotation), and the same
    matrix."""
    assert type(a) is type(b), (type(a), type(b))
    pa, pb = onp.array(a.parameters()), onp.array(b.parameters())
    if type(a) in (jaxlie.SO3, jaxlie.SE3):  # quaternion first: wxyz, wxyz_xyz
        sign = onp.where(onp.sum(pa[..., :4] * pb[..., :4], axis=-1) < 0, -1.0, 1.0)
        pb[..., :4] *= sign[..., None]
    assert_arrays_close(pa, pb)
    assert_arrays_close(a.as_matrix(), b.as_matrix())


def jacnumerical(f, eps=1e-5):
    """Central-difference Jacobian of ``f`` at a 1-D primal: (*out, n)."""
    def jac(primal):
        primal = onp.asarray(primal, dtype=onp.float64)
        cols = []
        for i in range(primal.shape[-1]):
            step = onp.zeros_like(primal)
            step[i] = eps
            hi = onp.asarray(f(primal + step), dtype=onp.float64)
            lo = onp.asarray(f(primal - step), dtype=onp.float64)
            cols.append((hi - lo) / (2 * eps))
        return onp.stack(cols, axis=-1)
    return jac
'''

CONFTEST = """import os

if os.environ["JAXLIE_SUITE_TARGET"] == "jaxlie_geo":
    import jaxlie_geo.interop

    jaxlie_geo.interop.install_as_jaxlie()
"""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", choices=["jaxlie_geo", "jaxlie"], default="jaxlie_geo")
    parser.add_argument("--sdist", help="a jaxlie-1.5.x source distribution (.tar.gz)")
    parser.add_argument("pytest_args", nargs="*", help="passed to pytest (after --)")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        sdist = args.sdist
        if sdist is None:
            pip = "pip download -q --no-deps --no-binary :all: -d".split()
            subprocess.run([sys.executable, "-m", *pip, tmp, "jaxlie==1.5.*"], check=True)
            sdist = glob.glob(os.path.join(tmp, "jaxlie-*.tar.gz"))[0]
        with tarfile.open(sdist) as tar:
            members = [m for m in tar.getmembers() if "/tests/" in m.name and m.isfile()]
            # the "data" filter (Python >= 3.10.12 / 3.11.4) refuses links and absolute paths
            safe = {"filter": "data"} if hasattr(tarfile, "data_filter") else {}
            tar.extractall(tmp, members=members, **safe)
        tests = glob.glob(os.path.join(tmp, "*", "tests"))[0]
        print(f"{os.path.basename(sdist)}: {len(members)} test files, target {args.target}")
        with open(os.path.join(tests, "utils.py"), "w") as f:
            f.write(HELPERS)
        with open(os.path.join(tests, "conftest.py"), "w") as f:
            f.write(CONFTEST)
        with open(os.path.join(tmp, "pytest.ini"), "w") as f:
            f.write("[pytest]\n")  # keep our pyproject's pytest settings out
        ini = os.path.join(tmp, "pytest.ini")
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-c", ini]
        cmd += ["--rootdir", tests, tests, "--ignore", os.path.join(tests, "test_jac_left.py")]
        cmd += ["--deselect", "test_jlog.py::test_jlog_runtime", *args.pytest_args]
        env = {**os.environ, "JAXLIE_SUITE_TARGET": args.target}
        return subprocess.run(cmd, env=env, cwd=tests).returncode


if __name__ == "__main__":
    sys.exit(main())
