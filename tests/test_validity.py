"""Validity of elements: ``is_valid`` per element, ``check_valid`` through checkify.

References: the norm of the rotation part and the finiteness of the parameters, computed
in float64 NumPy. That the elements the group operations make are valid is a property of
the regime batch (``test_axioms``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import (
    over_groups,
    over_groups_dtypes,
    random_element,
    random_tangent,
    rotation_params,
)
from jax.experimental import checkify

import jaxlie_geo
from jaxlie_geo import SO3


def _default_atol(dtype):
    return float(np.sqrt(np.finfo(dtype).eps))


def _scale_rotation(T, factors):
    """``T`` with its rotation part multiplied by ``factors`` (batch shape)."""
    k = rotation_params(type(T))
    p = np.array(T.parameters())
    p[..., :k] *= np.asarray(factors, p.dtype)[..., None]
    return type(T)(jnp.asarray(p))


@over_groups_dtypes
def test_rotation_norm_beyond_atol_is_invalid(G, dtype):
    """A rotation part scaled by 1 ± 2·atol is invalid, by 1 ± atol/2 valid, for the
    default atol (√ε) and an explicit one; only the scaled elements are flagged."""
    T = random_element(G, 2, (6,), dtype)
    for atol in (None, 1e-3):
        a = _default_atol(dtype) if atol is None else atol
        factors = np.array([1.0, 1 + 2 * a, 1 - 2 * a, 1 + a / 2, 1 - a / 2, 1.0])
        got = np.asarray(_scale_rotation(T, factors).is_valid(atol))
        np.testing.assert_array_equal(got, [True, False, False, True, True, True])
    assert not np.any(np.asarray(_scale_rotation(T, np.zeros(6)).is_valid()))
    # from atol = 1 on, the lower bound is 0: any finite rotation part of norm ≤ 1 + atol
    assert np.all(np.asarray(_scale_rotation(T, np.full(6, 0.01)).is_valid(1.0)))


@over_groups_dtypes
def test_non_finite_parameters_are_invalid(G, dtype):
    """NaN or ±inf in any parameter (rotation or translation) makes that element invalid,
    and only that one; so does a rotation part whose squared norm overflows."""
    P = G.parameters_dim
    T = random_element(G, 3, (P, 3), dtype)
    p = np.array(T.parameters())
    for j, value in enumerate((np.nan, np.inf, -np.inf)):
        for i in range(P):
            p[i, j, i] = value
    huge = np.array(random_element(G, 4, (), dtype).parameters())
    huge[: rotation_params(G)] = np.finfo(dtype).max / 2
    got = np.asarray(G(jnp.asarray(p)).is_valid())
    assert got.shape == (P, 3) and not np.any(got)
    assert not bool(G(jnp.asarray(huge)).is_valid())
    assert np.all(np.asarray(T.is_valid()))


@over_groups
def test_under_jit_vmap_and_grad(G):
    """``is_valid`` gives the same booleans under ``jit`` and ``vmap`` as eagerly, for batch
    axes (2, 3); ``atol`` may be traced or broadcast against the batch axes; a gradient
    through a function that selects on it is the one of the selected branch."""
    dtype = np.float32
    factors = np.array([[1.0, 1.01, 1.0], [np.nan, 1.0, 1.0 + 1e-4]])
    T = _scale_rotation(random_element(G, 5, (2, 3), dtype), factors)
    want = np.array([[True, False, True], [False, True, True]])
    np.testing.assert_array_equal(np.asarray(T.is_valid()), want)
    np.testing.assert_array_equal(np.asarray(jax.jit(lambda T: T.is_valid())(T)), want)
    np.testing.assert_array_equal(np.asarray(jax.vmap(lambda T: T.is_valid())(T)), want)
    per_column = jnp.asarray([1e-5, 0.1, 1e-5], dtype)  # broadcasts against (2, 3)
    np.testing.assert_array_equal(
        np.asarray(jax.jit(lambda T, a: T.is_valid(a))(T, per_column)),
        [[True, True, True], [False, True, False]],
    )
    x = jnp.asarray(random_tangent(G, 6, (), dtype))

    def f(x):
        E = G.exp(x)
        return jnp.where(E.is_valid(), jnp.sum(E.log() ** 2), 0.0)

    np.testing.assert_allclose(np.asarray(jax.grad(f)(x)), np.asarray(2 * x), rtol=1e-4, atol=1e-5)


@over_groups_dtypes
def test_check_valid_under_checkify(G, dtype):
    """``check_valid`` inside a jitted, checkified function passes valid elements and
    reports invalid ones (a non-unit rotation, NaN) with the group's name, their count and
    the first one's batch index; under ``vmap`` too. Eagerly it raises at once."""

    @jax.jit
    def f(T):
        jaxlie_geo.check_valid(T)
        return T.log()

    checked = checkify.checkify(f)
    T = random_element(G, 7, (2, 3), dtype)
    err, out = checked(T)
    assert err.get() is None and out.shape == (2, 3, G.tangent_dim)
    err.throw()
    bad = _scale_rotation(T, np.array([[1.0, 1.0, 1.0], [1.0, 1.1, np.nan]]))
    err, _ = checked(bad)
    msg = err.get()
    assert msg is not None and f"2 of 6 {G.__name__} elements are invalid" in msg, msg
    assert "at batch index [1, 1]" in msg, msg
    with pytest.raises(checkify.JaxRuntimeError, match=G.__name__):
        err.throw()
    err, _ = checkify.checkify(jax.vmap(f))(bad)
    assert err.get() is not None and G.__name__ in err.get()
    jaxlie_geo.check_valid(T)  # eager, valid: nothing happens
    with pytest.raises(checkify.JaxRuntimeError, match="1 of 1"):
        jaxlie_geo.check_valid(bad[1, 2])
    with pytest.raises(checkify.JaxRuntimeError, match="1 of 1"):
        jaxlie_geo.check_valid(T[0, 0], atol=-1.0)


def test_check_valid_names_a_wrong_argument():
    """A non-element raises TypeError at trace time, naming the function and argument."""
    with pytest.raises(TypeError, match="check_valid: `x` must be MatrixLieGroup"):
        jaxlie_geo.check_valid(jnp.ones(4))
    jaxlie_geo.check_valid(SO3.identity((0,)))  # an empty batch has nothing to check


def test_default_atol_per_dtype():
    """The default tolerance is √ε: a float32 element cast to float64 is off by up to a
    few float32 ulp and fails float64's default until normalized; it passes float32's."""
    T = random_element(SO3, 8, (1000,), np.float32)
    up = SO3(T.parameters().astype(jnp.float64))
    dev = np.abs(np.linalg.norm(np.asarray(up.parameters()), axis=-1) - 1)
    valid = np.asarray(up.is_valid())
    np.testing.assert_array_equal(valid, dev <= _default_atol(np.float64) * (1 + 1e-12))
    assert not np.all(valid)
    assert np.all(np.asarray(up.normalize().is_valid()))
    assert np.all(np.asarray(T.is_valid()))
