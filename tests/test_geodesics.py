"""Interpolation, geodesics and ``between`` on every group × batch shape × dtype.

References: the geodesic written with scipy's ``expm`` in its body and left forms,
T expm(t log(T⁻¹U)) and expm(t log(U T⁻¹)) T (built from U = T exp(x), whose relative log
is x, so no library log enters the reference), and the group product a⁻¹ b.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import (
    GROUPS,
    all_close_as_matrices,
    assert_close,
    hat_ref,
    over_cases,
    over_groups,
    over_groups_dtypes,
    random_element,
    random_tangent,
    seeds,
    to_np,
)
from hypothesis import given
from hypothesis import strategies as st

import jaxlie_geo


@jax.jit
def _call_path(path, t):
    """A geodesic called under jit (it is a pytree argument)."""
    return path(t)


@over_cases
@given(seed=seeds)
def test_interpolate_endpoints(G, batch, dtype, seed):
    """interpolate(U, 0) == T and interpolate(U, 1) == U, as matrices."""
    T = random_element(G, seed, batch, dtype)
    U = random_element(G, seed + 1, batch, dtype)
    T0 = T.interpolate(U, 0.0)
    T1 = T.interpolate(U, 1.0)
    assert T0.parameters().dtype == dtype and T0.get_batch_axes() == batch
    all_close_as_matrices(T0, T, dtype, 2)
    all_close_as_matrices(T1, U, dtype, 16)


def _pair_away_from_pi(G, seed, batch, dtype):
    """T uniform, U = T exp(x) with |rotation angle of x| ≤ 3 (relative rotation away
    from π, where the geodesic is unique)."""
    T = random_element(G, seed, batch, dtype)
    x = random_tangent(G, seed, batch, dtype, max_angle=3.0)
    return T, T @ G.exp(x), x


def _geodesic_ref(MT, x, G, t):
    """Body and left forms of the geodesic through MT with body velocity x, with scipy:
    MT expm(t hat(x)) and expm(t MT hat(x) MT⁻¹) MT (hat from the generators), float64.
    For U = T exp(x) with |angle(x)| < π, x is log(T⁻¹U)."""
    import scipy.linalg

    MT = to_np(MT)
    X = hat_ref(G, x)
    X = np.broadcast_to(X, MT.shape)
    t = np.broadcast_to(np.asarray(t, np.float64), MT.shape[:-2])
    body = np.empty_like(MT)
    left = np.empty_like(MT)
    for idx in np.ndindex(MT.shape[:-2]):
        A = MT[idx]
        body[idx] = A @ scipy.linalg.expm(t[idx] * X[idx])
        left[idx] = scipy.linalg.expm(t[idx] * (A @ X[idx] @ np.linalg.inv(A))) @ A
    return body, left


@over_cases
@given(seed=seeds, t=st.sampled_from([0.5, 0.25, 0.9, -0.3, 1.7]))
def test_interpolate_is_geodesic(G, batch, dtype, seed, t):
    """T.interpolate(U, t) == T expm(t log(T⁻¹U)) == expm(t log(U T⁻¹)) T,
    away from a relative rotation of π; t = 0.5 is the geodesic midpoint. (Reference:
    U = T exp(x), whose relative log is x, and scipy's expm.)"""
    T, U, x = _pair_away_from_pi(G, seed, batch, dtype)
    got = T.interpolate(U, t)
    assert got.parameters().dtype == dtype and got.get_batch_axes() == batch
    body, left = _geodesic_ref(T.as_matrix(), x, G, t)
    assert_close(got.as_matrix(), body, dtype, 32)
    assert_close(got.as_matrix(), left, dtype, 32)


@over_cases
@given(seed=seeds, t=st.floats(-1.0, 2.0))
def test_geodesic_path_equals_interpolate(G, batch, dtype, seed, t):
    """geodesic(T, U)(t) == T.interpolate(U, t), and the path goes through jit as a pytree."""
    T = random_element(G, seed, batch, dtype)
    U = random_element(G, seed + 1, batch, dtype)
    path = jaxlie_geo.geodesic(T, U)
    got = path(t)
    assert got.parameters().dtype == dtype
    assert_close(got.parameters(), T.interpolate(U, t).parameters(), dtype)
    # the path is a pytree: it goes through jit.
    jitted = _call_path(path, np.asarray(t, dtype))
    assert_close(jitted.parameters(), got.parameters(), dtype, 2)


@over_groups_dtypes
@given(seed=seeds)
def test_interpolate_time_broadcasting(G, dtype, seed):
    """Times of shape (K,) give K poses, times of shape (K, 1) against endpoints of batch (3,)
    give (K, 3), lists work as arrays, and extrapolation (t = 2) follows the same geodesic
    (scipy reference)."""
    T, U, x = _pair_away_from_pi(G, seed, (), dtype)
    ts = np.asarray([0.0, 0.2, 0.5, 1.0, 2.0], dtype)
    # unbatched endpoints, t of shape (K,) -> K poses
    path = T.interpolate(U, ts)
    assert path.get_batch_axes() == (5,) and path.parameters().dtype == dtype
    # a list of times works as the array does (it raised TracerArrayConversionError)
    assert_close(T.interpolate(U, ts.tolist()).as_matrix(), path.as_matrix(), dtype, 2)
    for k in range(5):
        assert_close(path[k].as_matrix(), T.interpolate(U, float(ts[k])).as_matrix(), dtype, 2)
    # extrapolation t = 2: T exp(2 log(T⁻¹U)) = T exp(2x)
    all_close_as_matrices(path[4], T @ G.exp(2 * x), dtype, 32)
    body, _ = _geodesic_ref(T.as_matrix(), x, G, 2.0)
    assert_close(path[4].as_matrix(), body, dtype, 64)
    # batched endpoints (3,), outer product t[:, None] -> (K, 3)
    Tb, Ub, xb = _pair_away_from_pi(G, seed, (3,), dtype)
    grid = Tb.interpolate(Ub, ts[:, None])
    assert grid.get_batch_axes() == (5, 3) and grid.parameters().dtype == dtype
    MT = np.broadcast_to(to_np(Tb.as_matrix()), (5, 3, G.matrix_dim, G.matrix_dim))
    body, _ = _geodesic_ref(MT, xb, G, np.broadcast_to(to_np(ts)[:, None], (5, 3)))
    assert_close(grid.as_matrix(), body, dtype, 64)
    # geodesic object with the same broadcasting
    assert_close(jaxlie_geo.geodesic(Tb, Ub)(ts[:, None]).parameters(), grid.parameters(), dtype)


@over_groups
def test_between_is_the_relative_element(G):
    """``between(a, b)`` is ``a⁻¹ @ b`` (the same rotation, translations to rounding near the
    origin; accuracy far from it: test_accuracy), broadcasts batch axes, and refuses another
    group or a bare array."""
    a = random_element(G, 1, (3, 1), np.float64)
    b = random_element(G, 2, (4,), np.float64)
    E = jaxlie_geo.between(a, b)
    assert E.get_batch_axes() == (3, 4)
    assert_close(E.as_matrix(), (a.inverse() @ b).as_matrix(), np.float64, 8)
    want = jnp.broadcast_to(b.as_matrix(), (3, 4, G.matrix_dim, G.matrix_dim))
    assert_close((a @ E).as_matrix(), want, np.float64, 8)
    other = GROUPS[(GROUPS.index(G) + 1) % len(GROUPS)]
    with pytest.raises(TypeError, match=f"expected {G.__name__}, got {other.__name__}"):
        jaxlie_geo.between(a, other.identity())
    with pytest.raises(TypeError, match="expected a group element"):
        jaxlie_geo.between(a.parameters(), b)
