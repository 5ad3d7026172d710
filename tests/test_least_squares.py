"""``jaxlie_geo.least_squares``: the solve against an independent solver (scipy's
``least_squares``, plain and with Huber's loss), optimality on groups, ``vmap`` against solving
each problem alone, the implicit derivative against central differences of the solution,
fixed variables, marginal covariances against (AᵀA)⁻¹, the stop reasons and the trace-time
errors. Float64 (the test suite's default); the problems are small so that each compiles once."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

import jaxlie_geo as jl
from jaxlie_geo import least_squares as ls

# -- a curve fit on arrays: y = a exp(b t) + c, against scipy ------------------------------

T = np.linspace(0.0, 2.0, 25)
Y = 1.5 * np.exp(-0.7 * T) + 0.3 + 0.01 * np.sin(7 * T)
Y_OUTLIERS = Y.copy()
Y_OUTLIERS[[3, 11, 19]] += np.array([0.8, -1.1, 0.9])


def _curve(p, data):
    t, y = data
    return jnp.atleast_1d(p[0] * jnp.exp(p[1] * t) + p[2] - y)


def _curve_factor(y, robust=None):
    n = T.shape[0]
    return ls.Factor(
        _curve, (0,), (jnp.zeros(n, jnp.int32),), (jnp.asarray(T), jnp.asarray(y)), robust
    )


def _scipy_fit(y, loss="linear", f_scale=1.0):
    fun = lambda p: p[0] * np.exp(p[1] * T) + p[2] - y  # noqa: E731
    return scipy.optimize.least_squares(
        fun, [1.0, 0.0, 0.0], loss=loss, f_scale=f_scale, xtol=1e-15, ftol=1e-15, gtol=1e-15
    ).x


@pytest.mark.parametrize("robust", [None, ("huber", 0.1)], ids=["plain", "huber"])
def test_curve_fit_matches_scipy(robust) -> None:
    y = Y if robust is None else Y_OUTLIERS
    sol = ls.solve([_curve_factor(y, robust)], (jnp.array([[1.0, 0.0, 0.0]]),), tolerance=1e-15)
    ref = _scipy_fit(y) if robust is None else _scipy_fit(y, loss="huber", f_scale=robust[1])
    assert bool(sol.converged), ls.StopReason(int(sol.stop_reason))
    np.testing.assert_allclose(np.asarray(sol.variables[0][0]), ref, rtol=1e-7, atol=1e-9)


# -- a small SE2 pose graph ----------------------------------------------------------------

N = 5
IA = jnp.array([0, 1, 2, 3, 0])
IB = jnp.array([1, 2, 3, 4, 4])


@jax.jit
def _graph_parameters():
    truth = jl.SE2.exp(jnp.array([[0.0, 0.0, 0.0], [1, 0.1, 0.3], [2, 0.5, 0.7], [2.5, 1.5, 1.2],
                                  [1.8, 2.2, 2.0]]))  # fmt: skip
    noise = 0.02 * jax.random.normal(jax.random.key(0), (IA.shape[0], 3))
    meas = (truth[IA].inverse() @ truth[IB]) @ jl.SE2.exp(noise)
    init = truth @ jl.SE2.exp(0.1 * jax.random.normal(jax.random.key(1), (N, 3)))
    starts = jl.SE2.exp(init.log()[None] + 0.05 * jax.random.normal(jax.random.key(2), (3, N, 3)))
    return truth.parameters(), meas.parameters(), init.parameters(), starts.parameters()


def _graph():
    truth, meas, init, starts = _graph_parameters()
    return jl.SE2(truth), jl.SE2(meas), jl.SE2(init), starts


def _between(a, b, z):
    return (z.inverse() @ (a.inverse() @ b)).log()


def _prior(a, z):
    return (z.inverse() @ a).log()


def _factors(meas, anchor):
    return [
        ls.Factor(_between, (0, 0), (IA, IB), meas),
        ls.Factor(_prior, (0,), (np.array([0]),), anchor),
    ]


def _solve_graph(meas_params, init_params, anchor_params):
    meas, init, anchor = jl.SE2(meas_params), jl.SE2(init_params), jl.SE2(anchor_params)
    return ls.solve(_factors(meas, anchor), (init,), tolerance=1e-14)


_solve_graph_jit = jax.jit(_solve_graph)


@jax.jit
def _tangent_gradient(meas_params, anchor_params, x_params):
    """The gradient of the cost in the right tangent at x, by autodiff (not the solver's
    normal equations)."""
    factors = _factors(jl.SE2(meas_params), jl.SE2(anchor_params))
    x = jl.SE2(x_params)
    return jax.grad(lambda d: ls.cost(factors, (x @ jl.SE2.exp(d),)))(jnp.zeros((N, 3)))


def test_pose_graph_reaches_a_stationary_point_and_vmap_equals_each_alone() -> None:
    truth, meas, init, starts = _graph()
    anchor = truth[np.array([0])].parameters()
    batched = jax.vmap(_solve_graph_jit, in_axes=(None, 0, None))(meas.parameters(), starts, anchor)
    for i in range(3):
        alone = _solve_graph_jit(meas.parameters(), starts[i], anchor)
        assert bool(alone.converged)
        np.testing.assert_allclose(
            batched.variables[0].parameters()[i], alone.variables[0].parameters(), atol=1e-12
        )
        assert float(alone.cost) < float(alone.initial_cost)
        grad = _tangent_gradient(meas.parameters(), anchor, alone.variables[0].parameters())
        assert float(jnp.max(jnp.abs(grad))) < 1e-9


@jax.jit
def _last_position_and_cost(meas_params, init_params, anchor_params):
    sol = _solve_graph_jit(meas_params, init_params, anchor_params)
    return jnp.sum(sol.variables[0].translation()[N - 1] ** 2) + sol.cost


def test_implicit_derivative_equals_central_differences() -> None:
    truth, meas, init, _ = _graph()
    anchor = truth[np.array([0])].parameters()
    p, x0 = meas.parameters(), init.parameters()
    g = jax.jit(jax.grad(_last_position_and_cost))(p, x0, anchor)
    assert bool(jnp.all(jnp.isfinite(g)))
    rng = np.random.default_rng(0)
    for _ in range(2):
        d = jnp.asarray(rng.standard_normal(p.shape))
        h = 1e-6
        fd = (
            _last_position_and_cost(p + h * d, x0, anchor)
            - _last_position_and_cost(p - h * d, x0, anchor)
        ) / (2 * h)
        np.testing.assert_allclose(float(jnp.sum(g * d)), float(fd), rtol=1e-6)
    # Asked for a decrease below rounding, the solve ends with no step lowering the cost and
    # λ grown past its limit; the derivative is still the optimum's.
    tight = jax.jit(jax.value_and_grad(_last_position_at_rounding, has_aux=True))
    (_, reason), g_tight = tight(p, x0, anchor)
    assert int(reason) == ls.StopReason.NO_STEP_LOWERS_COST
    np.testing.assert_allclose(np.asarray(g_tight), np.asarray(g), rtol=1e-7, atol=1e-9)


def _last_position_at_rounding(meas_params, init_params, anchor_params):
    meas, anchor = jl.SE2(meas_params), jl.SE2(anchor_params)
    sol = ls.solve(_factors(meas, anchor), (jl.SE2(init_params),), tolerance=1e-300)
    value = jnp.sum(sol.variables[0].translation()[N - 1] ** 2) + sol.cost
    return value, sol.stop_reason


def test_fixed_variables_stay_and_marginals_equal_the_linear_covariance() -> None:
    # A linear problem on arrays: r = A x − b per row, x in R², one set of 2 variables with
    # the second held fixed; the marginal covariance of a linear least-squares problem is
    # (AᵀA)⁻¹ exactly.
    rng = np.random.default_rng(1)
    A = rng.standard_normal((12, 2))
    b = rng.standard_normal(12)

    def row(x, data):
        a, bb = data
        return jnp.atleast_1d(a @ x - bb)

    factor = ls.Factor(row, (0,), (jnp.zeros(12, jnp.int32),), (jnp.asarray(A), jnp.asarray(b)))
    x0 = jnp.array([[0.0, 0.0], [5.0, -3.0]])
    sol = ls.solve([factor], (x0,), fixed=(jnp.array([False, True]),), tolerance=1e-14)
    np.testing.assert_array_equal(np.asarray(sol.variables[0][1]), [5.0, -3.0])
    np.testing.assert_allclose(
        np.asarray(sol.variables[0][0]), np.linalg.lstsq(A, b, rcond=None)[0], rtol=1e-10
    )
    one = ls.solve([factor], (x0[:1],), tolerance=1e-14)
    cov = ls.marginal_covariances([factor], one)
    np.testing.assert_allclose(np.asarray(cov), np.linalg.inv(A.T @ A), rtol=1e-10)


def test_stop_reasons() -> None:
    factor = _curve_factor(Y)
    x0 = (jnp.array([[1.0, 0.0, 0.0]]),)
    none = ls.solve([factor], x0, max_iterations=0)
    assert int(none.stop_reason) == ls.StopReason.MAX_ITERATIONS and int(none.iterations) == 0
    np.testing.assert_array_equal(np.asarray(none.variables[0]), np.asarray(x0[0]))
    assert not bool(none.converged)
    two = ls.solve([factor], x0, max_iterations=2)
    assert int(two.iterations) == 2 and int(two.stop_reason) == ls.StopReason.MAX_ITERATIONS
    # At (1, 0, 0) the columns of a and c are equal: a singular system, which Gauss–Newton
    # reports; from (1, −0.5, 0.1) it converges.
    singular = ls.solve([factor], x0, method="gn")
    assert int(singular.stop_reason) == ls.StopReason.NON_FINITE_STEP
    np.testing.assert_array_equal(np.asarray(singular.variables[0]), np.asarray(x0[0]))
    gn = ls.solve([factor], (jnp.array([[1.0, -0.5, 0.1]]),), method="gn", tolerance=1e-12)
    assert bool(gn.converged) and float(gn.damping) == 0.0
    np.testing.assert_allclose(np.asarray(gn.variables[0][0]), _scipy_fit(Y), rtol=1e-7)
    # A NaN in the data, eager and traced: both methods stop at once, not converged, the
    # values unchanged.
    bad = np.where(np.arange(Y.size) == 3, np.nan, Y)
    for method in ("lm", "gn"):
        eager = ls.solve([_curve_factor(bad)], x0, method=method)
        traced = jax.jit(lambda y, m=method: ls.solve([_curve_factor(y)], x0, method=m))(bad)
        for out in (eager, traced):
            assert int(out.stop_reason) == ls.StopReason.NON_FINITE_COST, method
            assert not bool(out.converged) and int(out.iterations) == 0
            np.testing.assert_array_equal(np.asarray(out.variables[0]), np.asarray(x0[0]))


def test_errors_name_the_problem() -> None:
    x = (jnp.zeros((2, 3)),)
    good = lambda v: v  # noqa: E731
    with pytest.raises(IndexError, match=r"outside \[0, 2\)"):
        ls.solve([ls.Factor(good, (0,), (jnp.array([0, 2]),))], x)
    with pytest.raises(ValueError, match="names variable set 1"):
        ls.solve([ls.Factor(good, (1,), (jnp.array([0]),))], x)
    with pytest.raises(ValueError, match="int array"):
        ls.solve([ls.Factor(good, (0,), (jnp.array([0.0]),))], x)
    with pytest.raises(ValueError, match="must return a vector"):
        jax.eval_shape(
            lambda: ls.solve([ls.Factor(lambda v: jnp.sum(v), (0,), (jnp.array([0]),))], x)
        )
    with pytest.raises(ValueError, match="exactly one batch axis"):
        ls.solve([ls.Factor(good, (0,), (jnp.array([0]),))], (jnp.zeros(3),))
    with pytest.raises(ValueError, match="method must be"):
        ls.solve([], x, method="newton")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="robust must be"):
        ls.Factor(good, (0,), (jnp.array([0]),), robust=("tukey", 1.0))  # type: ignore[arg-type]


def test_float32_problem_is_solved_in_float32() -> None:
    f = ls.Factor(
        _curve,
        (0,),
        (np.zeros(T.shape[0], np.int32),),
        (jnp.asarray(T, jnp.float32), jnp.asarray(Y, jnp.float32)),
    )
    sol = ls.solve([f], (jnp.array([[1.0, 0.0, 0.0]], jnp.float32),))
    assert sol.variables[0].dtype == jnp.float32 and sol.cost.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(sol.variables[0][0]), _scipy_fit(Y), rtol=2e-4)


# -- closed-form Jacobians -----------------------------------------------------------------


def _between_closed_form(a, b, z):
    """r = log(Z⁻¹ a⁻¹ b) and [∂r/∂δ_a, ∂r/∂δ_b] = J_r⁻¹(r) [−Ad(b⁻¹ a), I] (Solà, Deray
    and Atchuthan, *A micro Lie theory for state estimation in robotics*, 2018, §III)."""
    e = z.inverse() @ (a.inverse() @ b)
    J_ab = jnp.concatenate(jl.jacobians.between(a, b), axis=-1)
    return e.log(), jl.jacobians.log(e) @ J_ab


@pytest.mark.parametrize("group", [jl.SE2, jl.SE3], ids=["SE2", "SE3"])
def test_closed_form_jacobian_equals_autodiff(group) -> None:
    """Between factors with the closed-form Jacobian take the autodiff path's steps: one
    step from the same start lands on the same point (a wrong Jacobian moves it), and the
    converged solves agree."""
    k = group.tangent_dim
    key = jax.random.split(jax.random.key(3), 3)
    truth = group.exp(jax.random.normal(key[0], (N, k)))
    meas = (truth[IA].inverse() @ truth[IB]) @ group.exp(0.05 * jax.random.normal(key[1], (5, k)))
    init = truth @ group.exp(0.2 * jax.random.normal(key[2], (N, k)))
    anchor = truth[jnp.array([0])]
    prior = ls.Factor(_prior, (0,), (np.array([0]),), anchor)
    auto = [ls.Factor(_between, (0, 0), (IA, IB), meas), prior]
    closed = [ls.Factor(_between, (0, 0), (IA, IB), meas, jacobian=_between_closed_form), prior]
    for options in (dict(max_iterations=1), dict(tolerance=1e-14)):
        want = ls.solve(auto, (init,), **options)
        got = ls.solve(closed, (init,), **options)
        assert int(got.iterations) == int(want.iterations) and int(got.iterations) > 0
        np.testing.assert_allclose(
            got.variables[0].parameters(), want.variables[0].parameters(), atol=1e-12
        )
    with pytest.raises(ValueError, match="Jacobian must be"):
        bad = lambda a, b, z: (_between(a, b, z), jnp.zeros((k, k)))  # noqa: E731
        ls.solve([ls.Factor(_between, (0, 0), (IA, IB), meas, jacobian=bad), prior], (init,))
