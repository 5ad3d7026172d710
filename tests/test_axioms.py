"""The group axioms and the definitions of each operation, on every group × batch shape ×
dtype of the harness.

References are independent of the library: the group laws themselves, the matrix
representation (numpy products, inverses and determinants), the generators written out in
conftest (``hat_ref``, ``vee_ref``), ``scipy.linalg.expm``, automatic differentiation of the
library's own composition (jaxlie's definition of ``jlog``) and, for ``sample_uniform``, the
Haar measure's known distributions (Kolmogorov–Smirnov tests).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from conftest import (
    LAYOUT,
    SE_GROUPS,
    all_close_as_matrices,
    angle_kinds,
    assert_close,
    assert_rel_norm,
    expm_ref,
    has_scale,
    hat_ref,
    homogeneous_apply,
    identity_matrices,
    over_cases,
    over_groups_dtypes,
    random_element,
    random_points,
    random_tangent,
    rotation_angle,
    rotation_params,
    seeds,
    special_tangents,
    to_np,
    vee_ref,
)
from hypothesis import given
from hypothesis import strategies as st

from jaxlie_geo import SO2, SO3


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


# ---------------------------------------------------------------------------------
# Group laws.


@over_cases
@given(seed=seeds)
def test_identity_laws(G, batch, dtype, seed):
    """T I = I T = T for a batched and an unbatched identity; the identity is exactly the
    identity matrix, its log and inverse exactly zero and the identity, exp(0) exactly I."""
    T = random_element(G, seed, batch, dtype)
    I_batched = G.identity(batch, dtype=dtype)
    I_single = G.identity(dtype=dtype)
    eye = identity_matrices(G, batch)
    assert I_batched.get_batch_axes() == batch
    assert I_batched.parameters().dtype == dtype
    np.testing.assert_array_equal(to_np(I_batched.as_matrix()), eye)
    for I in (I_batched, I_single):
        all_close_as_matrices(T @ I, T, dtype)
        all_close_as_matrices(I @ T, T, dtype)
    np.testing.assert_array_equal(to_np(I_batched.log()), np.zeros((*batch, G.tangent_dim)))
    zero = jnp.zeros((*batch, G.tangent_dim), dtype)
    np.testing.assert_array_equal(to_np(G.exp(zero).as_matrix()), eye)
    np.testing.assert_array_equal(to_np(I_batched.inverse().as_matrix()), eye)


@over_cases
@given(seed=seeds)
def test_inverse_laws(G, batch, dtype, seed):
    """T T⁻¹ = T⁻¹ T = I and (T⁻¹)⁻¹ = T, as matrices."""
    T = random_element(G, seed, batch, dtype)
    eye = identity_matrices(G, batch)
    assert_close((T @ T.inverse()).as_matrix(), eye, dtype, 2)
    assert_close((T.inverse() @ T).as_matrix(), eye, dtype, 2)
    all_close_as_matrices(T.inverse().inverse(), T, dtype, 2)
    assert T.inverse().get_batch_axes() == batch


@over_cases
@given(seed=seeds)
def test_associativity(G, batch, dtype, seed):
    """(T U) V = T (U V), as matrices."""
    T, U, V = (random_element(G, seed + i, batch, dtype) for i in range(3))
    all_close_as_matrices((T @ U) @ V, T @ (U @ V), dtype, 4)


# ---------------------------------------------------------------------------------
# exp and log.


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
    """exp(log T) == T (as matrices) for Haar-random T; the log is principal: its
    rotation angle is at most π."""
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
    """from_matrix(as_matrix(T)) == T; the matrix is a rigid motion (orthonormal rotation
    block with determinant +1, homogeneous last row), checked with numpy."""
    T = random_element(G, seed, batch, dtype)
    M = T.as_matrix()
    assert M.dtype == dtype and M.shape == (*batch, G.matrix_dim, G.matrix_dim)
    back = G.from_matrix(M)
    assert back.parameters().dtype == dtype and back.get_batch_axes() == batch
    assert_close(back.as_matrix(), M, dtype, 2)
    # The matrix is a rigid motion (a similarity for Sim(3)): its linear block is s R with
    # R orthonormal, det R = +1 and s = 1 unless the group has a scale; the rows below
    # are the identity's.
    n = G.space_dim
    A = to_np(M)[..., :n, :n]
    s = np.cbrt(np.linalg.det(A)) if has_scale(G) else np.ones(batch)
    R = A / s[..., None, None]
    assert_close(np.swapaxes(R, -1, -2) @ R, identity_matrices(G, batch)[..., :n, :n], dtype, 2)
    assert_close(np.linalg.det(R), np.ones(batch), dtype, 2)
    np.testing.assert_array_equal(to_np(M)[..., n:, :], identity_matrices(G, batch)[..., n:, :])


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
    """hat places the coordinates on the generators of conftest exactly (``hat_ref``), and
    vee reads them back exactly, from the library's hat and from the reference one."""
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
    """vee reads the generator coefficients (documented: the symmetric part is ignored; for
    Sim(3), whose σI is symmetric, the traceless symmetric part)."""
    x = random_tangent(G, seed, batch, dtype)
    n = G.space_dim
    A = np.random.default_rng(seed).normal(size=(*batch, n, n))
    S = np.zeros((*batch, G.matrix_dim, G.matrix_dim))
    S[..., :n, :n] = A + np.swapaxes(A, -1, -2)
    if has_scale(G):
        trace = np.trace(S[..., :n, :n], axis1=-2, axis2=-1)
        S[..., :n, :n] -= trace[..., None, None] / n * np.eye(n)
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
    """T.apply(p) == M p (SO) or (M [p; 1])[:n] (SE) in numpy; ``T @ p`` is the same
    call, and unbatched points broadcast against the batch."""
    T = random_element(G, seed, batch, dtype)
    p = random_points(G, seed, batch, dtype)
    got = T.apply(p)
    assert got.dtype == dtype and got.shape == (*batch, G.space_dim)
    assert_close(got, homogeneous_apply(G, T.as_matrix(), p), dtype, 4)
    np.testing.assert_array_equal(to_np(T @ p), to_np(got))
    # Unbatched points broadcast against the batch.
    got1 = T.apply(p[(0,) * len(batch)])
    assert_close(
        got1,
        homogeneous_apply(
            G, T.as_matrix(), np.broadcast_to(to_np(p[(0,) * len(batch)]), (*batch, G.space_dim))
        ),
        dtype,
        4,
    )


@over_cases
@given(seed=seeds)
def test_multiply_is_matrix_product(G, batch, dtype, seed):
    """T.multiply(U) is the numpy product of the matrices; ``T @ U`` is the same call."""
    T = random_element(G, seed, batch, dtype)
    U = random_element(G, seed + 1, batch, dtype)
    TU = T.multiply(U)
    assert TU.parameters().dtype == dtype and TU.get_batch_axes() == batch
    assert_close(TU.as_matrix(), to_np(T.as_matrix()) @ to_np(U.as_matrix()), dtype, 4)
    np.testing.assert_array_equal(to_np((T @ U).parameters()), to_np(TU.parameters()))


@over_cases
@given(seed=seeds)
def test_inverse_is_matrix_inverse(G, batch, dtype, seed):
    """T.inverse() is numpy's inverse of the matrix."""
    T = random_element(G, seed, batch, dtype)
    Ti = T.inverse()
    assert Ti.parameters().dtype == dtype
    assert_close(Ti.as_matrix(), np.linalg.inv(to_np(T.as_matrix())), dtype, 4)


# ---------------------------------------------------------------------------------
# normalize.


@over_cases
@given(seed=seeds, scale=st.floats(0.5, 2.0))
def test_normalize(G, batch, dtype, seed, scale):
    """normalize is a projection: unit elements are fixed, a scaled rotation part is
    brought back to the same element, and normalizing twice changes nothing."""
    T = random_element(G, seed, batch, dtype)
    N = T.normalize()
    assert N.parameters().dtype == dtype
    assert_close(N.parameters(), T.parameters(), dtype, 2)
    k = rotation_params(G)
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
    k = rotation_params(G)
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
    """jlog == the autodiff reference at the delicate elements of ``special_tangents``
    (zero, 1e-12, pure and long translations, π − 1e-6), and is finite there."""
    T = G.exp(special_tangents(G, dtype))
    # exclude the exact-π element: log is not differentiable there (branch cut).
    keep = rotation_angle(G, T.log()) < 3.1
    T = G(jnp.asarray(np.asarray(T.parameters())[keep]))
    J = T.jlog()
    ref = _jlog_by_autodiff(T)
    assert np.all(np.isfinite(to_np(J)))
    assert_close(J, ref, dtype, 16)


# ---------------------------------------------------------------------------------
# Random elements.


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
    for G in SE_GROUPS:
        t = to_np(G.sample_uniform(key, (n,)).translation()).ravel()
        assert scipy.stats.kstest(t, lambda x: (x + 1) / 2).pvalue > 1e-3
