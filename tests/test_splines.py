"""Cumulative B-splines (``jaxlie_geo.splines``) against independent references: the
de Boor–Cox recursion in exact fractions, ``scipy.linalg.expm``/``logm`` of the matrices,
motions of constant body velocity (which every degree reproduces exactly), autodiff of the
curve, ``jax.jacfwd`` through right perturbations of the control points, and recovery of a
known spline by the fit.

Compiling dominates: every group runs every degree in the exact checks (the constant
velocity, the knots); the autodiff references, third derivatives through the curve, run
on every group at degree 5 (every term of the recursions) and on SE3 at every degree. The
splines have 8 control points and are evaluated at 5 times, with one ``t0`` and ``dt``,
so the tests share their compiled programs.
"""

from __future__ import annotations

import dataclasses
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import (
    EPS,
    GROUPS,
    dtype_name,
    expm_ref,
    group_name,
    hat_ref,
    logm_ref,
    over_dtypes,
    over_groups,
    to_np,
    vee_ref,
)

from jaxlie_geo import SE3, SO2, SO3, splines
from jaxlie_geo.splines import Spline, SplineTime

T0, DT = 0.5, 0.3
N = 8  # control points
DEGREES = (1, 2, 3, 4, 5)
GROUP_DEGREES = [pytest.param(G, d, id=f"{G.__name__}-degree{d}") for G in GROUPS for d in DEGREES]
AUTODIFF_CASES = [
    pytest.param(G, d, id=f"{G.__name__}-degree{d}")
    for G in GROUPS
    for d in (DEGREES if G is SE3 else (5,))
]


def _control_points(G, n, seed=0, scale=0.5, dtype=jnp.float64, batch=()):
    rng = np.random.default_rng(seed)
    return G.exp(jnp.asarray(rng.normal(size=(n, *batch, G.tangent_dim)) * scale, dtype))


# -- the blending matrix ---------------------------------------------------------------


def _de_boor_cox(i: int, order: int, x: Fraction) -> Fraction:
    """B_{i,order}(x) on the integer knots (Cox 1972, de Boor 1972)."""
    if order == 1:
        return Fraction(1) if i <= x < i + 1 else Fraction(0)
    p = order - 1
    return (x - i) / p * _de_boor_cox(i, p, x) + (i + order - x) / p * _de_boor_cox(i + 1, p, x)


@pytest.mark.parametrize("order", range(2, 7))
def test_cumulative_basis_is_the_de_boor_cox_basis(order):
    """λ_j(u) = Σ_{i ≥ j} B_i(k − 1 + u), exactly, at k + 2 points of [0, 1)."""
    M = splines.cumulative_basis(order)
    for u in [Fraction(m, order + 2) for m in range(order + 2)]:
        basis = [_de_boor_cox(i, order, order - 1 + u) for i in range(order)]
        assert sum(basis) == 1
        for j in range(order):
            assert sum(M[j][n] * u**n for n in range(order)) == sum(basis[j:])


# -- exact references ----------------------------------------------------------------


@pytest.mark.parametrize(("G", "degree"), GROUP_DEGREES)
def test_constant_body_velocity_is_reproduced(G, degree):
    """Control points T₀ exp(i Δt ξ): every degree gives T₀ exp(((t − t0)/Δt + (k − 2)/2) Δt ξ)
    (the B-splines' linear precision), body velocity ξ, zero acceleration and jerk, and
    world velocity Ad(T) ξ (references by scipy's expm)."""
    rng = np.random.default_rng(3)
    xi = rng.normal(size=G.tangent_dim) * 0.7
    M0 = expm_ref(G, rng.normal(size=G.tangent_dim) * 0.5)
    cp = G.from_matrix(jnp.asarray(M0 @ expm_ref(G, np.arange(N)[:, None] * DT * xi)))
    t = T0 + np.array([0.0, 0.37, 1.0, 1.5, 2.2]) * DT
    sp = Spline(cp, degree=degree, t0=T0, dt=DT)
    ev = sp.evaluate(t, derivatives=3)
    shift = (t - T0) / DT + (degree - 1) / 2
    want = M0 @ expm_ref(G, shift[:, None] * DT * xi)
    np.testing.assert_allclose(to_np(ev.value.as_matrix()), want, atol=1e-13)
    np.testing.assert_allclose(
        to_np(ev.velocity), np.broadcast_to(xi, ev.velocity.shape), atol=1e-13
    )
    np.testing.assert_allclose(to_np(ev.acceleration), 0, atol=1e-12)
    np.testing.assert_allclose(to_np(ev.jerk), 0, atol=1e-10)
    world = vee_ref(G, want @ hat_ref(G, xi) @ np.linalg.inv(want))
    np.testing.assert_allclose(to_np(sp.velocity(t, frame="world")), world, atol=1e-12)


@over_groups
def test_degree_one_is_the_piecewise_geodesic(G):
    """Degree 1: T_s expm(u logm(T_s⁻¹ T_{s+1})) on each segment, through the control
    points at the knots."""
    cp = _control_points(G, N, seed=1)
    sp = Spline(cp, degree=1, t0=T0, dt=DT)
    M = to_np(cp.as_matrix())
    seg = np.array([0, 1, 3, 5, 6])
    u = np.array([0.4, 0.9, 0.5, 0.1, 1.0])
    rel = logm_ref(np.linalg.inv(M[seg]) @ M[seg + 1])
    want = M[seg] @ np.stack([expm_ref(G, vee_ref(G, r * ui)) for r, ui in zip(rel, u)])
    got = sp.evaluate(T0 + (seg + u) * DT, 3).value.as_matrix()
    np.testing.assert_allclose(to_np(got), want, atol=1e-13)
    knots = np.array([0, 2, 3, 4, 7])
    at_knots = sp.evaluate(T0 + knots * DT, 3).value.as_matrix()
    np.testing.assert_allclose(to_np(at_knots), M[knots], atol=1e-14)


@over_groups
def test_continuity_across_every_knot(G):
    """C^(degree − 1): at each interior knot the end of segment s and the start of s + 1
    agree in value and in the derivatives of order < degree (to rounding); the
    derivative of order ``degree`` jumps (so the comparison can fail)."""
    cp = _control_points(G, N, seed=2, scale=0.8)
    for degree in DEGREES:
        sp = Spline(cp, degree=degree, t0=T0, dt=DT)
        s = np.minimum(np.arange(5), sp.num_segments - 2)  # the interior knots, 5 times
        left = sp.evaluate(SplineTime(jnp.asarray(s), jnp.ones(s.shape)), derivatives=3)
        right = sp.evaluate(SplineTime(jnp.asarray(s + 1), jnp.zeros(s.shape)), derivatives=3)
        gap = to_np(left.value._between(right.value).log())
        np.testing.assert_allclose(gap, 0, atol=1e-13)
        derivs = [left.velocity, left.acceleration, left.jerk]
        others = [right.velocity, right.acceleration, right.jerk]
        for order, (a, b) in enumerate(zip(derivs, others), start=1):
            jump = np.max(np.abs(to_np(a) - to_np(b)))
            scale = np.max(np.abs(to_np(a))) + 1.0
            if order < degree:
                assert jump <= 1e-11 * scale, (degree, order, jump)
            elif order == degree:
                assert jump > 1e-3 * scale, (degree, order, jump)


# -- derivatives and Jacobians against autodiff ------------------------------------


def _body_derivatives(sp, t):
    """ω, ω̇, ω̈ by forward-mode autodiff of the curve's matrix: ω = vee(T⁻¹ dT/dt)."""
    G = type(sp.control_points)

    def omega(tt):
        M = sp(tt).as_matrix()
        dM = jax.jacfwd(lambda x: sp(x).as_matrix())(tt)
        return G.vee(jnp.linalg.solve(M, dM))

    return jax.jit(
        jax.vmap(lambda tt: (omega(tt), jax.jacfwd(omega)(tt), jax.jacfwd(jax.jacfwd(omega))(tt)))
    )(t)


@pytest.mark.parametrize(("G", "degree"), AUTODIFF_CASES)
def test_derivatives_equal_autodiff_of_the_curve(G, degree):
    """Velocity, acceleration and jerk from the recursions equal autodiff of the value,
    to a few ulp of their scale (float64), inside segments and at their ends."""
    cp = _control_points(G, N, seed=4, scale=0.7)
    sp = Spline(cp, degree=degree, t0=T0, dt=DT)
    t = jnp.asarray(T0 + np.array([0.05, 0.6, 1.37, 2.01, 2.8]) * DT)
    ev = sp.evaluate(t, derivatives=3)
    refs = _body_derivatives(sp, t)
    speed = np.max(np.abs(to_np(refs[0])))
    for r, (got, want) in enumerate(zip((ev.velocity, ev.acceleration, ev.jerk), refs)):
        want = to_np(want)
        # the r-th derivative's natural scale: |ω|/Δtʳ (its reference is zero where the
        # degree is below r, up to the rounding of the autodiff)
        scale = max(np.max(np.abs(want)), speed / DT**r) + 1.0
        err = np.max(np.abs(to_np(got) - want))
        assert err <= 64 * EPS[jnp.dtype(jnp.float64)] * scale, (r + 1, err, scale)


@pytest.mark.parametrize(("G", "degree"), AUTODIFF_CASES)
def test_control_point_jacobians_equal_jacfwd(G, degree):
    """Value, velocity and acceleration Jacobians equal ``jax.jacfwd`` through right
    perturbations T_m exp(δ_m) of the ``order`` control points each time depends on, and
    ``first`` is the segment's first control point."""
    cp = _control_points(G, N, seed=5, scale=0.7)
    sp = Spline(cp, degree=degree, t0=T0, dt=DT)
    t = T0 + np.array([0.0, 0.2, 1.5, 2.5, 2.99]) * DT
    where = sp.locate(t)
    jac = sp.jacobians(t)
    np.testing.assert_array_equal(np.asarray(jac.first), np.floor((t - T0) / DT).astype(int))
    k = sp.order

    def moved(delta, first, seg, frac):  # delta: (k, dim) on control points first … first+k−1
        idx = first + jnp.arange(k)
        p = cp.parameters()
        p = p.at[idx].set((G(p[idx]) @ G.exp(delta)).parameters())
        ev = dataclasses.replace(sp, control_points=G(p)).evaluate(SplineTime(seg, frac), 2)
        base = sp.evaluate(SplineTime(seg, frac), 0).value
        return base._between(ev.value).log(), ev.velocity, ev.acceleration

    zero = jnp.zeros((k, G.tangent_dim))
    refs = jax.jit(jax.vmap(jax.jacfwd(moved), in_axes=(None, 0, 0, 0)))(
        zero, jac.first, where.segment, where.fraction
    )
    for got, want in zip((jac.value, jac.velocity, jac.acceleration), refs):
        want = np.moveaxis(to_np(want), 2, 1)  # (N, dim, k, dim) → (N, k, dim, dim)
        scale = np.max(np.abs(want)) + 1.0
        np.testing.assert_allclose(to_np(got), want, atol=64 * EPS[jnp.dtype(jnp.float64)] * scale)


# -- batches, dtypes, time --------------------------------------------------------------


@over_dtypes
@pytest.mark.parametrize("G", [SO2, SE3], ids=group_name)
def test_batched_over_times_and_splines_keeps_the_dtype(G, dtype):
    """Two independent splines (control points of batch (n, 2)) at times of shape (3, 1):
    results of batch (3, 2), each equal to its own spline alone, in the control points'
    dtype; the Jacobians too."""
    cp = _control_points(G, 6, seed=6, dtype=dtype, batch=(2,))
    sp = Spline(cp, degree=3, t0=T0, dt=DT)
    t = T0 + np.array([[0.1], [1.2], [2.9]]) * DT
    ev, jac = sp.evaluate(t, 3), sp.jacobians(t)
    assert ev.value.get_batch_axes() == (3, 2) and ev.jerk.shape == (3, 2, G.tangent_dim)
    assert jac.value.shape == (3, 2, 4, G.tangent_dim, G.tangent_dim)
    for x in (ev.value.parameters(), ev.velocity, ev.acceleration, ev.jerk, jac.velocity):
        assert x.dtype == jnp.dtype(dtype)
    for b in range(2):
        one = Spline(cp[:, b], degree=3, t0=T0, dt=DT)
        ev1, jac1 = one.evaluate(t[:, 0], 3), one.jacobians(t[:, 0])
        rtol = 1e-6 if dtype == jnp.float32 else 1e-14
        for got, want in [
            (ev.value.parameters()[:, b], ev1.value.parameters()),
            (ev.acceleration[:, b], ev1.acceleration),
            (jac.acceleration[:, b], jac1.acceleration),
        ]:
            np.testing.assert_allclose(to_np(got), to_np(want), rtol=rtol, atol=rtol)


def test_times_outside_the_interval():
    """A concrete time outside [t0, t_end] raises ``ValueError`` naming the interval; the
    interval's end is the end of the last segment; a traced time is clamped."""
    sp = Spline(_control_points(SO3, 6), degree=3, t0=T0, dt=DT)
    lo, hi = sp.interval
    assert (lo, hi) == (T0, T0 + 3 * DT)
    for bad in (lo - 1e-9, hi + 1e-9, np.array([lo, np.nan])):
        with pytest.raises(ValueError, match=r"outside the valid interval \[0\.5, 1\.4"):
            sp(bad)
    end = sp.locate(hi)
    assert int(end.segment) == 2 and float(end.fraction) == 1.0
    clamped = jax.jit(lambda t: sp(t).parameters())(jnp.array([lo - 5.0, hi + 5.0]))
    want = sp(np.array([lo, hi])).parameters()
    np.testing.assert_array_equal(np.asarray(clamped), np.asarray(want))


def test_float32_spline_far_from_its_start():
    """10⁵ s after t0 a float32 time is only known to 8 ms; a float32 spline located from
    float64 time stamps, integer nanoseconds or a ``SplineTime`` keeps the fraction of its
    25 s segments and agrees with the float64 spline to float32 rounding of the values."""
    n = 4003  # 4000 segments of 25 s: [0, 10⁵]
    cp64 = _control_points(SO3, n, seed=7, scale=0.3)
    cp32 = SO3(cp64.parameters().astype(jnp.float32))
    t = 1e5 - np.array([12.3456789, 0.0017, 24.9999])
    want = Spline(cp64, degree=3, t0=0.0, dt=25.0)(t).as_matrix()
    by_float = Spline(cp32, degree=3, t0=0.0, dt=25.0)(t)
    t_ns = np.round(t * 1e9).astype(np.int64)
    by_int = Spline(cp32, degree=3, t0=0, dt=25_000_000_000)(t_ns)
    seg = np.floor(t / 25.0).astype(np.int32)
    where = SplineTime(jnp.asarray(seg), jnp.asarray((t - 25.0 * seg) / 25.0, jnp.float32))
    sp32 = Spline(cp32, degree=3, t0=0.0, dt=25.0)
    by_segment = jax.jit(lambda w: sp32(w).as_matrix())(where)
    for got in (by_float.as_matrix(), by_int.as_matrix(), by_segment):
        assert got.dtype == jnp.float32
        np.testing.assert_allclose(to_np(got), to_np(want), atol=8 * EPS[jnp.dtype(jnp.float32)])


def test_invalid_splines_raise():
    cp = _control_points(SE3, 4)
    for kwargs, match in [
        ({"degree": 0}, "degree"),
        ({"degree": 6}, "degree"),
        ({"degree": 4}, "at least 5 control points"),
        ({"dt": 0.0}, "positive"),
        ({"t0": float("nan")}, "finite"),
    ]:
        with pytest.raises(ValueError, match=match):
            Spline(cp, **kwargs)
    with pytest.raises(TypeError, match="group element"):
        Spline(jnp.zeros((4, 7)))
    with pytest.raises(ValueError, match="frame"):
        Spline(cp, degree=3).velocity(0.5, frame="spatial")


def test_gradient_with_respect_to_the_control_points():
    """A spline is a pytree of its control points: ``jax.grad`` of a loss gives a spline of
    parameter gradients, equal to central differences along a random direction."""
    cp = _control_points(SE3, 6, seed=8)
    t = T0 + np.array([0.3, 1.1, 2.6]) * DT
    target = _control_points(SE3, 3, seed=9)

    def loss(sp):
        ev = sp.evaluate(t, 1)
        return jnp.sum(target._between(ev.value).log() ** 2) + jnp.sum(ev.velocity**2)

    sp = Spline(cp, degree=3, t0=T0, dt=DT)
    g = jax.grad(loss)(sp)
    assert isinstance(g, Spline) and g.degree == 3
    d = np.random.default_rng(10).normal(size=cp.parameters().shape)
    h = 1e-6
    f = jax.jit(lambda p: loss(Spline(SE3(p), degree=3, t0=T0, dt=DT)))
    p = cp.parameters()
    fd = (f(p + h * d) - f(p - h * d)) / (2 * h)
    np.testing.assert_allclose(
        float(jnp.sum(g.control_points.parameters() * d)), float(fd), rtol=1e-7
    )


# -- fitting ------------------------------------------------------------------------


def test_fit_recovers_a_spline_from_its_samples():
    """Noise-free samples of a known cubic spline, fitted from the nearest-sample start:
    the cost falls to rounding and the control points are recovered."""
    truth = Spline(_control_points(SE3, 9, seed=11, scale=0.6), degree=3, t0=T0, dt=DT)
    t = np.linspace(*truth.interval, 120)
    result = splines.fit(t, truth(t), dt=DT, degree=3, t0=T0)
    assert result.converged and np.all(np.diff(result.costs) <= 0)
    assert result.costs[-1] < 1e-20 and result.costs[0] > 1e-3
    err = to_np(truth.control_points._between(result.spline.control_points).log())
    np.testing.assert_allclose(err, 0, atol=1e-9)


@pytest.mark.parametrize("dtype", [jnp.float64], ids=dtype_name)
def test_fit_rejects_inconsistent_input(dtype):
    poses = _control_points(SE3, 5, dtype=dtype)
    with pytest.raises(ValueError, match=r"shape \(N,\)"):
        splines.fit(np.zeros((5, 1)), poses, dt=0.1)
    with pytest.raises(ValueError, match="batch"):
        splines.fit(np.arange(4.0), poses, dt=0.1)


@over_groups
def test_adjoint_action_and_bracket_without_matrices(G):
    """The recursions' ``_adjoint_apply`` and ``_bracket`` equal ``adjoint() @ x`` and
    ``ad(a) @ b`` (against the Lie bracket of the reference generators), batched."""
    rng = np.random.default_rng(12)
    T = _control_points(G, 4, seed=13, scale=1.0)
    a, b = (jnp.asarray(rng.normal(size=(4, G.tangent_dim))) for _ in range(2))
    want = np.einsum("...ij,...j->...i", to_np(T.adjoint()), to_np(b))
    np.testing.assert_allclose(to_np(T._adjoint_apply(b)), want, atol=1e-14)
    A, B = hat_ref(G, a), hat_ref(G, b)
    np.testing.assert_allclose(to_np(G._bracket(a, b)), vee_ref(G, A @ B - B @ A), atol=1e-14)


def test_fit_is_the_shared_least_squares_loop_with_every_linear_solver():
    """A noisy fit of 300 control points from 3,000 samples: every linear solver of the
    least-squares loop shared with ``pose_graph.solve`` (LAPACK banded and dense Cholesky,
    QDLDL, CHOLMOD, conjugate gradients) reaches the same minimum (1e-10 relative) with the
    same control points (1e-8); ``"auto"`` is CHOLMOD, step for step; the minimum is a
    stationary point of the cost by ``jax.grad`` through the spline's evaluation."""
    n, per = 300, 10
    t = np.arange((n - 3) * per) * DT / per
    truth = Spline(_control_points(SE3, n, seed=21, scale=0.2), degree=3, t0=0.0, dt=DT)
    rng = np.random.default_rng(22)
    measured = truth(t) @ SE3.exp(jnp.asarray(rng.normal(scale=0.01, size=(len(t), 6))))
    fits = {
        name: splines.fit(t, measured, dt=DT, t0=0.0, linear_solver=name, tolerance=1e-14)
        for name in ("banded", "dense", "qdldl", "cholmod", "pcg", "auto")
    }
    want = fits["banded"]
    assert fits["auto"].costs.tolist() == fits["cholmod"].costs.tolist()
    for name, got in fits.items():
        assert got.converged, (name, got.stop_reason)
        np.testing.assert_allclose(got.costs[-1], want.costs[-1], rtol=1e-10, err_msg=name)
        err = to_np(want.spline.control_points._between(got.spline.control_points).log())
        np.testing.assert_allclose(err, 0, atol=1e-8, err_msg=name)
    assert want.costs[-1] < 0.5 * 6 * len(t) * 1e-4 < want.costs[0]

    def cost(delta, cp):  # on the tangent of every control point: T_m exp(δ_m)
        s = Spline(cp @ SE3.exp(delta), degree=3, t0=0.0, dt=DT)
        r = measured._between(s(t)).log()
        return 0.5 * jnp.sum(r * r)

    zero = jnp.zeros((n, 6))
    g = jax.grad(cost)(zero, want.spline.control_points)
    g0 = jax.grad(cost)(zero, truth.control_points)
    assert float(jnp.max(jnp.abs(g))) < 1e-7 * float(jnp.max(jnp.abs(g0)))
