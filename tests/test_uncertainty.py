"""jaxlie_geo.uncertainty against Monte Carlo: the first-order propagated covariances are the
covariances of the actual perturbed results, ``sample`` draws the covariance it is given, and
``mean`` returns the centre of symmetric samples.

Convention under test: an uncertain element is ``T̄ @ exp(δ)``, ``δ ~ N(0, Σ)``; the
covariance of a result ``f`` is that of ``log(f(T̄)⁻¹ f(T̄ ⊕ δ))``. With perturbations of
size σ = 0.01 the first-order error is O(σ) relative (≈1%) and the Monte-Carlo error with
N = 100 000 draws is ≈ √(2/N) ≈ 0.5% per entry; the bound is 4% of the largest entry.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import (
    is_se,
    over_groups,
    over_non_abelian_groups,
    random_element,
    random_points,
    to_np,
)

from jaxlie_geo import SE2, SE3, SO3, uncertainty

N_MC = 100_000
SIGMA = 0.01
DTYPE = jnp.float64


def _random_cov(k: int, seed: int, scale: float = SIGMA) -> np.ndarray:
    """A well-conditioned SPD matrix with standard deviations ≈ scale and correlations."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(k, k))
    Q, _ = np.linalg.qr(A)
    return scale**2 * (Q * rng.uniform(0.3, 1.5, size=k)) @ Q.T


def _draws(key, cov: np.ndarray, n: int = N_MC) -> jax.Array:
    L = np.linalg.cholesky(cov)
    z = jax.random.normal(key, (n, cov.shape[0]), DTYPE)
    return z @ jnp.asarray(L).T


def _empirical_cov(x) -> np.ndarray:
    x = to_np(x)
    x = x - x.mean(axis=0)
    return x.T @ x / (x.shape[0] - 1)


def _assert_cov_close(got, want, rel: float = 0.04):
    got, want = to_np(got), np.asarray(want)
    scale = np.max(np.abs(want))
    assert np.max(np.abs(got - want)) <= rel * scale, (got, want)


@over_groups
def test_propagate_compose_independent_and_correlated(G):
    """``propagate_compose`` equals the Monte-Carlo covariance of log((ab)⁻¹ (a⊕δa)(b⊕δb)), for
    independent operands and for correlated ones (an asymmetric cross covariance); ignoring
    the correlation is measurably wrong."""
    k = G.tangent_dim
    a, b = random_element(G, 1, (), DTYPE), random_element(G, 2, (), DTYPE)
    cov_a, cov_b = _random_cov(k, 1), _random_cov(k, 2)
    ka, kb, kj = jax.random.split(jax.random.key(0), 3)
    da, db = _draws(ka, cov_a), _draws(kb, cov_b)
    ab_inv = (a @ b).inverse()

    def residual(da, db):
        return (ab_inv @ a @ G.exp(da) @ b @ G.exp(db)).log()

    mc = _empirical_cov(jax.jit(residual)(da, db))
    _assert_cov_close(uncertainty.propagate_compose(a, cov_a, b, cov_b), mc)

    # correlated operands: one joint Gaussian over (δa, δb) whose cross block E[δa δbᵀ] is
    # not symmetric (a symmetric one cannot tell J_a Σ_ab J_bᵀ from J_b Σ_ab J_aᵀ)
    # δb = M δa + ε, M a random rotation scaled by 0.9: E[δa δbᵀ] = C Mᵀ
    C = _random_cov(k, 3)
    M = 0.9 * np.linalg.qr(np.random.default_rng(4).normal(size=(k, k)))[0]
    cab = C @ M.T
    joint = np.block([[C, cab], [cab.T, M @ C @ M.T + 0.2 * C]])
    assert k == 1 or np.abs(cab - cab.T).max() > 0.5 * np.abs(cab).max()  # SO2: 1×1
    d = _draws(kj, joint)
    mc = _empirical_cov(jax.jit(residual)(d[:, :k], d[:, k:]))
    got = uncertainty.propagate_compose(a, joint[:k, :k], b, joint[k:, k:], cov_ab=joint[:k, k:])
    _assert_cov_close(got, mc)
    # and ignoring the correlation is measurably wrong (the test can fail)
    wrong = uncertainty.propagate_compose(a, joint[:k, :k], b, joint[k:, k:])
    assert np.max(np.abs(to_np(wrong) - mc)) > 0.1 * np.max(np.abs(mc))


@over_groups
def test_propagate_inverse(G):
    """``propagate_inverse`` equals the Monte-Carlo covariance of log(a (a⊕δ)⁻¹)."""
    a = random_element(G, 4, (), DTYPE)
    cov = _random_cov(G.tangent_dim, 4)
    d = _draws(jax.random.key(1), cov)
    residual = jax.jit(lambda d: (a @ (a @ G.exp(d)).inverse()).log())  # log(ā⁻¹⁻¹ (a⊕δ)⁻¹)
    _assert_cov_close(uncertainty.propagate_inverse(a, cov), _empirical_cov(residual(d)))


@over_groups
def test_propagate_apply_with_and_without_point_noise(G):
    """``propagate_apply`` equals the Monte-Carlo covariance of (T⊕δ)(p + ε), without and with
    point noise ε."""
    T = random_element(G, 5, (), DTYPE)
    p = random_points(G, 5, (), DTYPE) * 3.0
    cov_T = _random_cov(G.tangent_dim, 5)
    cov_p = _random_cov(G.space_dim, 6, scale=0.02)
    kT, kp = jax.random.split(jax.random.key(2))
    dT, dp = _draws(kT, cov_T), _draws(kp, cov_p)
    moved = jax.jit(lambda dT, dp: (T @ G.exp(dT)) @ (p + dp))
    _assert_cov_close(uncertainty.propagate_apply(T, cov_T, p), _empirical_cov(moved(dT, 0.0 * dp)))
    _assert_cov_close(
        uncertainty.propagate_apply(T, cov_T, p, cov_points=cov_p),
        _empirical_cov(moved(dT, dp)),
    )


@over_groups
def test_sample_draws_the_given_covariance(G):
    """The tangents log(μ⁻¹ x) of ``sample``'s draws have mean 0 and the given covariance (Monte
    Carlo), with the mean's dtype and the requested batch."""
    mean = random_element(G, 7, (), DTYPE)
    cov = _random_cov(G.tangent_dim, 7, scale=0.05)
    draws = uncertainty.sample(jax.random.key(3), mean, cov, batch_axes=(N_MC,))
    assert draws.get_batch_axes() == (N_MC,)
    assert draws.parameters().dtype == DTYPE
    tangents = to_np((mean.inverse() @ draws).log())
    # exactly exp(L z) about the mean: the tangents are Gaussian with covariance Σ
    _assert_cov_close(_empirical_cov(tangents), cov, rel=0.03)
    assert np.max(np.abs(tangents.mean(axis=0))) < 5 * 0.05 / np.sqrt(N_MC) * 3


def test_sample_batched_means_and_float32():
    """``sample`` with a batch of float32 means, and with a batched covariance that broadcasts
    against them, gives draws of batch (draws, *broadcast batch) in float32."""
    means = random_element(SE3, 8, (4,), jnp.float32)
    draws = uncertainty.sample(jax.random.key(4), means, np.eye(6, dtype=np.float32) * 1e-4, (5,))
    assert draws.get_batch_axes() == (5, 4)
    assert draws.parameters().dtype == jnp.float32
    # a batched covariance broadcasts with the mean's batch, as documented
    covs = np.broadcast_to(np.eye(6, dtype=np.float32) * 1e-4, (3, 1, 6, 6))
    assert uncertainty.sample(jax.random.key(4), means, covs, (5,)).get_batch_axes() == (5, 3, 4)


@over_groups
def test_mean_of_symmetric_samples_is_the_centre(G):
    """x = c ⊕ ±δᵢ: the right-invariant-residual mean returns c (to rounding)."""
    c = random_element(G, 9, (), DTYPE)
    rng = np.random.default_rng(9)
    # SO3/SE3: δ and −δ are symmetric only to first order in the fixed point of
    # μ ← μ exp(Σ log(μ⁻¹ x)); log(c⁻¹ c exp(±δ)) = ±δ exactly, so μ = c is a fixed point.
    d = rng.normal(scale=0.3, size=(8, G.tangent_dim))
    xs = c @ G.exp(np.concatenate([d, -d]))
    mu = jax.jit(uncertainty.mean)(xs)
    np.testing.assert_allclose(to_np(mu.as_matrix()), to_np(c.as_matrix()), atol=1e-12)
    # started elsewhere, it still converges to the centre
    mu2 = uncertainty.mean(xs, init=c @ G.exp(np.full(G.tangent_dim, 0.2)))
    np.testing.assert_allclose(to_np(mu2.as_matrix()), to_np(c.as_matrix()), atol=1e-10)


def test_mean_weights_batches_and_errors():
    """``mean`` on the one-parameter subgroup through two poses, where the weighted fixed point
    is known in closed form (a ⊕ β log(a⁻¹ b), β = w_b / (w_a + w_b), negative weights
    included); default weights, the iteration cap, and an unbatched input's error."""
    a = random_element(SE3, 10, (3,), DTYPE)
    b = a @ SE3.exp(np.array([0.4, -0.2, 0.1, 0.3, 0.0, -0.2]))
    xs = SE3(jnp.stack([a.parameters(), b.parameters()]))  # batch (2, 3): 3 means of 2
    only_a = uncertainty.mean(xs, weights=np.array([1.0, 0.0]))
    np.testing.assert_allclose(to_np(only_a.parameters()), to_np(a.parameters()), atol=1e-12)
    # equal weights of two points: the geodesic midpoint a ⊕ ½ log(a⁻¹ b)
    mid = uncertainty.mean(xs, weights=np.array([2.0, 2.0]))
    np.testing.assert_allclose(
        to_np(mid.as_matrix()), to_np(a.interpolate(b, 0.5).as_matrix()), atol=1e-12
    )
    # Two points, weights (w_a, w_b): the fixed point is a ⊕ β log(a⁻¹ b), β = w_b/(w_a + w_b)
    # (on the one-parameter subgroup: Σ wᵢ log(μ⁻¹ xᵢ) = (β − s) log(a⁻¹ b) at μ = a ⊕ s ·).
    # Negative weights, documented as the affine combination, extrapolate.
    for w_a, w_b in ((3.0, 1.0), (-1.0, 2.0), (-2.0, 1.0), (2.0, -1.0)):
        got = uncertainty.mean(xs, weights=np.array([w_a, w_b]))
        want = a.interpolate(b, w_b / (w_a + w_b))
        np.testing.assert_allclose(to_np(got.as_matrix()), to_np(want.as_matrix()), atol=1e-12)
    # default weights are 1/n: two points give the midpoint (1/(n−1) over-relaxes and
    # oscillates about it)
    np.testing.assert_allclose(
        to_np(uncertainty.mean(xs).as_matrix()),
        to_np(a.interpolate(b, 0.5).as_matrix()),
        atol=1e-12,
    )
    # the iteration cap: 0 iterations return the start (the first pose), 1 iteration is one
    # step μ₁ = x₀ ⊕ mean_i log(x₀⁻¹ xᵢ), written out here
    np.testing.assert_array_equal(
        to_np(uncertainty.mean(xs, max_iters=0).parameters()), to_np(a.parameters())
    )
    step = a @ SE3.exp(0.5 * (a.inverse() @ a).log() + 0.5 * (a.inverse() @ b).log())
    np.testing.assert_allclose(
        to_np(uncertainty.mean(xs, max_iters=1).as_matrix()), to_np(step.as_matrix()), atol=1e-12
    )
    with pytest.raises(ValueError, match="at least one batch axis"):
        uncertainty.mean(SO3.identity())
    with pytest.raises(ValueError, match=r"weights.*\(2,\)"):
        uncertainty.mean(xs, weights=np.ones(3))
    with pytest.raises(ValueError, match="empty"):
        uncertainty.mean(SE3.identity((0, 3)))
    for tol in (0.0, -1e-6, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="tol"):
            uncertainty.mean(xs, tol=tol)


def test_mean_ignores_a_nan_element_in_the_stopping_test():
    """Two means in one batch: a NaN among the poses of the second leaves the first equal to
    its mean alone, at its fixed point; the second is NaN."""
    # batch (5, 2): two means of five; a NaN among the poses of the second must not stop
    # the iteration of the first (a NaN update compares false against tol).
    x = np.random.default_rng(4).normal(size=(5, 2, 6)) * 0.3
    poses = SE3.exp(x)
    clean = uncertainty.mean(poses)
    p = np.array(poses.parameters())
    p[2, 1, 0] = np.nan
    got = uncertainty.mean(SE3(jnp.asarray(p)))
    np.testing.assert_allclose(to_np(got.parameters()[0]), to_np(clean.parameters()[0]), atol=1e-12)
    assert np.all(np.isnan(to_np(got.parameters()[1])))
    # the clean column is the fixed point: its update is below the default tolerance
    r = (got[0].inverse()[None] @ poses[:, 0]).log()
    assert np.max(np.abs(to_np(jnp.mean(r, axis=0)))) < 1e-12


@over_groups
def test_propagation_batched_and_dtype(G):
    """Batched propagation keeps the batch and the dtype (float32 and float64) and returns
    symmetric positive semi-definite covariances; covariances of the wrong size raise
    ValueError naming the argument."""
    for dtype in (jnp.float32, jnp.float64):
        a = random_element(G, 11, (2, 3), dtype)
        k = G.tangent_dim
        cov = np.broadcast_to(np.eye(k, dtype=dtype) * 1e-3, (3, k, k))
        out = uncertainty.propagate_compose(a, cov, a, cov)
        assert out.shape == (2, 3, G.tangent_dim, G.tangent_dim) and out.dtype == dtype
        inv = uncertainty.propagate_inverse(a, cov)
        assert inv.shape == (2, 3, G.tangent_dim, G.tangent_dim) and inv.dtype == dtype
        # symmetric positive semi-definite
        o = to_np(out)
        np.testing.assert_allclose(o, np.swapaxes(o, -1, -2), rtol=1e-5, atol=1e-9)
        assert np.all(np.linalg.eigvalsh(o.astype(np.float64)) > -1e-9)
    with pytest.raises(ValueError, match="cov_a"):
        uncertainty.propagate_inverse(random_element(G, 1, (), DTYPE), np.eye(G.tangent_dim + 1))
    if is_se(G):
        with pytest.raises(ValueError, match="cov_points"):
            uncertainty.propagate_apply(
                random_element(G, 1, (), DTYPE),
                np.eye(G.tangent_dim),
                np.zeros(G.space_dim),
                cov_points=np.eye(G.space_dim + 1),
            )


# ---------------------------------------------------------------------------------
# Derivatives of `mean`: the implicit function theorem at the fixed point, in forward and
# reverse mode and to second order, against a closed form (SO2) and finite differences of
# the iteration itself (the other groups).


def test_mean_derivatives_closed_form_so2():
    """Angles within a half-turn of each other: the mean is Σ wᵢθᵢ / S (S = Σ wᵢ), so
    ∂μ/∂θⱼ = wⱼ/S, ∂μ/∂wⱼ = (θⱼ − μ)/S and ∂²μ/∂wⱼ∂wₖ = −((θⱼ − μ) + (θₖ − μ))/S²."""
    from jaxlie_geo import SO2

    rng = np.random.default_rng(21)
    th, w = rng.uniform(-1.0, 1.0, 6), rng.uniform(0.5, 2.0, 6)
    S = w.sum()
    mu = (w * th).sum() / S

    def f(th, w):
        return uncertainty.mean(SO2.from_radians(th), w).as_radians()

    np.testing.assert_allclose(float(f(th, w)), mu, rtol=1e-14)
    for jac in (jax.jacfwd, jax.jacrev):
        np.testing.assert_allclose(to_np(jax.jit(jac(f))(th, w)), w / S, rtol=1e-13)
        np.testing.assert_allclose(
            to_np(jax.jit(jac(f, 1))(th, w)), (th - mu) / S, rtol=1e-12, atol=1e-15
        )
    want = -((th - mu)[:, None] + (th - mu)[None, :]) / S**2
    hessian = jax.jit(lambda th, w: (jax.hessian(f, 1)(th, w), jax.hessian(f)(th, w)))
    h_w, h_th = hessian(th, w)
    np.testing.assert_allclose(to_np(h_w), want, rtol=1e-11, atol=1e-15)
    np.testing.assert_allclose(to_np(h_th), 0.0, atol=1e-14)
    # float32 follows
    g32 = jax.jit(jax.grad(f))(th.astype(np.float32), w.astype(np.float32))
    assert g32.dtype == jnp.float32
    np.testing.assert_allclose(to_np(g32), w / S, rtol=1e-6)


@over_non_abelian_groups
def test_mean_derivatives_against_finite_differences(G):
    """The non-abelian groups (SO2's mean is a weighted average of angles, checked in closed
    form by test_mean_derivatives_closed_form_so2). Three means of six poses (batch (6, 3))
    and weights: the gradient against central
    differences of the converged iteration (step 1e-5 in float64: truncation ≈ 1e-10,
    rounding ≈ 1e-11), forward against reverse mode, and (one group each, the rule being
    the same code for all: it costs seconds of compile) a Hessian-vector product against
    differences of the gradient, and vmap."""
    rng = np.random.default_rng(22)
    x = rng.normal(size=(6, 3, G.tangent_dim)) * 0.4
    w = rng.uniform(0.5, 2.0, 6)
    c = rng.normal(size=(3, G.tangent_dim))

    def g(x, w):
        return jnp.sum(jnp.sin(uncertainty.mean(G.exp(x), w).log() + c))

    h = 1e-5
    dx, dw = rng.normal(size=x.shape), rng.normal(size=w.shape)
    grad = jax.jit(jax.grad(g, (0, 1)))
    gx, gw = grad(x, w)
    g_jit = jax.jit(g)
    fd = (g_jit(x + h * dx, w + h * dw) - g_jit(x - h * dx, w - h * dw)) / (2 * h)
    np.testing.assert_allclose(float(jnp.sum(gx * dx) + jnp.sum(gw * dw)), float(fd), rtol=1e-8)
    if G is SE3:

        def m(w):
            return uncertainty.mean(G.exp(x), w).log()

        fwd, rev = jax.jit(lambda w: (jax.jacfwd(m)(w), jax.jacrev(m)(w)))(w)
        np.testing.assert_allclose(to_np(fwd), to_np(rev), rtol=1e-11, atol=1e-13)
    if G is SE2:
        # Hessian along dx against differences of the gradient
        def gx_of(x):
            return grad(x, w)[0]

        hvp = jax.jit(lambda x, w, dx: jax.jvp(jax.grad(g), (x, w), (dx, jnp.zeros_like(w)))[1])
        Hd = hvp(x, w, dx)
        fdH = (gx_of(x + h * dx) - gx_of(x - h * dx)) / (2 * h)
        np.testing.assert_allclose(to_np(Hd), to_np(fdH), atol=1e-8 * np.max(np.abs(to_np(fdH))))
    if G is SO3:
        # batched over independent problems under vmap: each row as alone
        gb = jax.jit(jax.vmap(grad))(np.stack([x, 0.5 * x]), np.stack([w, w]))
        np.testing.assert_allclose(to_np(gb[0][0]), to_np(gx), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(to_np(gb[1][0]), to_np(gw), rtol=1e-12, atol=1e-14)


def test_mean_gradient_of_a_clean_mean_beside_a_nan_one():
    """The gradient of a clean mean is unchanged by a NaN among the poses of another mean in
    the same batch; the other's gradient is NaN (0 × NaN, as everywhere in JAX)."""
    # two means; NaN among the poses of the second leaves the first's gradient as alone
    # (the second's is NaN, even where its cotangent is zero: 0 × NaN, as everywhere in JAX)
    x = np.random.default_rng(23).normal(size=(5, 2, 6)) * 0.3

    def g(x):
        return jnp.sum(uncertainty.mean(SE3.exp(x)).log() ** 2, axis=-1)

    bad = x.copy()
    bad[2, 1, 0] = np.nan
    grad = jax.jit(jax.grad(lambda x: g(x)[0]))
    clean, got = grad(x), grad(bad)
    np.testing.assert_allclose(to_np(got[:, 0]), to_np(clean[:, 0]), rtol=1e-12, atol=1e-15)
    assert np.all(np.isnan(to_np(got[:, 1])))
