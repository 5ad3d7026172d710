"""dtype in = dtype out: every public function, at float32 and float64, returns the dtype it
was given (no silent promotion to float64 under x64, no float32 constants leaking into
float64); integer input is promoted to a float; half precision stays finite and close to
float32; a NumPy float64 time promotes as NumPy does.

References: the dtypes of the inputs, ``jnp.issubdtype`` for the kinds, and for values the
same computation in float32 or float64 (numpy for ``normalize``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _calls import context, public_calls
from conftest import (
    GROUPS,
    HALF_DTYPES,
    LAYOUT,
    assert_close,
    dtype_name,
    identity_matrices,
    is_se,
    over_groups,
    over_quaternion_groups,
    param_dtypes,
    random_element,
    random_tangent,
    rotation_params,
    to_np,
)

import jaxlie_geo
from jaxlie_geo import SE2, SO2, SO3

# ---------------------------------------------------------------------------------
# Floating-point inputs.

_DTYPE_CASES = [
    pytest.param(G, name, d, id=f"{G.__name__}-{name}-{jnp.dtype(d).name}")
    for G in GROUPS
    for name in public_calls(G)
    for d in (jnp.float32, jnp.float64)
]


@pytest.mark.parametrize(("G", "name", "dtype"), _DTYPE_CASES)
def test_dtype_in_equals_dtype_out(G, name, dtype):
    """Every array leaf of the result has the input's dtype, and is finite."""
    out = public_calls(G)[name](context(G, dtype))
    dtypes = param_dtypes(out)
    assert dtypes == {jnp.dtype(dtype)}, f"{G.__name__}.{name}: {dtype} in, {dtypes} out"
    for leaf in jax.tree.leaves(out):
        assert np.all(np.isfinite(to_np(leaf)))


# ---------------------------------------------------------------------------------
# Integer inputs.


@over_groups
def test_integer_inputs_promoted_to_float(G):
    """Integer tangents, matrices, points and translations give float results with the exact
    values (the identity, the integers themselves)."""
    k = G.tangent_dim
    T = G.exp(np.zeros((3, k), np.int32))
    assert jnp.issubdtype(T.parameters().dtype, jnp.floating)
    np.testing.assert_array_equal(to_np(T.as_matrix()), identity_matrices(G, (3,)))
    M = G.from_matrix(np.eye(G.matrix_dim, dtype=np.int64))
    assert jnp.issubdtype(M.parameters().dtype, jnp.floating)
    np.testing.assert_array_equal(to_np(M.as_matrix()), np.eye(G.matrix_dim))
    assert jnp.issubdtype(G.hat(np.arange(k)).dtype, jnp.floating)
    assert jnp.issubdtype(G.vee(np.zeros((G.matrix_dim,) * 2, np.int32)).dtype, jnp.floating)
    p = np.arange(G.space_dim)
    I = G.identity()
    out = I.apply(p)
    assert jnp.issubdtype(out.dtype, jnp.floating)
    np.testing.assert_array_equal(to_np(out), p)
    if is_se(G):
        Tt = G.from_translation(np.arange(G.space_dim))
        assert jnp.issubdtype(Tt.parameters().dtype, jnp.floating)
        np.testing.assert_array_equal(to_np(Tt.translation()), np.arange(G.space_dim))


@over_groups
def test_integer_inputs_keep_float32_of_the_element(G):
    """Mixing a float32 element with integer data gives float32, as JAX's promotion does
    (int ⊕ float32 → float32), so dtype in == dtype out also for integer points."""
    T = random_element(G, 3, (3,), jnp.float32)
    out = T.apply(np.ones((3, G.space_dim), np.int32))
    assert out.dtype == jnp.float32, out.dtype
    assert T.interpolate(T, 1).parameters().dtype == jnp.float32
    if is_se(G):
        R = T.rotation()
        E = G.from_rotation_and_translation(R, np.ones((3, G.space_dim), np.int32))
        assert E.parameters().dtype == jnp.float32, E.parameters().dtype


@over_groups
def test_integer_parameters(G):
    """An integer rotation with a float translation keeps the translation's fractions (the
    pair takes the promoted dtype); ``inverse`` and ``@`` of integer elements are exact
    (integer for SO2, SE2 and SO3, the default float for SE3, Sim3 and SE23, as documented)."""
    k = G.parameters_dim
    p = np.zeros(k, np.int32)
    p[0] = 1
    if rotation_params(G) == 4:
        p[:4] = [0, 0, 1, 0]  # a half turn about y, integer
    T = G(jnp.asarray(p))
    if is_se(G):
        t = np.linspace(0.25, 1.5, G.space_dim)
        E = G.from_rotation_and_translation(T.rotation(), t)
        assert jnp.issubdtype(E.parameters().dtype, jnp.floating)
        np.testing.assert_array_equal(to_np(E.translation()), t)
        T = G(
            jnp.asarray(
                np.concatenate([p[: k - G.space_dim], np.arange(1, G.space_dim + 1)]), jnp.int32
            )
        )
    F = G(T.parameters().astype(jnp.float64))
    integer = G in (SO2, SE2, SO3)  # the others' documented exception
    for got, want in ((T.inverse(), F.inverse()), (T @ T, F @ F)):
        dtype = got.parameters().dtype
        assert jnp.issubdtype(dtype, jnp.integer) == integer, dtype
        np.testing.assert_array_equal(to_np(got.parameters()), to_np(want.parameters()))


def test_integer_factories():
    """The group-specific factories (SO2, SE2, SO3) promote integer angles, coordinates and
    quaternions to a float."""
    assert jnp.issubdtype(SO2.from_radians(1).parameters().dtype, jnp.floating)
    assert_close(SO2.from_radians(1).as_radians(), 1.0, jnp.float64)
    E = SE2.from_xy_theta(1, 2, 0)
    assert jnp.issubdtype(E.parameters().dtype, jnp.floating)
    assert_close(E.translation(), [1.0, 2.0], jnp.float64)
    R = SO3.from_z_radians(np.int32(0))
    assert jnp.issubdtype(R.parameters().dtype, jnp.floating)
    Q = SO3.from_quaternion_xyzw(np.array([0, 0, 0, 1]))
    assert jnp.issubdtype(Q.parameters().dtype, jnp.floating)
    np.testing.assert_array_equal(to_np(Q.wxyz), [1.0, 0.0, 0.0, 0.0])


# ---------------------------------------------------------------------------------
# Half precision.


@over_quaternion_groups
@pytest.mark.parametrize("dtype", HALF_DTYPES, ids=dtype_name)
def test_half_precision_exp_is_finite_and_close(G, dtype):
    """exp in float16/bfloat16 is finite and within 4 eps of float32 exp of the rounded
    tangent (4 + |θ|/2 eps beyond π, the conditioning bound), at 0, below π and at θ = 12.
    Groups with a quaternion only."""
    x = random_tangent(G, 5, (6,), np.float32)
    x[0] = 0.0
    rot = LAYOUT[G][0]
    x[1, rot] = [0.0, 0.0, 12.0]  # beyond π
    got = G.exp(jnp.asarray(x, dtype)).parameters()
    assert got.dtype == dtype
    x_rounded = np.asarray(jnp.asarray(x, dtype).astype(jnp.float32))
    ref = to_np(G.exp(x_rounded).parameters())
    eps = float(jnp.finfo(dtype).eps)
    scale = np.maximum(1.0, np.abs(ref))
    theta = np.linalg.norm(x_rounded[:, rot], axis=-1, keepdims=True)
    bound = 4.0 + np.where(theta > np.pi, 0.5 * theta, 0.0)
    assert np.all(np.isfinite(to_np(got.astype(jnp.float32))))
    assert np.all(np.abs(to_np(got.astype(jnp.float32)) - ref) <= bound * eps * scale)


@over_groups
@pytest.mark.parametrize("dtype", HALF_DTYPES, ids=dtype_name)
def test_half_precision_normalize_any_scale(G, dtype):
    """normalize in float16/bfloat16 at every scale of the rotation part whose squares the
    dtype can hold after its power-of-two rescaling, against float64 numpy: float16 once
    returned NaN for rotation parts of norm 0.25 to 0.7 (its rescaled squares overflowed),
    and repr then printed NaN for any float16 element."""
    k = rotation_params(G)
    p = np.asarray(random_element(G, 3, (8,), np.float32).parameters())
    fi = jnp.finfo(dtype)
    for log2 in range(-6, 14, 1):
        scaled = p.copy()
        scaled[..., :k] *= 2.0**log2 * 0.7
        x = jnp.asarray(scaled, dtype)
        xr = np.asarray(x.astype(jnp.float32), np.float64)
        want = xr.copy()
        want[..., :k] /= np.linalg.norm(xr[..., :k], axis=-1, keepdims=True)
        got = G(x).normalize().parameters()
        assert got.dtype == dtype
        err = np.abs(np.asarray(got.astype(jnp.float32), np.float64) - want)
        assert np.all(err <= 2 * float(fi.eps) * np.maximum(1.0, np.abs(want))), (log2, err.max())
    assert "nan" not in repr(G(jnp.asarray(p, dtype)))


# ---------------------------------------------------------------------------------
# Mixed dtypes.


@over_groups
def test_times_follow_numpy_promotion(G):
    """A float64 NumPy ``t`` with float32 elements under x64 gives float64, as documented for
    NumPy float64 inputs (and as ``T @ G.exp(np.zeros(k))`` does)."""
    T, U = random_element(G, 1, (), np.float32), random_element(G, 2, (), np.float32)
    t = np.array([0.25, 0.5], np.float64)
    assert (T @ G.exp(np.zeros(G.tangent_dim))).parameters().dtype == jnp.float64
    for out in (T.interpolate(U, t), jaxlie_geo.geodesic(T, U)(t)):
        assert out.parameters().dtype == jnp.float64, out.parameters().dtype
