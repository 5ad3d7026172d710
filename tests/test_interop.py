"""jaxlie_geo.interop: our elements handed to jaxlie 1.5 and back, unchanged."""

from __future__ import annotations

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
