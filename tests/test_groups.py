"""The shared property harness: every property on every group × batch shape × dtype.

References are independent of the library: group axioms, the matrix representation
(numpy products and inverses), generators written out in conftest (``hat_ref``),
``scipy.linalg.expm``/``logm`` and automatic differentiation of the library's own
composition (jaxlie's definition of ``jlog``).
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import (
    GROUPS,
    LAYOUT,
    all_close_as_matrices,
    angle_kinds,
    assert_close,
    assert_rel_norm,
    expm_ref,
    hat_ref,
    homogeneous_apply,
    is_se,
    key_of,
    over_cases,
    over_groups,
    over_groups_dtypes,
    param_dtypes,
    random_element,
    random_points,
    random_tangent,
    rotation_angle,
    seeds,
    special_tangents,
    to_np,
    vee_ref,
)
from hypothesis import given
from hypothesis import strategies as st

import jax
import jax.numpy as jnp
import jaxlie_geo
from jaxlie_geo import SE2, SE3, SO2, SO3


def _eye(G, batch):
    return np.broadcast_to(np.eye(G.matrix_dim), (*batch, G.matrix_dim, G.matrix_dim))


@jax.jit
def _jlog_autodiff_flat(T):
    G = type(T)
    zero = jnp.zeros(G.tangent_dim, T.parameters().dtype)
    return jax.jacrev(lambda d: (T @ G.exp(d)).log())(zero)


def _jlog_by_autodiff(T):
    """jaxlie's definition of jlog: d log(T @ exp(δ)) / dδ at δ = 0 (reverse mode, the
    same δ for every batch element, so the Jacobian is per element). The batch is
    flattened and padded to 8 so that one compilation per group and dtype serves every
    batch shape (eager reverse mode would recompile on every call)."""
    G = type(T)
    batch = T.get_batch_axes()
    p = np.asarray(T.parameters()).reshape(-1, G.parameters_dim)
    n = p.shape[0]
    assert n <= 8
    padded = G(jnp.asarray(p[np.arange(8) % n]))
    J = np.asarray(_jlog_autodiff_flat(padded))[:n]
    return J.reshape(*batch, G.tangent_dim, G.tangent_dim)


@jax.jit
def _call_path(path, t):
    return path(t)


# ---------------------------------------------------------------------------------
# Group axioms.


@over_cases
@given(seed=seeds)
def test_identity_laws(G, batch, dtype, seed):
    T = random_element(G, seed, batch, dtype)
    I_batched = G.identity(batch, dtype=dtype)
    I_single = G.identity(dtype=dtype)
    assert I_batched.get_batch_axes() == batch
    assert I_batched.parameters().dtype == dtype
    np.testing.assert_array_equal(to_np(I_batched.as_matrix()), _eye(G, batch))
    for I in (I_batched, I_single):
        all_close_as_matrices(T @ I, T, dtype)
        all_close_as_matrices(I @ T, T, dtype)
    np.testing.assert_array_equal(to_np(I_batched.log()), np.zeros((*batch, G.tangent_dim)))
    np.testing.assert_array_equal(
        to_np(G.exp(jnp.zeros((*batch, G.tangent_dim), dtype)).as_matrix()), _eye(G, batch)
    )
    np.testing.assert_array_equal(to_np(I_batched.inverse().as_matrix()), _eye(G, batch))


@over_cases
@given(seed=seeds)
def test_inverse_laws(G, batch, dtype, seed):
    T = random_element(G, seed, batch, dtype)
    eye = _eye(G, batch)
    assert_close((T @ T.inverse()).as_matrix(), eye, dtype, 2)
    assert_close((T.inverse() @ T).as_matrix(), eye, dtype, 2)
    all_close_as_matrices(T.inverse().inverse(), T, dtype, 2)
    assert T.inverse().get_batch_axes() == batch


@over_cases
@given(seed=seeds)
def test_associativity(G, batch, dtype, seed):
    T, U, V = (random_element(G, seed + i, batch, dtype) for i in range(3))
    all_close_as_matrices((T @ U) @ V, T @ (U @ V), dtype, 4)


# ---------------------------------------------------------------------------------
# exp / log.


@over_cases
@given(seed=seeds, kind=angle_kinds)
def test_log_of_exp_is_identity(G, batch, dtype, seed, kind):
    """log(exp(x)) == x for |rotation angle| < π; the rotation part to a relative error
    of a few ulp (no absolute floor: small angles must not lose digits)."""
    x = random_tangent(G, seed, batch, dtype, kind)
    y = G.exp(x).log()
    assert y.dtype == dtype and y.shape == (*batch, G.tangent_dim)
    assert_close(y, x, dtype, 4)
    rot = LAYOUT[G][0]
    assert_rel_norm(y[..., rot], x[..., rot], dtype, ulps=16)


@over_cases
@given(seed=seeds)
def test_exp_of_log_is_identity(G, batch, dtype, seed):
    T = random_element(G, seed, batch, dtype)
    x = T.log()
    assert x.dtype == dtype and x.shape == (*batch, G.tangent_dim)
    all_close_as_matrices(G.exp(x), T, dtype, 4)
    # Principal log: rotation angle in [0, π].
    assert np.all(rotation_angle(G, x) <= np.pi * (1 + 4 * float(jnp.finfo(dtype).eps)))


@over_groups_dtypes
def test_exp_of_log_special_elements(G, dtype):
    """exp(log(T)) == T at zero, 1e-12, pure translations, exactly π (as a float) and
    π − 1e-6, and long translations."""
    T = G.exp(special_tangents(G, dtype))
    x = T.log()
    assert np.all(np.isfinite(to_np(x)))
    all_close_as_matrices(G.exp(x), T, dtype, 8)
    assert np.all(rotation_angle(G, x) <= np.pi * (1 + 4 * float(jnp.finfo(dtype).eps)))


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64], ids=lambda d: jnp.dtype(d).name)
def test_exp_at_enormous_angles(dtype):
    """Rotation angles up to where θ² overflows keep the quaternion within 2 eps of mpmath
    (the angle is the exact float given); beyond, SO3/SE3 exp give NaN, as documented
    (SO2/SE2 take the angle directly and stay accurate)."""
    import mpmath

    mpmath.mp.dps = 60
    eps = float(jnp.finfo(dtype).eps)
    below, above = (1e19, 1e20) if dtype == jnp.float32 else (1e150, 1e160)
    for th in (1e5, 1e10, below, above):
        t = float(np.dtype(dtype).type(th))
        half = mpmath.mpf(t) / 2
        want3 = np.array([float(mpmath.cos(half)), float(mpmath.sin(half))])
        want2 = np.array([float(mpmath.cos(2 * half)), float(mpmath.sin(2 * half))])
        so3 = to_np(SO3.exp(np.array([0.0, t, 0.0], dtype)).wxyz)[[0, 2]]
        se3 = to_np(SE3.exp(np.array([1.0, 2.0, 3.0, 0.0, t, 0.0], dtype)).wxyz_xyz)[[0, 2]]
        so2 = to_np(SO2.exp(np.array([t], dtype)).unit_complex)
        se2 = to_np(SE2.exp(np.array([0.0, 0.0, t], dtype)).unit_complex_xy)[:2]
        for got, want in ((so2, want2), (se2, want2)) + (((so3, want3), (se3, want3)) if th < above else ()):
            np.testing.assert_allclose(got, want, rtol=0, atol=2 * eps, err_msg=f"θ = {t:g}")
        if th == above:
            assert np.isnan(so3).all() and np.isnan(se3).all()


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64], ids=lambda d: jnp.dtype(d).name)
def test_log_is_scale_invariant_over_the_documented_norms(dtype):
    """_scalar.atan2_over: 1e-15 < ‖q‖ < 4e18 in float32, 1e-145 < ‖q‖ < 1e153 in float64
    (below, the squares of small components flush to zero; above, (w + r)² overflows).
    The rotation, and so the log, depends on q's direction only; SE3.log's translation
    part once carried a stray 1/‖q‖ (exp(log T) off by 0.5 at ‖q‖ = 2). The 5th and 6th
    rows have a small component (0.05, 0.0005): at 1e-18 the first read 8e3 ulp wrong."""
    small, big = (1e-15, 4e18) if dtype == jnp.float32 else (1e-145, 1e153)
    q = np.array([[0.6, 0.8, 0.0, 0.0], [0.0, 0.0, 0.6, -0.8], [1.0, 0.0, 0.0, 0.0]], dtype)
    q = np.concatenate([q, to_np(SO3.exp(np.array([[0.3, -0.5, 0.9], [0.3, 0.2, -0.1],
                                                   [3.1, 0.001, 0.2]], dtype)).wxyz)]).astype(dtype)
    t = np.array([[1.0, -2.0, 0.5]] * len(q), dtype)
    so3, se3 = to_np(SO3(q).log()), to_np(SE3(np.concatenate([q, t], -1)).log())
    eps = float(jnp.finfo(dtype).eps)
    for scale in (small, 1e-3, 0.5, 1.001, 2.0, 1e3, big):
        np.testing.assert_allclose(to_np(SO3(q * scale).log()), so3, rtol=0, atol=8 * eps,
                                   err_msg=f"‖q‖ = {scale:g}")
        if 1e-3 <= scale <= 1e3:
            np.testing.assert_allclose(to_np(SE3(np.concatenate([q * scale, t], -1)).log()), se3,
                                       rtol=0, atol=16 * eps, err_msg=f"‖q‖ = {scale:g}")


@pytest.mark.parametrize("G", [SO3, SE3], ids=lambda G: G.__name__)
@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64], ids=lambda d: jnp.dtype(d).name)
@given(seed=seeds)
def test_log_is_independent_of_quaternion_sign(G, dtype, seed):
    """q and −q are the same rotation: the principal log must not depend on the sign."""
    T = random_element(G, seed, (3,), dtype)
    p = np.array(T.parameters())
    p[..., :4] *= -1
    flipped = G(jnp.asarray(p))
    assert_close(flipped.log(), T.log(), dtype, 2)
    all_close_as_matrices(flipped, T, dtype)


@over_cases
@given(seed=seeds)
def test_exp_matches_scipy_expm(G, batch, dtype, seed):
    """exp(x) == expm(Σ xₖ Eₖ) (scipy, float64, generators from the documented ordering),
    and == expm(hat(x)) with the library's hat; also for angles up to 10."""
    for x in (
        random_tangent(G, seed, batch, dtype),
        random_tangent(G, seed + 1, batch, dtype, max_angle=10.0),
    ):
        got = G.exp(x).as_matrix()
        assert got.dtype == dtype
        factor = 2 + float(np.max(rotation_angle(G, x), initial=0.0))
        assert_close(got, expm_ref(G, x), dtype, factor)
        hat = to_np(G.hat(x))
        flat = hat.reshape(-1, G.matrix_dim, G.matrix_dim)
        import scipy.linalg

        via_hat = np.stack([scipy.linalg.expm(m) for m in flat]).reshape(hat.shape)
        assert_close(got, via_hat, dtype, factor)


# ---------------------------------------------------------------------------------
# Matrices, hat and vee.


@over_cases
@given(seed=seeds)
def test_matrix_round_trip(G, batch, dtype, seed):
    T = random_element(G, seed, batch, dtype)
    M = T.as_matrix()
    assert M.dtype == dtype and M.shape == (*batch, G.matrix_dim, G.matrix_dim)
    back = G.from_matrix(M)
    assert back.parameters().dtype == dtype and back.get_batch_axes() == batch
    assert_close(back.as_matrix(), M, dtype, 2)
    # The matrix is a rigid motion: orthonormal rotation block, det +1, homogeneous row.
    n = G.space_dim
    R = to_np(M)[..., :n, :n]
    assert_close(np.swapaxes(R, -1, -2) @ R, _eye(G, batch)[..., :n, :n], dtype, 2)
    assert_close(np.linalg.det(R), np.ones(batch), dtype, 2)
    if is_se(G):
        bottom = np.zeros((*batch, n + 1))
        bottom[..., n] = 1.0
        np.testing.assert_array_equal(to_np(M)[..., n, :], bottom)


@over_cases
@given(seed=seeds)
def test_from_matrix_of_independent_matrix(G, batch, dtype, seed):
    """from_matrix of scipy's expm (rounded to dtype) reproduces it."""
    x = random_tangent(G, seed, batch, dtype, max_angle=np.pi)
    M = expm_ref(G, x).astype(dtype)
    T = G.from_matrix(M)
    assert T.parameters().dtype == dtype
    assert_close(T.as_matrix(), M, dtype, 4)


@over_cases
@given(seed=seeds)
def test_hat_vee(G, batch, dtype, seed):
    x = random_tangent(G, seed, batch, dtype, max_angle=5.0)
    X = G.hat(x)
    assert X.dtype == dtype and X.shape == (*batch, G.matrix_dim, G.matrix_dim)
    # hat places the coordinates: exact.
    np.testing.assert_array_equal(to_np(X), hat_ref(G, x))
    v = G.vee(X)
    assert v.dtype == dtype and v.shape == (*batch, G.tangent_dim)
    np.testing.assert_array_equal(to_np(v), to_np(x))
    np.testing.assert_array_equal(to_np(G.vee(hat_ref(G, x).astype(dtype))), to_np(x))


@over_cases
@given(seed=seeds)
def test_vee_ignores_symmetric_part_of_rotation_block(G, batch, dtype, seed):
    """vee reads the generator coefficients (documented: the symmetric part is ignored)."""
    x = random_tangent(G, seed, batch, dtype)
    n = G.space_dim
    A = np.random.default_rng(seed).normal(size=(*batch, n, n))
    S = np.zeros((*batch, G.matrix_dim, G.matrix_dim))
    S[..., :n, :n] = A + np.swapaxes(A, -1, -2)
    X = (hat_ref(G, x) + S).astype(dtype)
    assert_close(G.vee(X), vee_ref(G, X), dtype)
    assert_close(G.vee(X), x, dtype, 4)


# ---------------------------------------------------------------------------------
# Adjoint.


@over_cases
@given(seed=seeds)
def test_adjoint_identity(G, batch, dtype, seed):
    """M hat(x) M⁻¹ == hat(Ad x), and T exp(x) == exp(Ad x) T."""
    T = random_element(G, seed, batch, dtype)
    x = random_tangent(G, seed, batch, dtype)
    Ad = T.adjoint()
    assert Ad.dtype == dtype and Ad.shape == (*batch, G.tangent_dim, G.tangent_dim)
    M = to_np(T.as_matrix())
    lhs = M @ hat_ref(G, x) @ np.linalg.inv(M)
    Adx = np.einsum("...ij,...j->...i", to_np(Ad), to_np(x))
    assert_close(hat_ref(G, Adx), lhs, dtype, 8)
    all_close_as_matrices(T @ G.exp(x), G.exp(Adx.astype(dtype)) @ T, dtype, 8)


# ---------------------------------------------------------------------------------
# Operations against the matrix representation.


@over_cases
@given(seed=seeds)
def test_apply_is_matrix_action(G, batch, dtype, seed):
    T = random_element(G, seed, batch, dtype)
    p = random_points(G, seed, batch, dtype)
    got = T.apply(p)
    assert got.dtype == dtype and got.shape == (*batch, G.space_dim)
    assert_close(got, homogeneous_apply(G, T.as_matrix(), p), dtype, 4)
    np.testing.assert_array_equal(to_np(T @ p), to_np(got))
    # Unbatched points broadcast against the batch.
    got1 = T.apply(p[(0,) * len(batch)])
    assert_close(got1, homogeneous_apply(G, T.as_matrix(), np.broadcast_to(
        to_np(p[(0,) * len(batch)]), (*batch, G.space_dim))), dtype, 4)


@over_cases
@given(seed=seeds)
def test_multiply_is_matrix_product(G, batch, dtype, seed):
    T = random_element(G, seed, batch, dtype)
    U = random_element(G, seed + 1, batch, dtype)
    TU = T.multiply(U)
    assert TU.parameters().dtype == dtype and TU.get_batch_axes() == batch
    assert_close(TU.as_matrix(), to_np(T.as_matrix()) @ to_np(U.as_matrix()), dtype, 4)
    np.testing.assert_array_equal(to_np((T @ U).parameters()), to_np(TU.parameters()))


@over_cases
@given(seed=seeds)
def test_inverse_is_matrix_inverse(G, batch, dtype, seed):
    T = random_element(G, seed, batch, dtype)
    Ti = T.inverse()
    assert Ti.parameters().dtype == dtype
    assert_close(Ti.as_matrix(), np.linalg.inv(to_np(T.as_matrix())), dtype, 4)


@over_cases
@given(seed=seeds, scale=st.floats(0.5, 2.0))
def test_normalize(G, batch, dtype, seed, scale):
    """normalize is a projection: unit elements are fixed, a scaled rotation part is
    brought back to the same element, and normalizing twice changes nothing."""
    T = random_element(G, seed, batch, dtype)
    N = T.normalize()
    assert N.parameters().dtype == dtype
    assert_close(N.parameters(), T.parameters(), dtype, 2)
    k = {SO2: 2, SE2: 2, SO3: 4, SE3: 4}[G]
    p = np.array(T.parameters())
    scaled = p.copy()
    scaled[..., :k] *= scale
    scaled = G(jnp.asarray(scaled))
    Ns = scaled.normalize()
    assert Ns.parameters().dtype == dtype
    assert_close(Ns.parameters(), p, dtype, 4)
    assert_close(Ns.normalize().parameters(), Ns.parameters(), dtype, 2)
    assert_close(np.linalg.norm(to_np(Ns.parameters())[..., :k], axis=-1), np.ones(batch), dtype, 2)


@over_groups_dtypes
def test_normalize_any_scale(G, dtype):
    """A rotation part scaled by anything from just above the smallest normal float to
    the largest normalizes to the same element: the sum of squares would overflow (float32
    3e38: the plain formula returned 0) or underflow (1e-30: inf and NaN) without the
    power-of-two scaling. Scaling by a power of two changes nothing, bit for bit. Zero and
    non-finite rotation parts give NaN in every rotation component."""
    k = {SO2: 2, SE2: 2, SO3: 4, SE3: 4}[G]
    p = np.asarray(random_element(G, 7, (5,), dtype).parameters())
    fi, f = np.finfo(dtype), np.dtype(dtype).type
    for scale in (float(fi.tiny) * 2**10, 1e-30, 0.5**60, 2.0**60, 1e30, float(fi.max) / 2):
        scaled = p.copy()
        scaled[..., :k] = (scaled[..., :k].astype(np.float64) * scale).astype(dtype)
        got = G(jnp.asarray(scaled)).normalize().parameters()
        assert_close(got, p, dtype, 4, msg=f"scale {scale:g}")
    exact = p.copy()
    exact[..., :k] *= f(2.0**40)
    np.testing.assert_array_equal(
        np.asarray(G(jnp.asarray(exact)).normalize().parameters()),
        np.asarray(G(jnp.asarray(p)).normalize().parameters()),
    )
    bad = np.repeat(p[:1], 3, axis=0)
    bad[0, :k] = 0.0
    bad[1, 0] = np.inf
    bad[2, 0] = np.nan
    got = np.asarray(G(jnp.asarray(bad)).normalize().parameters())
    assert np.isnan(got[:, :k]).all()
    np.testing.assert_array_equal(got[:, k:], bad[:, k:])
    g = jax.grad(lambda q: G(q).normalize().parameters()[0, 0])(jnp.asarray(p * f(2.0**-70)))
    g_ref = jax.grad(lambda q: G(q).normalize().parameters()[0, 0])(jnp.asarray(p))
    assert_close(g * f(2.0**-70), g_ref, dtype, 4)


# ---------------------------------------------------------------------------------
# jlog.


@over_cases
@given(seed=seeds)
def test_jlog_matches_autodiff(G, batch, dtype, seed):
    """jlog == jax.jacrev(lambda d: (T @ exp(d)).log())(0) (jaxlie's definition)."""
    T = random_element(G, seed, batch, dtype)
    J = T.jlog()
    assert J.dtype == dtype and J.shape == (*batch, G.tangent_dim, G.tangent_dim)
    ref = _jlog_by_autodiff(T)
    assert ref.shape == J.shape
    assert_close(J, ref, dtype, 16)


@over_groups_dtypes
def test_jlog_matches_autodiff_special_elements(G, dtype):
    T = G.exp(special_tangents(G, dtype))
    # exclude the exact-π element: log is not differentiable there (branch cut).
    keep = rotation_angle(G, T.log()) < 3.1
    T = G(jnp.asarray(np.asarray(T.parameters())[keep]))
    J = T.jlog()
    ref = _jlog_by_autodiff(T)
    assert np.all(np.isfinite(to_np(J)))
    assert_close(J, ref, dtype, 16)


# ---------------------------------------------------------------------------------
# Interpolation and geodesics.


@over_cases
@given(seed=seeds)
def test_interpolate_endpoints(G, batch, dtype, seed):
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


# ---------------------------------------------------------------------------------
# Batch handling.


@over_groups_dtypes
@given(seed=seeds)
def test_indexing_reshape_stack(G, dtype, seed):
    T = random_element(G, seed, (2, 4), dtype)
    p = to_np(T.parameters())
    assert len(T) == 2
    np.testing.assert_array_equal(to_np(T[0].parameters()), p[0])
    np.testing.assert_array_equal(to_np(T[:, 1].parameters()), p[:, 1])
    np.testing.assert_array_equal(to_np(T[-1, 2].parameters()), p[-1, 2])
    np.testing.assert_array_equal(to_np(T[..., 1:3].parameters()), p[:, 1:3])
    assert T[0].get_batch_axes() == (4,) and T[:, 1].get_batch_axes() == (2,)
    assert T[1, 3].get_batch_axes() == ()
    assert type(T[0]) is G and T[0].parameters().dtype == dtype
    R = T.reshape((8,))
    assert R.get_batch_axes() == (8,)
    np.testing.assert_array_equal(to_np(R.parameters()), p.reshape(8, -1))
    assert T.reshape(4, 2).get_batch_axes() == (4, 2)
    np.testing.assert_array_equal(to_np(T.reshape(4, 2).parameters()), p.reshape(4, 2, -1))
    for shape in ((-1,), (2, -1), (-1, 1, 2)):  # -1 as in NumPy, the parameter axis kept
        np.testing.assert_array_equal(to_np(T.reshape(*shape).parameters()),
                                      p.reshape(*shape, G.parameters_dim))
    S0 = jaxlie_geo.stack([T[0], T[1]], axis=0)
    np.testing.assert_array_equal(to_np(S0.parameters()), p)
    S1 = jaxlie_geo.stack([T[0], T[1]], axis=1)
    assert S1.get_batch_axes() == (4, 2)
    np.testing.assert_array_equal(to_np(S1.parameters()), np.swapaxes(p, 0, 1))
    Su = jaxlie_geo.stack([T[0, 0], T[1, 1], T[0, 3]])
    assert Su.get_batch_axes() == (3,) and Su.parameters().dtype == dtype
    np.testing.assert_array_equal(to_np(Su.parameters()), p[[0, 1, 0], [0, 1, 3]])
    # an indexed element behaves like the element itself
    assert_close(T[1, 2].log(), to_np(T.log())[1, 2], dtype)


@over_groups
def test_iteration_truthiness_and_static_index_range(G):
    T = random_element(G, 3, (3, 2), np.float32)
    p = to_np(T.parameters())
    parts = list(T)  # over the first batch axis; before, iteration never ended
    assert len(parts) == 3 and all(type(e) is G and e.get_batch_axes() == (2,) for e in parts)
    for i, e in enumerate(parts):
        np.testing.assert_array_equal(to_np(e.parameters()), p[i])
    a, b, c = T
    np.testing.assert_array_equal(to_np(c.parameters()), p[2])
    with pytest.raises(TypeError, match="unbatched"):
        list(T[0, 0])
    assert bool(T) and bool(G.identity())  # jaxlie's elements are always true
    # static integers out of range raise, as in NumPy (JAX alone would clamp to the end)
    # (also after ..., and in static integer lists and NumPy arrays; these once clamped)
    for index in (3, -4, (0, 2), (slice(None), -3), (None, 5), (..., 2), (..., -3), (0, ..., 5),
                  [3], np.array([0, 3]), ([0, 1], ..., [2]), (0, 1, 0), (..., None, 2)):
        with pytest.raises(IndexError, match="out of range"):
            T[index]
    np.testing.assert_array_equal(to_np(T[-3, -2].parameters()), p[0, 0])
    np.testing.assert_array_equal(to_np(T[None, 2].parameters()), p[None, 2])
    for index in ((..., 1), (..., -2), (2, ..., 1), (None, ..., 0, None), [2, 0], np.array([-3, 1]),
                  ([0, 2], ..., [1, 0]), (p[..., 0] > 0,), (..., np.array([True, False])),
                  (np.array([0, 2]), ...), (np.array([True, False, True]), ...), (..., 1, True),
                  (True, 0), (np.True_, ..., None)):
        idx = index if isinstance(index, tuple) else (index,)
        if not any(i is Ellipsis for i in idx):
            idx = (*idx, ...)
        want = p[(*idx, slice(None))]  # NumPy's rules on the batch axes, parameters last
        np.testing.assert_array_equal(to_np(T[index].parameters()), want)
    # advanced indices apart (NumPy moves their axes first): the parameter axis stays last
    U = random_element(G, 4, (2, 5, 3), np.float32)
    q = to_np(U.parameters())
    for index in ((0, slice(None), [1, 2]), ([1, 0], slice(None), [2, 2]), (0, ..., [1, 2])):
        got = U[index]
        np.testing.assert_array_equal(to_np(got.parameters()), q[(*index, slice(None))])
        assert got.log().shape == (*got.get_batch_axes(), G.tangent_dim)


@pytest.mark.parametrize("G", [SO3, SE3], ids=["SO3", "SE3"])
@pytest.mark.parametrize("dtype", [jnp.float16, jnp.bfloat16], ids=["float16", "bfloat16"])
def test_half_precision_exp_is_finite_and_close(G, dtype):
    # A small batch takes the compensated kernel, whose error-free splits once assumed a
    # float64 splitter for every non-float32 dtype: 2^27 + 1 is inf in float16 (all NaN).
    x = random_tangent(G, 5, (6,), np.float32)
    x[0] = 0.0
    x[1, -3:] = [0.0, 0.0, 12.0]  # beyond √10: compensated θ² in any batch size
    got = G.exp(jnp.asarray(x, dtype)).parameters()
    assert got.dtype == dtype
    x_rounded = np.asarray(jnp.asarray(x, dtype).astype(jnp.float32))
    ref = to_np(G.exp(x_rounded).parameters())
    eps = float(jnp.finfo(dtype).eps)
    scale = np.maximum(1.0, np.abs(ref))
    assert np.all(np.abs(to_np(got.astype(jnp.float32)) - ref) <= 4 * eps * scale)


@pytest.mark.parametrize("G", [SO2, SO3, SE3], ids=["SO2", "SO3", "SE3"])
@pytest.mark.parametrize("dtype", [jnp.float16, jnp.bfloat16], ids=["float16", "bfloat16"])
def test_half_precision_normalize_any_scale(G, dtype):
    """normalize in float16/bfloat16 at every scale of the rotation part whose squares the
    dtype can hold after its power-of-two rescaling, against float64 numpy: float16 once
    returned NaN for rotation parts of norm 0.25 to 0.7 (its rescaled squares overflowed),
    and repr then printed NaN for any float16 element."""
    k = {SO2: 2, SO3: 4, SE3: 4}[G]
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


@pytest.fixture
def small_chunks(monkeypatch):
    """``in_chunks`` with 256-element chunks from 512 elements on, so that a test-sized
    batch takes the chunked path, with chunks large enough for ``_so3.by_angle`` to choose
    its kernel per chunk (jit caches cleared: the sizes are read at trace time)."""
    from jaxlie_geo import _batch
    from jaxlie_geo import _so3

    assert _so3._BY_ANGLE_MIN_BATCH <= 256
    monkeypatch.setattr(_batch, "CHUNK", 256)
    monkeypatch.setattr(_batch, "CHUNKED_FROM", 512)
    jax.clear_caches()
    yield
    monkeypatch.undo()
    jax.clear_caches()


def _chunked_ops():
    """The operations that run large batches in chunks (``_batch.in_chunks``): f(params,
    other params, t) and its arguments' shapes."""
    ops = [(G, "interpolate", lambda p, q, t, G=G: G(p).interpolate(G(q), t).parameters())
           for G in GROUPS if G._interpolate_in_chunks]
    ops.append((SE3, "exp", lambda p, q, t: SE3.exp(SE3(p).log() * t[..., None]).parameters()))
    return ops


@pytest.mark.parametrize(("G", "op", "f"), _chunked_ops(), ids=lambda x: getattr(x, "__name__", x))
@pytest.mark.parametrize("dtype", [np.float32, np.float64], ids=["float32", "float64"])
def test_in_chunks_equals_whole_batch(G, op, f, dtype, small_chunks):
    """A large batch runs chunk by chunk (a loop in the compiled program); values, vmap
    and gradients (taken whole, by design: no loop) agree with the whole-batch path within
    a few ulp. The batch, 7 × 143, is not a multiple of the chunk, so the last chunk
    overlaps its predecessor. Rotation angles t·θ exceed √10 only in the first chunk, so
    the whole batch takes the compensated SO(3) kernel and the later chunks the plain one."""
    from jaxlie_geo import _batch

    batch = (7, 143)
    T, U = random_element(G, 0, batch, dtype), random_element(G, 1, batch, dtype)
    t = np.random.default_rng(2).uniform(-0.5, 0.9, batch).astype(dtype)
    t[0, :5] = 1.5

    def loss(p, q, t):
        return jnp.sum(jnp.sin(f(p, q, t)))

    args = (T.parameters(), U.parameters(), jnp.asarray(t))
    # Chunking is CPU-only; elsewhere both paths are the whole batch.
    assert ("while" in jax.jit(f).lower(*args).as_text()) == (jax.default_backend() == "cpu")
    assert "while" not in jax.jit(jax.grad(loss)).lower(*args).as_text()
    got, grads = f(*args), jax.grad(loss, argnums=(0, 1, 2))(*args)
    stacked = jax.vmap(f)(*(jnp.stack([a, a[::-1]]) for a in args))
    _batch.CHUNKED_FROM = 2**19
    jax.clear_caches()
    assert "while" not in jax.jit(f).lower(*args).as_text()
    want, want_grads = f(*args), jax.grad(loss, argnums=(0, 1, 2))(*args)
    assert_close(got, want, dtype, 4)
    for g, w in zip(grads, want_grads):
        assert_close(g, w, dtype, 16)
    assert_close(stacked[0], want, dtype, 4)
    assert_close(stacked[1], f(*(a[::-1] for a in args)), dtype, 4)


_SHARDED_SCRIPT = r"""
import os, sys
os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
import jax, jax.numpy as jnp, numpy as np
from jax.sharding import NamedSharding, PartitionSpec as P
import jaxlie_geo
from jaxlie_geo import _batch

_batch.CHUNK, _batch.CHUNKED_FROM = 256, 512  # chunk a test-sized batch (as small_chunks)
n = 4096  # 1024 per device: shard_map's per-device batch is chunked too
rng = np.random.default_rng(0)
ops = {}
for G in (jaxlie_geo.SE2, jaxlie_geo.SO3, jaxlie_geo.SE3):
    if G._interpolate_in_chunks:
        ops[G.__name__ + ".interpolate"] = (
            lambda a, b, t, G=G: G.exp(a).interpolate(G.exp(b), t).parameters(), G.tangent_dim)
ops["SE3.exp"] = (lambda a, b, t: jaxlie_geo.SE3.exp(a * t[..., None]).parameters(), 6)
ops["SE3.grad"] = (lambda a, b, t: jax.grad(
    lambda a: jnp.sum(jaxlie_geo.SE3.exp(a).interpolate(jaxlie_geo.SE3.exp(b), t).log() ** 2))(a), 6)
AxisType = getattr(jax.sharding, "AxisType", None)
for kind in ("Auto", "Explicit") if AxisType is not None else ("default",):
    extra = {} if AxisType is None else {"axis_types": (getattr(AxisType, kind),)}
    mesh = jax.make_mesh((4,), ("b",), **extra)
    for name, (f, k) in ops.items():
        # angles well below π: the gradient of log is ill-conditioned near π (60-80 ulp
        # between any two evaluation orders there), which is not what this test is about
        a, b = (0.5 * rng.normal(size=(n, k)).astype(np.float32) for _ in range(2))
        t = rng.uniform(-0.5, 1.5, n).astype(np.float32)
        want = np.asarray(jax.jit(f)(a, b, t))  # on one device, whole
        args = [jax.device_put(x, NamedSharding(mesh, P("b"))) for x in (a, b, t)]
        compiled = jax.jit(f).lower(*args).compile()
        assert "all-gather" not in compiled.as_text(), (kind, name)
        got = compiled(*args)
        assert tuple(got.sharding.spec)[:1] == ("b",), (kind, name, got.sharding)
        mapped = getattr(jax, "shard_map", None)
        if mapped is None:
            from jax.experimental.shard_map import shard_map as mapped
        g = jax.jit(mapped(f, mesh=mesh, in_specs=(P("b"),) * 3, out_specs=P("b"))).lower(*args)
        if hasattr(jax, "shard_map") and not name.endswith("grad"):
            assert "while" in g.as_text(), (kind, name)  # chunks per device
        for out in (got,) + (() if name.endswith("grad") else (g.compile()(*args),)):
            # In the row's scale. Shards and chunks compile and round differently (plain or
            # compensated angles, fusion), and interpolate chains five operations: in
            # float32 each path is up to 10 ulp from a float64 evaluation, and the gradient
            # (through ten) 20-26 ulp.
            scale = np.maximum(1.0, np.max(np.abs(want), axis=-1, keepdims=True))
            err = np.max(np.abs(np.asarray(out) - want) / scale) / np.finfo(np.float32).eps
            assert err <= (64 if name.endswith("grad") else 16), (kind, name, err)
        print(kind, name, "ok", f"{err:.2f}")
"""


def test_chunked_ops_on_a_sharded_batch():
    """A batch sharded over several CPU devices (jax.sharding, 4 forced host devices, in
    a subprocess: the device count is fixed at jax's start). ``in_chunks``'s loop slices
    the batch axis, so it must not run there: with Explicit axes it failed to trace
    (dynamic_update_slice sharding mismatch) and with Auto axes XLA gathered the whole
    batch on every device and returned it replicated. The result keeps the input's
    sharding, the program has no all-gather, values match one device's, and inside
    ``shard_map`` (each device's own shard) the chunks run again."""
    code = _SHARDED_SCRIPT
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600, env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.count(" ok") >= 4, out.stdout


@pytest.mark.parametrize("G", [SO3, SE3], ids=lambda G: G.__name__)
def test_barrier_tangent_pass_through_keeps_derivatives(G, small_chunks, monkeypatch):
    """``materialize``'s jax ≥ 0.11 form (tangents bypass the barrier, ``_base._barrier``)
    gives the gradient through the chunked ``interpolate`` (the custom JVP where jax 0.11.2
    failed with JAX's own barrier rule) and the forward-mode Jacobian of a compose that
    JAX's rule gives on the whole batch (no custom JVP: that path works on every jax)."""
    from jaxlie_geo import _base, _batch

    batch = (3, 201)
    T, U = random_element(G, 3, batch, np.float32), random_element(G, 4, batch, np.float32)
    t = np.random.default_rng(5).uniform(0, 1, batch).astype(np.float32)

    def loss(p, q, t):
        return jnp.sum(jnp.sin(G(p).interpolate(G(q), t).parameters()))

    def fwd(p):
        return jax.jacfwd(lambda p: (G(p) @ U[0, 0]).log())(p)

    args = (T.parameters(), U.parameters(), jnp.asarray(t))
    results = {}
    for through in (False, True):
        monkeypatch.setattr(_base, "_TANGENTS_PASS_THROUGH", through)
        # the reference: the whole batch under JAX's barrier rule
        monkeypatch.setattr(_batch, "CHUNKED_FROM", 512 if through else 2**30)
        jax.clear_caches()
        if jax.default_backend() == "cpu":
            assert ("while" in jax.jit(loss).lower(*args).as_text()) == through
        results[through] = (jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(*args),
                            fwd(T.parameters()[0, 0]))
    for got, want in zip(jax.tree.leaves(results[True]), jax.tree.leaves(results[False])):
        assert_close(got, want, np.float32, 4)


def test_interpolate_memory_at_2_22_elements():
    """Issue 6: a 2^22-element SE3 interpolate needs no more than inputs + outputs + one
    temporary of the output's size. XLA's buffer assignment for the compiled program (not
    run) reports the temporaries; before chunking they were 268 MB, 2.3 outputs. Chunking
    is CPU-only (``_batch.in_chunks`` says why)."""
    if jax.default_backend() != "cpu":
        pytest.skip("interpolate chunks its batch on CPU only")
    n = 2**22
    spec = jax.ShapeDtypeStruct((n, 7), jnp.float32)
    for t in (jax.ShapeDtypeStruct((n,), jnp.float32), jax.ShapeDtypeStruct((), jnp.float32)):
        compiled = jax.jit(lambda a, b, t: SE3(a).interpolate(SE3(b), t).parameters()).lower(
            spec, spec, t).compile()
        memory = compiled.memory_analysis()
        assert memory.output_size_in_bytes == n * 7 * 4
        assert memory.temp_size_in_bytes <= memory.output_size_in_bytes, t.shape


@pytest.mark.parametrize("op", ["compose", "apply", "inverse"])
@pytest.mark.parametrize("G", GROUPS, ids=lambda G: G.__name__)
def test_group_operations_allocate_no_temporaries(G, op):
    """Issue 6: compose, apply and inverse of 2^20 elements already in memory stream from
    the inputs to the output with no temporary buffer. The SE groups materialize whole
    elements once and call the rotation's barrier-free kernels on slices: with jax ≥ 0.11 a
    second barrier on a slice made XLA copy it (a 2^22-element SE3 compose had 185 MB of
    temporaries, apply 67, inverse 117). jax 0.10 elides those copies, so there the buffer
    check alone would pass either way; the count of barriers in the jaxpr (at most one per
    operation; the old SE3 compose had 3, apply 2) fails on the old code with every jax, on
    every backend. The buffer sizes are XLA:CPU's assignment; GPUs were not measured."""
    n = 2**20
    P, D = G.parameters_dim, G.space_dim
    spec = jax.ShapeDtypeStruct((n, P), jnp.float32)
    fns = {
        "compose": (lambda a, b: (G(a) @ G(b)).parameters(), (spec, spec)),
        "apply": (lambda a, p: G(a) @ p, (spec, jax.ShapeDtypeStruct((n, D), jnp.float32))),
        "inverse": (lambda a: G(a).inverse().parameters(), (spec,)),
    }
    f, specs = fns[op]
    assert str(jax.make_jaxpr(f)(*specs)).count("optimization_barrier") <= 1
    if jax.default_backend() != "cpu":
        pytest.skip("buffer assignment checked on XLA:CPU only")
    memory = jax.jit(f).lower(*specs).compile().memory_analysis()
    assert memory.output_size_in_bytes >= n * 4 * D
    assert memory.temp_size_in_bytes <= 2**16, memory.temp_size_in_bytes


@over_groups_dtypes
@given(seed=seeds)
def test_batch_axes_broadcast_between_operands(G, dtype, seed):
    P = G.parameters_dim
    T = G(jnp.asarray(np.asarray(random_element(G, seed, (3,), dtype).parameters())[:, None]))
    U = G(jnp.asarray(np.asarray(random_element(G, seed, (2, 4), dtype).parameters())[:1]))
    assert T.get_batch_axes() == (3, 1) and U.get_batch_axes() == (1, 4)
    MT, MU = to_np(T.as_matrix()), to_np(U.as_matrix())
    TU = T @ U
    assert TU.get_batch_axes() == (3, 4) and TU.parameters().dtype == dtype
    assert_close(TU.as_matrix(), MT @ MU, dtype, 4)
    p = random_points(G, seed, (1, 4), dtype)
    got = T @ p
    assert got.shape == (3, 4, G.space_dim) and got.dtype == dtype
    assert_close(got, homogeneous_apply(G, np.broadcast_to(MT, (3, 4, *MT.shape[-2:])),
                                        np.broadcast_to(to_np(p), (3, 4, G.space_dim))), dtype, 4)
    # interpolate broadcasts endpoints and times like explicit broadcasting does
    ts = np.linspace(0.0, 1.0, 4).astype(dtype)
    got = T.interpolate(U, ts)
    assert got.get_batch_axes() == (3, 4) and got.parameters().dtype == dtype
    T_full = G(jnp.asarray(np.broadcast_to(np.asarray(T.parameters()), (3, 4, P))))
    U_full = G(jnp.asarray(np.broadcast_to(np.asarray(U.parameters()), (3, 4, P))))
    want = T_full.interpolate(U_full, np.broadcast_to(ts, (3, 4)))
    assert_close(got.parameters(), want.parameters(), dtype)
    # an SE element built from a batched rotation and a translation broadcasts too
    if is_se(G):
        t = np.zeros((1, 4, G.space_dim), dtype)
        assert G.from_rotation_and_translation(T.rotation(), t).get_batch_axes() == (3, 4)


# ---------------------------------------------------------------------------------
# dtype in == dtype out, for every public function.


def _public_calls(G):
    """name -> function of a context dict, returning whatever the public function returns."""
    calls = {
        "identity": lambda c: G.identity((3,), dtype=c["dtype"]),
        "identity_unbatched": lambda c: G.identity(dtype=c["dtype"]),
        "sample_uniform": lambda c: G.sample_uniform(key_of(1), (3,), dtype=c["dtype"]),
        "exp": lambda c: G.exp(c["x"]),
        "log": lambda c: c["T"].log(),
        "multiply": lambda c: c["T"].multiply(c["U"]),
        "matmul_group": lambda c: c["T"] @ c["U"],
        "apply": lambda c: c["T"].apply(c["p"]),
        "matmul_points": lambda c: c["T"] @ c["p"],
        "inverse": lambda c: c["T"].inverse(),
        "adjoint": lambda c: c["T"].adjoint(),
        "jlog": lambda c: c["T"].jlog(),
        "as_matrix": lambda c: c["T"].as_matrix(),
        "from_matrix": lambda c: G.from_matrix(c["T"].as_matrix()),
        "parameters": lambda c: c["T"].parameters(),
        "normalize": lambda c: c["T"].normalize(),
        "interpolate": lambda c: c["T"].interpolate(c["U"], 0.3),
        "interpolate_array_t": lambda c: c["T"].interpolate(c["U"], c["t"]),
        "geodesic": lambda c: jaxlie_geo.geodesic(c["T"], c["U"])(c["t"]),
        "hat": lambda c: G.hat(c["x"]),
        "vee": lambda c: G.vee(G.hat(c["x"])),
        "getitem": lambda c: c["T"][0],
        "reshape": lambda c: c["T"].reshape(3, 1),
        "stack": lambda c: jaxlie_geo.stack([c["T"], c["U"]]),
        "jac_right": lambda c: G.jac_right(c["x"]),
        "jac_right_inv": lambda c: G.jac_right_inv(c["x"]),
        "jac_left": lambda c: G.jac_left(c["x"]),
        "jac_left_inv": lambda c: G.jac_left_inv(c["x"]),
        "ad": lambda c: G.ad(c["x"]),
    }
    if G is SO2:
        calls.update(
            from_radians=lambda c: SO2.from_radians(c["theta"]),
            as_radians=lambda c: c["T"].as_radians(),
        )
    if G is SO3:
        calls.update(
            from_x_radians=lambda c: SO3.from_x_radians(c["theta"]),
            from_y_radians=lambda c: SO3.from_y_radians(c["theta"]),
            from_z_radians=lambda c: SO3.from_z_radians(c["theta"]),
            from_rpy_radians=lambda c: SO3.from_rpy_radians(c["theta"], c["theta"], c["theta"]),
            from_quaternion_xyzw=lambda c: SO3.from_quaternion_xyzw(c["T"].wxyz),
            as_quaternion_xyzw=lambda c: c["T"].as_quaternion_xyzw(),
            as_rpy_radians=lambda c: tuple(c["T"].as_rpy_radians()),
            compute_roll_radians=lambda c: c["T"].compute_roll_radians(),
            compute_pitch_radians=lambda c: c["T"].compute_pitch_radians(),
            compute_yaw_radians=lambda c: c["T"].compute_yaw_radians(),
        )
    if G is SE2:
        calls.update(
            from_xy_theta=lambda c: SE2.from_xy_theta(c["theta"], c["theta"], c["theta"]),
        )
    if is_se(G):
        calls.update(
            from_rotation_and_translation=lambda c: G.from_rotation_and_translation(
                c["T"].rotation(), c["p"]
            ),
            from_rotation=lambda c: G.from_rotation(c["T"].rotation()),
            from_translation=lambda c: G.from_translation(c["p"]),
            rotation=lambda c: c["T"].rotation(),
            translation=lambda c: c["T"].translation(),
        )
    return calls


_DTYPE_CASES = [
    pytest.param(G, name, d, id=f"{G.__name__}-{name}-{jnp.dtype(d).name}")
    for G in GROUPS
    for name in _public_calls(G)
    for d in (jnp.float32, jnp.float64)
]


@pytest.mark.parametrize(("G", "name", "dtype"), _DTYPE_CASES)
def test_dtype_in_equals_dtype_out(G, name, dtype):
    # batch (3,), as in the harness, so that compiled functions are shared.
    ctx = {
        "dtype": dtype,
        "T": random_element(G, 7, (3,), dtype),
        "U": random_element(G, 8, (3,), dtype),
        "x": random_tangent(G, 7, (3,), dtype),
        "p": np.ones((3, G.space_dim), dtype),
        "t": np.asarray([0.25, 0.75, 1.5], dtype),
        "theta": np.asarray([0.1, -0.4, 2.0], dtype),
    }
    out = _public_calls(G)[name](ctx)
    dtypes = param_dtypes(out)
    assert dtypes == {jnp.dtype(dtype)}, f"{G.__name__}.{name}: {dtype} in, {dtypes} out"
    for leaf in jax.tree.leaves(out):
        assert np.all(np.isfinite(to_np(leaf)))


# ---------------------------------------------------------------------------------
# jax_numpy_rank_promotion="raise": users who set it (to catch accidental broadcasting in
# their own code) must not see it fire inside ours, whose batch axes broadcast by design.


def _module_calls(G):
    """The module functions (jacobians, uncertainty, manifold, motion) and derivatives,
    as functions of the context dict of ``_public_calls``."""
    from jaxlie_geo import jacobians, manifold, motion, uncertainty

    k = G.tangent_dim
    cov = np.eye(k) * 0.01
    calls = {
        "jacobians.compose": lambda c: jacobians.compose(c["T"], c["U"]),
        "jacobians.inverse": lambda c: jacobians.inverse(c["T"]),
        "jacobians.between": lambda c: jacobians.between(c["T"], c["U"]),
        "jacobians.rminus": lambda c: jacobians.rminus(c["T"], c["U"]),
        "jacobians.rplus": lambda c: jacobians.rplus(c["T"], c["x"]),
        "jacobians.apply": lambda c: jacobians.apply(c["T"], c["p"]),
        "jacobians.exp": lambda c: jacobians.exp(G, c["x"]),
        "jacobians.log": lambda c: jacobians.log(c["T"]),
        "propagate_compose": lambda c: uncertainty.propagate_compose(
            c["T"], cov.astype(c["dtype"]), c["U"], cov.astype(c["dtype"])),
        "propagate_inverse": lambda c: uncertainty.propagate_inverse(c["T"], cov.astype(c["dtype"])),
        "propagate_apply": lambda c: uncertainty.propagate_apply(
            c["T"], cov.astype(c["dtype"]), c["p"]),
        "sample": lambda c: uncertainty.sample(key_of(3), c["T"], cov.astype(c["dtype"])),
        "mean": lambda c: uncertainty.mean(c["U"]),
        "mean_grad": lambda c: jax.grad(
            lambda x: jnp.sum(uncertainty.mean(G.exp(x)).log() ** 2))(c["x"]),
        "rplus": lambda c: manifold.rplus(c["T"], c["x"]),
        "rminus": lambda c: manifold.rminus(c["T"], c["U"]),
        "rplus_jacobian": lambda c: manifold.rplus_jacobian_parameters_wrt_delta(c["T"]),
        "velocity_between": lambda c: motion.velocity_between(c["T"], c["U"], c["t"] + 1.0),
        "pose_at": lambda c: motion.pose_at(c["T"], c["x"], c["t"]),
        "grad": lambda c: jax.grad(
            lambda x: jnp.sum(G.exp(x).interpolate(c["U"], c["t"]).log() ** 2))(c["x"]),
        "jacfwd": lambda c: jax.jacfwd(lambda x: (c["T"] @ G.exp(x)).log())(c["x"].reshape(-1, k)[0]),
        "hessian": lambda c: jax.hessian(lambda x: jnp.sum(G.exp(x).log() ** 2))(c["x"][0]),
    }
    if G is SE2:
        calls["arc"] = lambda c: motion.arc(c["T"], c["x"])
    return calls


_TWO_OPERANDS = {
    "multiply", "matmul_group", "apply", "matmul_points", "interpolate", "interpolate_array_t",
    "geodesic", "from_rotation_and_translation", "jacobians.compose", "jacobians.between",
    "jacobians.rminus", "jacobians.apply", "propagate_compose", "propagate_apply", "rminus",
    "velocity_between", "pose_at", "grad",
}


@pytest.mark.parametrize("higher", ["T", "U"])
@over_groups
def test_rank_promotion_raise(G, higher):
    """Every public function and module function, values and derivatives, runs under
    ``jax.numpy_rank_promotion("raise")`` with batch axes of different ranks: T and x of
    batch (2, 3) against U, points and times of batch (3,), and (``higher="U"``, for the
    functions of two operands) the reverse. Results have the broadcast batch shape, and
    equal those computed with rank promotion allowed. jaxlie fails this for compose and
    inverse; our group inverses, SO3/SE2 Jacobians, binary operations, geodesics and
    motion failed too. Rank promotion is checked as operations are traced, so every call is
    traced (``jax.eval_shape``, which also gives the batch shape) and only the sample that
    is compared with promotion allowed is compiled and run."""
    dtype = np.float32
    hi, lo = (2, 3), (3,)
    bT, bU = (hi, lo) if higher == "T" else (lo, hi)
    ctx = {
        "dtype": dtype,
        "T": random_element(G, 7, bT, dtype),
        "U": random_element(G, 8, bU, dtype),
        "x": random_tangent(G, 7, bT, dtype),
        "p": np.ones(bU + (G.space_dim,), dtype),
        "t": np.asarray([0.25, 0.75, 1.5], dtype),
        "theta": np.asarray([0.1, -0.4, 2.0], dtype),
    }
    calls = {**_public_calls(G), **_module_calls(G)}
    for name in ("stack", "reshape"):  # need equal batch shapes, or 3 elements
        del calls[name]
    if higher == "U":
        calls = {k: v for k, v in calls.items() if k in _TWO_OPERANDS}
    compared = {"multiply", "apply", "interpolate_array_t", "jacobians.apply", "pose_at", "grad"}
    for name, call in calls.items():
        with jax.numpy_rank_promotion("raise"):
            shapes = jax.eval_shape(lambda: call(ctx))
        if name in _TWO_OPERANDS - {"grad", "propagate_compose", "propagate_apply", "pose_at"}:
            batch = jax.tree.leaves(shapes)[0].shape[:2]
            assert batch == hi, (name, batch)
        if name in compared:  # a sample, run, against implicit promotion
            with jax.numpy_rank_promotion("raise"):
                got = call(ctx)
            with jax.numpy_rank_promotion("allow"):
                want = call(ctx)
            for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
                np.testing.assert_array_equal(np.asarray(g), np.asarray(w), err_msg=name)


@over_groups
def test_debug_nans_without_jit(G):
    """Under ``jax_debug_nans`` with jit disabled, JAX checks every primitive's output, even
    values a select discards: no public or module function, value or derivative, may make
    a NaN from valid input at the delicate tangents (0, 1e-12, exactly π, pure
    translations). ``normalize`` (a NaN constant for direction-less input) and
    ``motion.arc`` (sign(ω)·inf at ω = 0) raised FloatingPointError for every valid pose.
    Input without a direction still gives NaN, and the alarm then is right."""
    dtype = np.float64
    x = special_tangents(G, dtype)[:6]
    n = x.shape[0]
    ctx = {
        "dtype": dtype, "T": G.exp(x), "U": G.exp(x[::-1].copy()), "x": x,
        "p": np.zeros((n, G.space_dim), dtype), "t": np.linspace(0.0, 1.0, n).astype(dtype),
        "theta": np.asarray([0.0, 1e-12, np.pi, -np.pi, 1.0, 2.0], dtype),
    }
    calls = {**_public_calls(G), **_module_calls(G)}
    del calls["reshape"]  # needs 3 elements
    with jax.disable_jit(), jax.debug_nans(True):
        for name, call in calls.items():
            try:
                call(ctx)
            except FloatingPointError as e:
                raise AssertionError(f"{G.__name__}.{name}: {str(e).splitlines()[0]}") from None
        bad = G(jnp.zeros(G.parameters_dim, dtype))
        with pytest.raises(FloatingPointError):
            bad.normalize()
    out = bad.normalize()
    rot = out.rotation() if is_se(G) else out
    assert np.all(np.isnan(to_np(rot.parameters()))), out


# ---------------------------------------------------------------------------------
# Integer inputs are promoted to float.


@over_groups
def test_integer_inputs_promoted_to_float(G):
    k = G.tangent_dim
    T = G.exp(np.zeros((3, k), np.int32))
    assert jnp.issubdtype(T.parameters().dtype, jnp.floating)
    np.testing.assert_array_equal(to_np(T.as_matrix()), _eye(G, (3,)))
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
    (integer for SO2, SE2 and SO3, the default float for SE3, as documented)."""
    k = G.parameters_dim
    p = np.zeros(k, np.int32)
    p[0] = 1
    if G in (SO3, SE3):
        p[:4] = [0, 0, 1, 0]  # a half turn about y, integer
    T = G(jnp.asarray(p))
    if is_se(G):
        t = np.linspace(0.25, 1.5, G.space_dim)
        E = G.from_rotation_and_translation(T.rotation(), t)
        assert jnp.issubdtype(E.parameters().dtype, jnp.floating)
        np.testing.assert_array_equal(to_np(E.translation()), t)
        T = G(jnp.asarray(np.concatenate([p[: k - G.space_dim], np.arange(1, G.space_dim + 1)]),
                          jnp.int32))
    F = G(T.parameters().astype(jnp.float64))
    for got, want in ((T.inverse(), F.inverse()), (T @ T, F @ F)):
        integer = G is not SE3
        assert jnp.issubdtype(got.parameters().dtype, jnp.integer) == integer, got.parameters().dtype
        np.testing.assert_array_equal(to_np(got.parameters()).astype(np.float64), to_np(want.parameters()))


def test_angle_of_a_half_turn():
    """A rotation by π reads ±π, a valid log (exp of it gives the rotation back), in every
    float dtype; −π exactly where the stored sine is −0.0, as documented (``from_matrix(−I)``
    stores one), as atan2 gives."""
    for dtype in (jnp.float16, jnp.bfloat16, jnp.float32, jnp.float64):
        R = SO2.from_matrix(-np.eye(2, dtype=dtype))
        want = jnp.asarray(-np.pi if np.signbit(np.float32(R.unit_complex[1])) else np.pi, dtype)
        for got in (R.as_radians(), R.log()[0], SE2.from_rotation(R).log()[2]):
            assert got.dtype == dtype and got == want, (dtype, got)
        np.testing.assert_allclose(np.float32(SO2.exp(R.log()).as_matrix()),
                                   -np.eye(2), atol=2 * float(jnp.finfo(dtype).eps))


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64], ids=["float32", "float64"])
def test_log_at_exactly_pi_takes_the_stored_axis(dtype):
    """At w = 0 exactly (a turn of π) the principal log is +π times the stored vector
    part's direction, as documented (−π·axis is the other valid log), in SO3 and SE3;
    interpolate and velocity_between follow it."""
    rng = np.random.default_rng(14)
    axes = np.concatenate([np.eye(3), -np.eye(3), rng.normal(size=(4, 3))])
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    q = jnp.asarray(np.concatenate([np.zeros((10, 1)), axes], axis=-1), dtype)
    eps = float(jnp.finfo(dtype).eps)
    want = np.pi * axes
    np.testing.assert_allclose(to_np(SO3(q).log()), want, atol=8 * eps)
    t = jnp.asarray(rng.normal(size=(10, 3)), dtype)
    T = SE3.from_rotation_and_translation(SO3(q), t)
    np.testing.assert_allclose(to_np(T.log()[..., 3:]), want, atol=8 * eps)
    half = SO3.identity((10,), dtype).interpolate(SO3(q), 0.5)
    np.testing.assert_allclose(to_np(half.as_matrix()), to_np(SO3.exp(want / 2).as_matrix()),
                               atol=8 * eps)
    w = jaxlie_geo.motion.velocity_between(SO3.identity((10,), dtype), SO3(q), 2.0)
    np.testing.assert_allclose(to_np(w), want / 2, atol=8 * eps)


def test_integer_factories():
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
# repr.


@over_groups
def test_repr_names_the_field_and_rounds_the_values(G):
    """jaxlie's layout: SE groups print the rotation and the translation apart."""
    T = G.exp(jnp.full(G.tangent_dim, 1e-7, jnp.float64))
    labels = {SO2: ["unit_complex"], SE2: ["unit_complex", "xy"], SO3: ["wxyz"],
              SE3: ["wxyz", "xyz"]}[G]
    text = repr(T)
    assert text.startswith(f"{G.__name__}({labels[0]}=[1. 0.") and text.endswith("])")
    assert [part.split("=")[0] for part in text[len(G.__name__) + 1 : -1].split(", ")] == labels
    assert "e-0" not in text  # rounded to 5 decimals
    assert "Array(" not in text and "dtype" not in text
    field = dataclasses.fields(G)[0].name
    traced = jax.jit(lambda T: (repr(T), T)[1])  # repr of a traced element does not fail
    traced(T)
    shaped = repr(jax.eval_shape(lambda: G.identity((2,))))  # holds a ShapeDtypeStruct
    assert shaped.startswith(f"{G.__name__}({field}=ShapeDtypeStruct(shape=(2, ")


@pytest.mark.parametrize("G", [SE2, SE3], ids=lambda G: G.__name__)
def test_a_subclass_gets_classmethods_bound_to_it(G):
    """Classmethods are jitted with their class bound (for ``.lower``); a subclass binds
    them again, so the constructor that builds ``cls(...)`` builds the subclass."""

    class Pose(G):  # type: ignore[misc,valid-type]
        pass

    jax.tree_util.register_pytree_node(
        Pose, lambda T: ((T.parameters(),), None), lambda _, c: Pose(*c)
    )
    R = G._rotation_type.identity()
    T = Pose.from_rotation_and_translation(R, jnp.zeros(G.space_dim))
    assert type(T) is Pose and type(G.from_rotation_and_translation(R, T.translation())) is G


@over_groups
def test_every_public_method_is_documented(G):
    """help(G.method) shows text: overrides without their own docstring show the base's."""
    import inspect

    undocumented = [
        name
        for name in dir(G)
        if not name.startswith("_")
        and callable(getattr(G, name))
        and not (inspect.getdoc(getattr(G, name)) or "").strip()
    ]
    assert undocumented == [], undocumented


# ---------------------------------------------------------------------------------
# Closed-form kernels: no matrices inside.


def _all_eqns(jaxpr):
    """Every equation, those of sub-jaxprs (jit, custom_jvp, cond, while, ...) included."""
    out = []
    for eqn in jaxpr.eqns:
        out.append(eqn)
        for param in eqn.params.values():
            subs = param if isinstance(param, (list, tuple)) else [param]
            for sub in subs:
                inner = getattr(sub, "jaxpr", None)
                if inner is not None:
                    out += _all_eqns(getattr(inner, "jaxpr", inner))
    return out


def _all_avals(jaxpr):
    """Every intermediate's abstract value, sub-jaxprs included."""
    return [v.aval for eqn in _all_eqns(jaxpr) for v in eqn.outvars]


@pytest.mark.parametrize("G", [SO3, SE3], ids=lambda G: G.__name__)
def test_no_matrix_intermediates_in_the_kernels(G):
    """exp, log, compose, apply, inverse and interpolate of SO3/SE3 are quaternion algebra
    and cross products: no (…, 3, 3) or (…, 4, 4) array appears in their jaxprs."""
    T = random_element(G, 1, (5,), jnp.float32)
    x = random_tangent(G, 1, (5,), jnp.float32)
    p = random_points(G, 1, (5,), jnp.float32)
    ops = {
        "exp": lambda x: G.exp(x).parameters(),
        "log": lambda T: T.log(),
        "compose": lambda T: (T @ T).parameters(),
        "apply": lambda T: T @ p,
        "inverse": lambda T: T.inverse().parameters(),
        "interpolate": lambda T: T.interpolate(T[::-1], 0.3).parameters(),
    }
    for name, f in ops.items():
        arg = x if name == "exp" else T
        avals = _all_avals(jax.make_jaxpr(f)(arg).jaxpr)
        assert avals, name
        matrices = [a.shape for a in avals
                    if len(getattr(a, "shape", ())) >= 2 and a.shape[-2:] in ((3, 3), (4, 4))]
        assert matrices == [], (name, matrices)
    # the check can fail: as_matrix does build 3x3 blocks
    avals = _all_avals(jax.make_jaxpr(lambda T: T.as_matrix())(T).jaxpr)
    assert any(len(a.shape) >= 2 and a.shape[-2:] in ((3, 3), (4, 4)) for a in avals)



@over_groups
def test_matrix_products_at_full_precision(G):
    """Every ``dot_general`` in the library runs at ``Precision.HIGHEST`` (``_base.matmul``):
    on GPUs a float32 dot at JAX's default precision runs in TF32, about 1e-3 relative
    error (seen on an H100: SE3 ``propagate_compose`` lost its symmetry at that level).
    Walks the jaxprs of every method and module function that builds or multiplies
    matrices, and of derivatives through them."""
    from jaxlie_geo import jacobians, uncertainty

    T = random_element(G, 2, (4,), jnp.float32)
    x = random_tangent(G, 2, (4,), jnp.float32)
    p = random_points(G, 2, (4,), jnp.float32)
    cov = np.eye(G.tangent_dim, dtype=np.float32) * 1e-2
    fns = {
        "adjoint": lambda T, x: T.adjoint(),
        "jlog": lambda T, x: T.jlog(),
        "jacs": lambda T, x: (G.jac_right(x), G.jac_left(x), G.jac_right_inv(x),
                              G.jac_left_inv(x), G.ad(x)),
        "as/from_matrix": lambda T, x: G.from_matrix(T.as_matrix()).parameters(),
        "jacobians": lambda T, x: (jacobians.compose(T, T), jacobians.inverse(T),
                                   jacobians.between(T, T), jacobians.rminus(T, T),
                                   jacobians.rplus(T, x), jacobians.exp(G, x),
                                   jacobians.log(T), jacobians.apply(T, p)),
        "uncertainty": lambda T, x: (uncertainty.propagate_compose(T, cov, T, cov, cov),
                                     uncertainty.propagate_inverse(T, cov),
                                     uncertainty.propagate_apply(T, cov, p, np.eye(G.space_dim)),
                                     uncertainty.sample(key_of(0), T, cov).parameters(),
                                     uncertainty.mean(T).parameters()),
        "d/dx": lambda T, x: jax.jacfwd(lambda x: (T @ G.exp(x)).log())(x),
        "grad": lambda T, x: jax.grad(lambda x: jnp.sum(G.exp(x).inverse().apply(p)
                                                        + G.jac_right(x).sum()))(x),
    }
    found = 0
    for name, f in fns.items():
        eqns = _all_eqns(jax.make_jaxpr(f)(T, x).jaxpr)
        assert eqns, name
        dots = [e for e in eqns if e.primitive.name == "dot_general"]
        low = [str(e) for e in dots if e.params["precision"] != (jax.lax.Precision.HIGHEST,) * 2]
        assert low == [], (name, low[:1])
        found += len(dots)
    assert found > 0  # the walk sees the products (SE3's adjoint has one at least)


# ---------------------------------------------------------------------------------
# exp picks its angle path per batch (``_so3.by_angle``): one element far beyond π sends
# the whole batch through the compensated kernel. Both paths, and vmap (where the cond
# becomes a select), must agree on the small angles.


@pytest.mark.parametrize("G", [SO3, SE3], ids=["SO3", "SE3"])
@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64], ids=["float32", "float64"])
def test_exp_path_choice_is_invisible(G, dtype):
    small = random_tangent(G, 3, (512,), dtype)  # angles below π: the plain kernel
    big = random_tangent(G, 4, (1,), dtype, max_angle=30.0)
    big[..., -3:] *= 30.0 / np.linalg.norm(big[..., -3:], axis=-1, keepdims=True)
    alone = to_np(G.exp(small).parameters())
    mixed = to_np(G.exp(np.concatenate([small, big])).parameters())
    # vmap and a batch under _BY_ANGLE_MIN_BATCH: the compensated kernel.
    mapped = to_np(jax.vmap(lambda x: G.exp(x).parameters())(small))
    few = to_np(G.exp(small[:8]).parameters())
    eps = float(jnp.finfo(dtype).eps)
    scale = np.maximum(1.0, np.max(np.abs(alone), axis=-1, keepdims=True))
    # Both kernels are exact to a few ulp (test_accuracy); they may round differently.
    assert np.max(np.abs(mixed[:-1] - alone) / scale) <= 4 * eps
    assert np.max(np.abs(mapped - alone) / scale) <= 4 * eps
    assert np.max(np.abs(few - alone[:8]) / scale[:8]) <= 4 * eps
    # The big element takes the compensated path either way (its accuracy beyond π is
    # tests/test_accuracy.py's "beyond_pi" regime, whose batches hold only such angles).
    np.testing.assert_array_equal(mixed[-1:], to_np(G.exp(big).parameters()))
    # Just past the threshold (θ² in (10, 40)) a whole batch takes the compensated kernel:
    # its quaternions agree with the per-element path (vmap: always compensated) to 0.5 eps;
    # the plain kernel there (the threshold 4x too high) differs by 1.5 eps.
    edge = random_tangent(G, 7, (512,), dtype)
    rot = edge[..., -3:]
    theta = np.sqrt(np.random.default_rng(7).uniform(10.0, 40.0, (512, 1)))
    edge[..., -3:] = (rot / np.linalg.norm(rot, axis=-1, keepdims=True) * theta).astype(dtype)
    batch = to_np(G.exp(edge).parameters()[..., :4])
    each = to_np(jax.vmap(lambda x: G.exp(x).parameters()[..., :4])(edge))
    assert np.max(np.abs(batch - each)) <= 0.5 * eps


@pytest.mark.parametrize("G", [SO3, SE3], ids=["SO3", "SE3"])
@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64], ids=["float32", "float64"])
def test_exp_derivative_takes_one_kernel(G, dtype):
    """by_angle's custom JVP: a gradient through a large batch differentiates the
    compensated kernel alone (no cond to compile and transpose twice), and equals the
    per-element gradient (vmap, which never takes the batch-level choice)."""
    xi = random_tangent(G, 5, (512,), dtype)
    w = random_tangent(G, 6, (512,), dtype)  # weights for all but qw (tangent_dim of them)

    def loss(x, w):
        return jnp.sum(w * G.exp(x).parameters()[..., 1:])

    forward = str(jax.make_jaxpr(loss)(xi, w))
    backward = str(jax.make_jaxpr(jax.grad(loss))(xi, w))
    assert "cond[" in forward  # the choice is there on the forward pass (CPU) ...
    assert "cond[" not in backward  # ... and not under differentiation
    eps = float(jnp.finfo(dtype).eps)
    np.testing.assert_allclose(
        to_np(jax.grad(loss)(xi, w)), to_np(jax.vmap(jax.grad(loss))(xi, w)), rtol=0, atol=16 * eps
    )


@pytest.mark.parametrize("dtype", [np.float32, np.float64], ids=["float32", "float64"])
def test_rpy_depends_on_the_quaternion_direction_only(dtype):
    """compute_roll/pitch/yaw_radians of a scaled quaternion equal those of the unit one, and
    scipy's intrinsic ZYX angles of the same rotation (as ``as_matrix`` reads it). The unit
    formulas read π/2 for a pitch of 1.3 from a quaternion 5% long (the clipped sine)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    rpy = rng.uniform([-3.0, -1.5, -3.0], [3.0, 1.5, 3.0], size=(64, 3))
    q = np.asarray(SO3.from_rpy_radians(*jnp.asarray(rpy.T, dtype)).wxyz, np.float64)
    ref = Rotation.from_quat(np.roll(q, -1, axis=-1)).as_euler("ZYX")[:, ::-1]
    eps = float(np.finfo(dtype).eps)
    for scale in (1.0, 0.5, 1.05, 2.0, 1e3):
        R = SO3(jnp.asarray(q * scale, dtype))
        got = np.stack([np.asarray(R.compute_roll_radians()), np.asarray(R.compute_pitch_radians()),
                        np.asarray(R.compute_yaw_radians())], -1).astype(np.float64)
        # pitch is ill-conditioned near ±π/2 (asin): compare its sine there
        err = np.abs(got - ref)
        err[:, 1] = np.abs(np.sin(got[:, 1]) - np.sin(ref[:, 1])) / np.maximum(
            np.cos(ref[:, 1]), 1e-3)
        assert err.max() <= 16 * eps, (scale, err.max() / eps)


@pytest.mark.parametrize("dtype", [np.float32, np.float64], ids=["float32", "float64"])
def test_rpy_at_and_near_gimbal_lock(dtype):
    """At and near pitch ±π/2 (0 to 0.3 away): the pitch is within 2 eps of mpmath's
    asin(2(wy − zx)/‖q‖²) of the stored quaternion (jaxlie's asin: 5.8e3 eps in float32,
    1.3e8 in float64, and NaN past ±1), and ``from_rpy_radians`` of the three angles, each
    read by its own (jitted) method, gives the rotation back within 8 eps (roll and yaw
    alone are ill-conditioned there; read independently they gave O(1) errors at lock).
    Scaled quaternions too (direction only)."""
    import mpmath

    mpmath.mp.dps = 50
    rng = np.random.default_rng(8)
    eps = float(np.finfo(dtype).eps)
    n = 256
    for delta in (0.0, 1e-6, 1e-3, 0.3):
        rpy = rng.uniform(-np.pi, np.pi, size=(n, 3))
        rpy[:, 1] = np.where(np.arange(n) % 2 == 0, 1.0, -1.0) * (np.pi / 2 - delta)
        R = SO3.from_rpy_radians(*jnp.asarray(rpy.T, dtype))
        q = np.asarray(R.wxyz, np.float64)
        want = []
        for w, x, y, z in q.tolist():
            w, x, y, z = (mpmath.mpf(v) for v in (w, x, y, z))
            want.append(float(mpmath.asin(2 * (w * y - z * x) / (w * w + x * x + y * y + z * z))))
        for scale in (1.0, 1.5, 0.75):
            Q = SO3(R.wxyz * jnp.asarray(scale, dtype))
            roll, pitch, yaw = Q.compute_roll_radians(), Q.compute_pitch_radians(), Q.compute_yaw_radians()
            np.testing.assert_allclose(to_np(pitch), want, rtol=0, atol=2 * eps, err_msg=f"{delta}")
            back = SO3.from_rpy_radians(roll, pitch, yaw)
            np.testing.assert_allclose(to_np(back.as_matrix()), to_np(R.as_matrix()), rtol=0,
                                       atol=8 * eps, err_msg=f"δ = {delta}, scale {scale}")
    # exactly at lock, w ∓ y and z ± x exactly 0 (each read as 1), and the zero quaternion
    exact = np.array([[0.5, 0.5, 0.5, -0.5], [0.5, -0.5, -0.5, -0.5], [1.0, 0.0, 1.0, 0.0],
                      [1.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 1.0], [0.6, 0.8, 0.6, -0.8]], dtype)
    R = SO3(jnp.asarray(exact))
    roll, pitch, yaw = R.as_rpy_radians()
    np.testing.assert_array_equal(np.abs(to_np(pitch)), np.float64(np.asarray(np.pi / 2, dtype)))
    np.testing.assert_allclose(to_np(SO3.from_rpy_radians(roll, pitch, yaw).as_matrix()),
                               to_np(R.as_matrix()), rtol=0, atol=8 * eps)
    assert [float(a) for a in SO3(jnp.zeros(4, dtype)).as_rpy_radians()] == [0.0, 0.0, 0.0]
    # derivatives: 0 for the pitch exactly at lock (a maximum; NaN through √0 before the
    # guard), central differences elsewhere (float64)
    pitch_of = jax.vmap(jax.grad(lambda q: SO3(q).compute_pitch_radians()))
    np.testing.assert_array_equal(to_np(pitch_of(jnp.asarray(exact))), 0.0)
    if dtype == np.float64:
        q = np.asarray(SO3.from_rpy_radians(0.3, np.pi / 2 - 0.1, -2.0).wxyz)
        for f in ("compute_roll_radians", "compute_pitch_radians", "compute_yaw_radians"):
            g = to_np(jax.grad(lambda q: getattr(SO3(q), f)())(jnp.asarray(q)))
            fd = [(float(getattr(SO3(jnp.asarray(q + h * e)), f)())
                   - float(getattr(SO3(jnp.asarray(q - h * e)), f)())) / (2 * h)
                  for e, h in zip(np.eye(4), [1e-6] * 4)]
            np.testing.assert_allclose(g, fd, rtol=1e-7, atol=1e-7, err_msg=f)


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
    assert_close((a @ E).as_matrix(), jnp.broadcast_to(b.as_matrix(), (3, 4, G.matrix_dim, G.matrix_dim)),
                 np.float64, 8)
    other = SE3 if G is not SE3 else SO3
    with pytest.raises(TypeError, match=f"expected {G.__name__}, got {other.__name__}"):
        jaxlie_geo.between(a, other.identity())
    with pytest.raises(TypeError, match="expected a group element"):
        jaxlie_geo.between(a.parameters(), b)


def test_sample_uniform_is_haar():
    """sample_uniform draws from the Haar measure, checked by Kolmogorov–Smirnov tests
    (20 000 draws, fixed key): the rotation angle has CDF θ/(2π) on [0, 2π) for SO(2) and
    (θ − sin θ)/π on [0, π] for SO(3); and a Haar rotation maps a fixed vector to a uniform
    point of the sphere, whose z has CDF (1 + z)/2. SE translations are uniform in [-1, 1]."""
    import scipy.stats

    key = jax.random.PRNGKey(3)
    n = 20000
    th = np.mod(to_np(SO2.sample_uniform(key, (n,)).as_radians()), 2 * np.pi)
    assert scipy.stats.kstest(th, lambda x: x / (2 * np.pi)).pvalue > 1e-3
    R = SO3.sample_uniform(key, (n,))
    angle = np.linalg.norm(to_np(R.log()), axis=-1)
    assert scipy.stats.kstest(angle, lambda x: (x - np.sin(x)) / np.pi).pvalue > 1e-3
    z = to_np(R.apply(jnp.array([1.0, 0.0, 0.0])))[:, 2]
    assert scipy.stats.kstest(z, lambda x: (1 + x) / 2).pvalue > 1e-3
    for G in (SE2, SE3):
        t = to_np(G.sample_uniform(key, (n,)).translation()).ravel()
        assert scipy.stats.kstest(t, lambda x: (x + 1) / 2).pvalue > 1e-3


@over_groups
def test_stack_axis_counts_batch_axes(G):
    """``stack(..., axis)`` counts among the batch axes, as ``np.stack`` on the batch:
    axis=-1 adds the last batch axis (the parameter axis stays last), and an axis past
    the batch rank raises instead of wrapping."""
    T, U = random_element(G, 1, (4,), np.float64), random_element(G, 2, (4,), np.float64)
    p, q = to_np(T.parameters()), to_np(U.parameters())
    S = jaxlie_geo.stack([T, U], axis=-1)
    assert S.get_batch_axes() == (4, 2)
    np.testing.assert_array_equal(to_np(S.parameters()), np.stack([p, q], axis=-2))
    for axis in (2, -3):
        with pytest.raises(ValueError, match="out of range"):
            jaxlie_geo.stack([T, U], axis=axis)


@over_groups
def test_times_follow_numpy_promotion(G):
    """A float64 NumPy ``t`` with float32 elements under x64 gives float64, as documented for
    NumPy float64 inputs (and as ``T @ G.exp(np.zeros(k))`` does)."""
    T, U = random_element(G, 1, (), np.float32), random_element(G, 2, (), np.float32)
    t = np.array([0.25, 0.5], np.float64)
    assert (T @ G.exp(np.zeros(G.tangent_dim))).parameters().dtype == jnp.float64
    for out in (T.interpolate(U, t), jaxlie_geo.geodesic(T, U)(t)):
        assert out.parameters().dtype == jnp.float64, out.parameters().dtype
