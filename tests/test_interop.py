"""jaxlie_geo.interop: our elements handed to jaxlie 1.5 and back, unchanged; and jaxlie_geo
installed under jaxlie's name for a library built on jaxlie."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import jaxlie
import numpy as np
import pytest
from conftest import (
    GROUPS,
    JAXLIE_GROUPS,
    group_name,
    over_jaxlie_groups_dtypes,
    random_element,
    random_points,
    to_np,
)

import jaxlie_geo
from jaxlie_geo.interop import from_jaxlie, to_jaxlie

REPO = Path(__file__).resolve().parents[1]


@over_jaxlie_groups_dtypes
def test_round_trip_keeps_parameters_bit_for_bit(G, dtype):
    """``to_jaxlie`` and ``from_jaxlie`` give the other library's class with the same batch,
    dtype and parameters, bit for bit."""
    T = random_element(G, 3, (2, 3), dtype)
    J = to_jaxlie(T)
    assert type(J) is getattr(jaxlie, G.__name__)
    assert J.get_batch_axes() == (2, 3)
    np.testing.assert_array_equal(to_np(J.parameters()), to_np(T.parameters()))
    back = from_jaxlie(J)
    assert type(back) is G
    np.testing.assert_array_equal(to_np(back.parameters()), to_np(T.parameters()))
    assert back.parameters().dtype == dtype


@over_jaxlie_groups_dtypes
def test_jaxlie_computes_the_same_transform(G, dtype):
    """A library that only knows jaxlie acts with our pose as we do."""
    T = random_element(G, 5, (4,), dtype)
    p = random_points(G, 5, (4,), dtype)
    tol = 1e-5 if dtype == jnp.float32 else 1e-12
    np.testing.assert_allclose(to_np(to_jaxlie(T) @ p), to_np(T @ p), rtol=tol, atol=tol)
    np.testing.assert_allclose(
        to_np(to_jaxlie(T).as_matrix()), to_np(T.as_matrix()), rtol=tol, atol=tol
    )


def test_pytrees_and_jit():
    """Both conversions map over pytrees (leaving other leaves alone) and run under jit."""
    tree = {
        "poses": [random_element(G, i, (2,), jnp.float64) for i, G in enumerate(JAXLIE_GROUPS)],
        "weight": jnp.arange(3.0),
        "name_free": (1.5, None),
    }
    converted = jax.jit(to_jaxlie)(tree)
    for ours, theirs in zip(tree["poses"], converted["poses"]):
        assert isinstance(theirs, jaxlie.MatrixLieGroup)
        assert type(theirs).__name__ == type(ours).__name__
    np.testing.assert_array_equal(to_np(converted["weight"]), to_np(tree["weight"]))
    assert converted["name_free"] == (1.5, None)
    back = jax.jit(from_jaxlie)(converted)
    for ours, again in zip(tree["poses"], back["poses"]):
        assert type(again) is type(ours)
        np.testing.assert_array_equal(to_np(again.parameters()), to_np(ours.parameters()))


def test_elements_of_neither_library_pass_through():
    """Arrays, and elements already of the target library, pass through unchanged."""
    assert to_jaxlie(jnp.ones(3)).shape == (3,)
    assert from_jaxlie(jaxlie_geo.SO3.identity()).wxyz.shape == (4,)  # ours stay ours
    assert isinstance(to_jaxlie(jaxlie.SO3.identity()), jaxlie.SO3)  # theirs stay theirs


def test_round_trip_keeps_negative_zeros():
    """Re-wrapping does no arithmetic: −0.0 components (an inverse's conjugate makes them)
    keep their sign bit both ways (assert_array_equal treats −0.0 == +0.0)."""
    for T in (jaxlie_geo.SO3.identity().inverse(), jaxlie_geo.SE3.identity().inverse()):
        p = np.asarray(T.parameters())
        assert np.signbit(p).any()
        for back in (from_jaxlie(to_jaxlie(T)).parameters(), to_jaxlie(T).parameters()):
            np.testing.assert_array_equal(
                np.asarray(back).view(np.uint32 if p.dtype == np.float32 else np.uint64),
                p.view(np.uint32 if p.dtype == np.float32 else np.uint64),
            )


@pytest.mark.parametrize("G", [G for G in GROUPS if G not in JAXLIE_GROUPS], ids=group_name)
def test_groups_without_a_jaxlie_counterpart_raise(G):
    """jaxlie has no Sim(3) or SE_2(3): ``to_jaxlie`` names the group in a ``TypeError``,
    also inside a pytree, rather than converting it to something else."""
    T = G.identity()
    for tree in (T, {"a": [T]}):
        with pytest.raises(TypeError, match=f"no counterpart of {G.__name__}"):
            to_jaxlie(tree)


# A library built on jaxlie, as jaxls and pyroki are: it imports jaxlie and its submodules,
# checks for jaxlie's class inside its own code, and captures a pose in a jitted closure.
_STAND_IN_LIBRARY = """
import jax
import jaxlie
import jaxlie.hints
import jaxlie.manifold
import jaxlie.utils


def checked(x):
    if not isinstance(x, jaxlie.SE3):
        raise TypeError(f"expected a jaxlie.SE3, got {type(x).__module__}.{type(x).__name__}")
    return x


def transformer(T: jaxlie.SE3):
    @jax.jit
    def apply(points: jaxlie.hints.Array):
        return checked(T) @ points

    return apply


def step(T: jaxlie.SE3, delta):
    return jaxlie.manifold.rplus(checked(T), delta)
"""

_USER_PROGRAM = """
import json, sys
import jaxlie_geo.interop
jaxlie_geo.interop.install_as_jaxlie()
jaxlie_geo.interop.install_as_jaxlie()  # a second call does nothing
import numpy as np
import jax.numpy as jnp
import jaxlie_geo
import stand_in

T = jaxlie_geo.SE3.exp(jnp.asarray([0.3, -1.0, 2.0, 0.4, -0.2, 0.9]))
points = jnp.asarray([[1.0, 2.0, 3.0], [-0.5, 0.0, 4.0]])
moved = stand_in.transformer(T)(points)
reference = points @ np.asarray(T.rotation().as_matrix()).T + np.asarray(T.translation())
stepped = stand_in.step(T, jnp.full(6, 0.1))
try:
    import jaxlie.not_a_module
    missing = "imported"
except ModuleNotFoundError as error:
    missing = str(error)
print(json.dumps({
    "apply_error": float(np.max(np.abs(np.asarray(moved) - reference))),
    "stepped_type": type(stepped).__module__ + "." + type(stepped).__name__,
    "step_error": float(np.max(np.abs(np.asarray(
        (stepped.parameters() - (T @ jaxlie_geo.SE3.exp(jnp.full(6, 0.1))).parameters()))))),
    "same_modules": [stand_in.jaxlie is jaxlie_geo,
                     stand_in.jaxlie.manifold is jaxlie_geo.manifold,
                     sys.modules["jaxlie.hints"] is jaxlie_geo.hints,
                     sys.modules["jaxlie.utils"] is jaxlie_geo.utils],
    "to_jaxlie_is_identity": jaxlie_geo.interop.to_jaxlie(T) is T,
    "missing": missing,
}))
"""


def _run_python(code: str, cwd) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(cwd), str(REPO)])}
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


def test_install_as_jaxlie_reaches_a_library_built_on_jaxlie(tmp_path):
    """In a fresh interpreter, ``install_as_jaxlie()`` before the import of a library built on
    jaxlie makes its ``isinstance(x, jaxlie.SE3)`` checks accept jaxlie_geo's elements, its
    jitted closure over a pose transform points as the rotation matrix and translation do,
    and its ``jaxlie.manifold`` be ours; an unknown ``jaxlie.<name>`` is a clear error."""
    (tmp_path / "stand_in.py").write_text(_STAND_IN_LIBRARY)
    proc = _run_python(_USER_PROGRAM, tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["apply_error"] < 1e-5
    assert out["stepped_type"] == "jaxlie_geo._se3.SE3"
    assert out["step_error"] < 1e-6
    assert out["same_modules"] == [True, True, True, True]
    assert out["to_jaxlie_is_identity"]
    assert "jaxlie.not_a_module" in out["missing"] and "install_as_jaxlie" in out["missing"]


def test_install_as_jaxlie_refuses_after_jaxlie_was_imported(tmp_path):
    """With the real jaxlie already imported, the call raises, naming where it came from,
    and leaves ``jaxlie`` as it was."""
    code = (
        "import jaxlie, jaxlie_geo.interop\n"
        "try:\n"
        "    jaxlie_geo.interop.install_as_jaxlie()\n"
        "except RuntimeError as error:\n"
        "    print('refused:', error)\n"
        "import jaxlie_geo\n"
        "print('unchanged:', jaxlie is not jaxlie_geo and 'site-packages' in jaxlie.__file__)\n"
    )
    proc = _run_python(code, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "refused: install_as_jaxlie: jaxlie is already imported" in proc.stdout
    assert "before anything imports jaxlie" in proc.stdout
    assert "unchanged: True" in proc.stdout
