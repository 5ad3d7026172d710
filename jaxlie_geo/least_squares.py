"""Nonlinear least squares on Lie groups as a JAX function: it runs inside ``jax.jit``, under
``jax.vmap`` over problems of one structure, and differentiates through its optimum.

A problem is a set of variables and a list of factors. The variables are a tuple of
*variable sets*, each a batched group element (any of the six groups, leading axis the n
elements of the set) or an array ``(n, d)``. A ``Factor`` is one residual function, vmapped
over its F factors: ``residual(*args, data)`` takes one element (or row) of each of the sets
it names (``sets``), at the indices its ``indices`` give, and that factor's slice of
``data``, and returns its whitened residual, shape ``(r,)``. The cost is ½ Σ_f ρ(‖r_f‖²)
(ρ(s) = s without a robust kernel).

``solve`` minimises the cost by Levenberg–Marquardt (Levenberg, *A method for the solution of
certain non-linear problems in least squares*, 1944; Marquardt, *An algorithm for
least-squares estimation of nonlinear parameters*, 1963) or Gauss–Newton, in one
``lax.while_loop``, with the damping policy and stopping rules of ``pose_graph.solve``
(``StopReason``). Steps are right perturbations, X ⊕ δ = X @ exp(δ) for a group element and
x + δ for an array (``manifold.rplus``); the residuals' Jacobians in those tangents come from
forward-mode autodiff. The normal equations are dense: (H + λD) δ = −g, H = JᵀJ, by Cholesky,
which suits problems of up to a few thousand unknowns (a batch of small problems under
``vmap``, inverse kinematics, calibration, a small pose graph).

The derivative of the solution with respect to every array the residuals read (the factors'
``data``) is the implicit function theorem's at the returned point x*: with G(x, θ) the
gradient of the cost in x's tangent and H* its Hessian (the exact one, by autodiff),
dx*/dθ = −H*⁻¹ ∂G/∂θ. It costs one extra dense Hessian and one solve, and no differentiation
through the iterations. It is the derivative of the optimum where the solve converged; where
it stopped early it is that of the minimiser of the local quadratic model at x*, and it is
kept finite: H* is damped by the final λ (D as in the solve), and a system that Cholesky
cannot factor gives a zero derivative. The initial values get no derivative (the optimum does
not depend on them).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from typing import Any, Callable, Literal, Optional, Sequence, Tuple, Union

import jax
import jax.numpy as jnp
import numpy as onp

from ._base import MatrixLieGroup

__all__ = [
    "Factor",
    "Solution",
    "StopReason",
    "solve",
    "cost",
    "marginal_covariances",
]

#: λ is divided by this after a step that lowers the cost, and multiplied by ν (then 2ν, ...)
#: after one that does not (ν starts at this value after every accepted step).
DAMPING_FACTOR = 10.0
#: λ is never divided below this, so that a failed step can still raise it.
MIN_DAMPING = 1e-15
#: λ beyond which Levenberg–Marquardt stops: no damped step lowers the cost.
MAX_DAMPING = 1e16
#: The floor of D = diag(H) with ``diagonal_damping``, so that a direction H does not see
#: is still damped.
DAMPING_FLOOR = 1e-6

Variable = Union[MatrixLieGroup, jax.Array]
Robust = Optional[Tuple[Literal["huber", "cauchy"], float]]


class StopReason(enum.IntEnum):
    """Why ``solve`` stopped; ``Solution.stop_reason`` holds the code (an int array under
    ``vmap``). ``converged`` is true for the three middle ones."""

    #: ``max_iterations`` accepted steps were taken.
    MAX_ITERATIONS = 0
    #: An accepted step lowered the cost by less than ``tolerance`` relative.
    DECREASE_BELOW_TOLERANCE = 1
    #: The linear model predicts, for an iteration's first (least damped) step, a relative
    #: decrease below ``tolerance``.
    PREDICTED_DECREASE_BELOW_TOLERANCE = 2
    #: λ passed ``MAX_DAMPING`` without a step lowering the cost: a minimum to working
    #: precision.
    NO_STEP_LOWERS_COST = 3
    #: Gauss–Newton: a step raised the cost; the previous estimate is kept.
    STEP_RAISED_COST = 4
    #: Gauss–Newton: the linear system gave a non-finite step (a singular system).
    NON_FINITE_STEP = 5


_CONVERGED = (
    StopReason.DECREASE_BELOW_TOLERANCE,
    StopReason.PREDICTED_DECREASE_BELOW_TOLERANCE,
    StopReason.NO_STEP_LOWERS_COST,
)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Factor:
    """F residuals of one form.

    Attributes:
        residual: ``residual(*args, data) -> (r,)`` for one factor (``residual(*args)`` when
            ``data`` is None), the whitened residual (multiply by the square root of the
            information yourself). It sees one element of each variable set it reads:
            a group element with no batch axes, or a ``(d,)`` row. Static: ``jit`` keys its
            programs on it, so pass the same function object for the same residual.
        sets: for each argument of ``residual``, the position of its variable set in
            ``solve``'s ``variables`` (static ints).
        indices: for each argument, an int array ``(F,)`` of elements of that set; all of
            length F.
        data: a pytree of arrays with leading axis F (or None), sliced per factor.
            Differentiable: ``jax.grad`` of a function of ``solve``'s result reaches it.
        robust: None, or ``("huber", k)`` or ``("cauchy", k)``: ρ(s) = s for s ≤ k², and
            2k√s − k² beyond (Huber), or ρ(s) = k² log(1 + s/k²) (Cauchy), s = ‖r‖².
            Applied by reweighting each factor by √ρ'(s) at the linearisation point.
    """

    residual: Callable[..., jax.Array] = dataclasses.field(metadata=dict(static=True))
    sets: Tuple[int, ...] = dataclasses.field(metadata=dict(static=True))
    indices: Tuple[jax.Array, ...]
    data: Any = None
    robust: Robust = dataclasses.field(default=None, metadata=dict(static=True))

    def __post_init__(self) -> None:
        if not callable(self.residual):
            raise TypeError(f"Factor: residual must be callable, got {type(self.residual)}")
        if len(self.sets) != len(self.indices):
            raise ValueError(f"Factor: {len(self.sets)} sets but {len(self.indices)} index arrays")
        if self.robust is not None and (
            len(self.robust) != 2 or self.robust[0] not in ("huber", "cauchy")
        ):
            raise ValueError(f"Factor: robust must be ('huber' | 'cauchy', k), got {self.robust}")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Solution:
    """What ``solve`` returns; under ``vmap`` every field has the batch axis.

    Attributes:
        variables: the solution, the structure of ``solve``'s ``variables``.
        cost: the cost ½ Σ ρ(‖r‖²) at the solution.
        initial_cost: the cost at the initial values.
        iterations: accepted steps, an int array.
        stop_reason: a ``StopReason`` code, an int array.
        converged: whether ``stop_reason`` is one of the three converged ones.
        damping: λ at the end (0 for Gauss–Newton).
    """

    variables: Tuple[Variable, ...]
    cost: jax.Array
    initial_cost: jax.Array
    iterations: jax.Array
    stop_reason: jax.Array
    converged: jax.Array
    damping: jax.Array


# -- the problem's layout --------------------------------------------------------------


def _tangent_dim(v: Variable) -> int:
    return type(v).tangent_dim if isinstance(v, MatrixLieGroup) else v.shape[-1]


def _count(v: Variable) -> int:
    shape = v.get_batch_axes() if isinstance(v, MatrixLieGroup) else v.shape[:-1]
    if len(shape) != 1:
        raise ValueError(
            "least_squares: each variable set needs exactly one batch axis (n elements), got "
            f"{type(v).__name__} with batch shape {tuple(shape)}"
        )
    return int(shape[0])


def _offsets(variables: Sequence[Variable]) -> Tuple[int, ...]:
    sizes = [_count(v) * _tangent_dim(v) for v in variables]
    return tuple(int(sum(sizes[:i])) for i in range(len(sizes) + 1))


def _retract(variables: Tuple[Variable, ...], delta: jax.Array) -> Tuple[Variable, ...]:
    """Every set moved by its slice of the flat tangent ``delta``."""
    out, offsets = [], _offsets(variables)
    for i, v in enumerate(variables):
        d = delta[offsets[i] : offsets[i + 1]].reshape(_count(v), _tangent_dim(v))
        out.append(v @ type(v).exp(d) if isinstance(v, MatrixLieGroup) else v + d)
    return tuple(out)


def _take(v: Variable, idx: jax.Array) -> Variable:
    return v[idx] if isinstance(v, MatrixLieGroup) else v[idx, :]


def _check(factors: Sequence[Factor], variables: Tuple[Variable, ...]) -> None:
    """Trace-time errors for factors that do not fit the variables."""
    for j, f in enumerate(factors):
        counts = set()
        for s, idx in zip(f.sets, f.indices):
            if not (isinstance(s, int) and 0 <= s < len(variables)):
                raise ValueError(
                    f"least_squares: factor {j} names variable set {s!r}; there are "
                    f"{len(variables)} (0 to {len(variables) - 1})"
                )
            concrete = not isinstance(idx, jax.core.Tracer)
            idx = onp.asarray(idx) if concrete else idx
            if idx.ndim != 1 or not jnp.issubdtype(idx.dtype, jnp.integer):
                raise ValueError(
                    f"least_squares: factor {j}'s indices must be an int array (F,), got "
                    f"shape {idx.shape} dtype {idx.dtype}"
                )
            if concrete:
                n = _count(variables[s])
                if idx.size and (int(idx.min()) < 0 or int(idx.max()) >= n):
                    raise IndexError(
                        f"least_squares: factor {j}'s indices into set {s} span "
                        f"[{int(idx.min())}, {int(idx.max())}], outside [0, {n})"
                    )
            counts.add(idx.shape[0])
        if len(counts) != 1:
            raise ValueError(f"least_squares: factor {j}'s index arrays differ in length")


# -- linearisation ---------------------------------------------------------------------


def _rho(robust: Robust, s: jax.Array) -> Tuple[jax.Array, jax.Array]:
    """ρ(s) and ρ'(s) of a robust kernel (s = ‖r‖²)."""
    if robust is None:
        return s, jnp.ones_like(s)
    kind, k = robust
    k2 = jnp.asarray(k, s.dtype) ** 2
    if kind == "huber":
        root = jnp.sqrt(jnp.maximum(s, k2))
        inside = s <= k2
        return jnp.where(inside, s, 2 * jnp.sqrt(k2) * root - k2), jnp.where(
            inside, 1.0, jnp.sqrt(k2) / root
        )
    return k2 * jnp.log1p(s / k2), 1.0 / (1.0 + s / k2)


def _factor_residuals(f: Factor, variables: Tuple[Variable, ...]) -> jax.Array:
    """``(F, r)``: every factor's residual at the variables."""
    args = tuple(_take(variables[s], jnp.asarray(idx)) for s, idx in zip(f.sets, f.indices))
    call = f.residual if f.data is None else (lambda *a: f.residual(*a[:-1], a[-1]))
    inputs = args if f.data is None else (*args, f.data)
    r = jax.vmap(call)(*inputs)
    if r.ndim != 2:
        raise ValueError(
            f"least_squares: a residual must return a vector (r,), got shape {r.shape[1:]}"
        )
    return r


def cost(factors: Sequence[Factor], variables: Tuple[Variable, ...]) -> jax.Array:
    """The cost ½ Σ_f ρ(‖r_f‖²) over every factor, a scalar."""
    total = jnp.zeros((), _dtype(variables))
    for f in factors:
        r = _factor_residuals(f, variables)
        total = total + 0.5 * jnp.sum(_rho(f.robust, jnp.sum(r * r, axis=-1))[0])
    return total


def _dtype(variables: Tuple[Variable, ...]) -> Any:
    leaves = jax.tree_util.tree_leaves(variables)
    return jnp.result_type(*leaves) if leaves else jnp.float32


def _normal_equations(
    factors: Sequence[Factor], variables: Tuple[Variable, ...]
) -> Tuple[jax.Array, jax.Array, jax.Array]:
    """The cost, H = JᵀWJ and g = JᵀW r (W the robust weights ρ'), dense, in the flat
    tangent of ``_retract``."""
    offsets = _offsets(variables)
    n = offsets[-1]
    dtype = _dtype(variables)
    H = jnp.zeros((n, n), dtype)
    g = jnp.zeros((n,), dtype)
    total = jnp.zeros((), dtype)
    for f in factors:
        args = tuple(_take(variables[s], jnp.asarray(idx)) for s, idx in zip(f.sets, f.indices))
        dims = tuple(_tangent_dim(variables[s]) for s in f.sets)

        def one(arg_values, data, f=f, dims=dims):
            def at(deltas):
                moved = [
                    a @ type(a).exp(d) if isinstance(a, MatrixLieGroup) else a + d
                    for a, d in zip(arg_values, deltas)
                ]
                return f.residual(*moved) if f.data is None else f.residual(*moved, data)

            zeros = tuple(jnp.zeros((k,), dtype) for k in dims)
            r = at(zeros)
            jac = jax.jacfwd(at)(zeros)  # one (r, k) block per argument
            return r, jac

        r, jac = jax.vmap(one)(args, f.data)
        if r.ndim != 2:
            raise ValueError(
                f"least_squares: a residual must return a vector (r,), got shape {r.shape[1:]}"
            )
        s = jnp.sum(r * r, axis=-1)
        rho, w = _rho(f.robust, s)
        total = total + 0.5 * jnp.sum(rho)
        root = jnp.sqrt(w)[:, None]
        r = root * r
        jac = [root[..., None] * J for J in jac]
        cols = [
            offsets[s] + jnp.asarray(idx)[:, None] * k + jnp.arange(k)
            for s, idx, k in zip(f.sets, f.indices, dims)
        ]
        for Ja, ca in zip(jac, cols):
            g = g.at[ca].add(jnp.einsum("fr,frk->fk", r, Ja))
            for Jb, cb in zip(jac, cols):
                H = H.at[ca[:, :, None], cb[:, None, :]].add(jnp.einsum("frk,frl->fkl", Ja, Jb))
    return total, H, g


def _free_mask(variables: Tuple[Variable, ...], fixed: Any) -> jax.Array:
    """1 for each free tangent coordinate, 0 for a fixed one (``fixed``: per set, None or a
    bool array ``(n,)``)."""
    parts = []
    for i, v in enumerate(variables):
        n, k = _count(v), _tangent_dim(v)
        f = None if fixed is None else fixed[i]
        keep = jnp.ones((n,), bool) if f is None else ~jnp.asarray(f, bool).reshape(n)
        parts.append(jnp.repeat(keep, k))
    return jnp.concatenate(parts) if parts else jnp.zeros((0,), bool)


def _damped_solve(H, g, damping, free):
    """δ = −(H + diag(damping))⁻¹ g on the free coordinates (0 on the fixed ones)."""
    A = jnp.where(free[:, None] & free[None, :], H, 0.0)
    A = A + jnp.diag(jnp.where(free, damping, 1.0))
    c = jax.scipy.linalg.cho_factor(A, lower=True)
    return -jnp.where(free, jax.scipy.linalg.cho_solve(c, jnp.where(free, g, 0.0)), 0.0)


# -- the loop --------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class _Options:
    method: str
    max_iterations: int
    tolerance: float
    initial_damping: float
    diagonal_damping: bool


def _minimise(opts: _Options, factors, variables, fixed) -> Solution:
    """The loop. Each pass linearises if x moved (and stops on the decrease or the iteration
    limit), then tries one damped step; ``_normal_equations`` and ``cost`` are traced once
    each."""
    free = _free_mask(variables, fixed)
    lm = opts.method == "lm"
    dtype = _dtype(variables)
    n = _offsets(variables)[-1]
    R = StopReason
    c0 = cost(factors, variables)
    st0 = dict(
        x=variables,
        cost=c0,
        H=jnp.zeros((n, n), dtype),
        g=jnp.zeros((n,), dtype),
        fresh=jnp.asarray(False),  # H and g are those of x
        lam=jnp.asarray(opts.initial_damping if lm else 0.0, dtype),
        nu=jnp.asarray(DAMPING_FACTOR, dtype),
        it=jnp.asarray(0, jnp.int32),
        reason=jnp.asarray(-1, jnp.int32),
    )

    def body(st):
        moved = ~st["fresh"]
        c, H, g = jax.lax.cond(
            moved,
            lambda: _normal_equations(factors, st["x"]),
            lambda: (st["cost"], st["H"], st["g"]),
        )
        # The decrease between the costs at two linearisation points.
        decrease = jnp.where(st["cost"] > 0, (st["cost"] - c) / st["cost"], 0.0)
        converged = moved & (st["it"] > 0) & (decrease < opts.tolerance)
        at_limit = moved & (st["it"] >= opts.max_iterations)

        diag = jnp.diagonal(H)
        D = st["lam"] * (jnp.maximum(diag, DAMPING_FLOOR) if opts.diagonal_damping else 1.0)
        delta = _damped_solve(H, g, D, free)
        predicted = 0.5 * (jnp.sum(D * delta * delta) - jnp.sum(g * delta))
        finite = jnp.isfinite(predicted)
        # Only the first, least damped step at a point speaks for the model: raising λ
        # after a failure shrinks every prediction.
        small = moved & finite & ~(predicted > opts.tolerance * c)
        trial = _retract(st["x"], jnp.where(finite, delta, 0.0))
        c_trial = cost(factors, trial)
        if lm:
            accept = finite & ~small & (c_trial < c)
            raised = jnp.asarray(False)
        else:
            accept = finite & ~small & (c_trial <= c)
            raised = finite & ~small & ~(c_trial <= c)  # also a NaN cost
        lam_up = st["lam"] * st["nu"]
        conditions = (  # the first that holds is the reason
            (converged, R.DECREASE_BELOW_TOLERANCE),
            (at_limit, R.MAX_ITERATIONS),
            (jnp.asarray(not lm) & ~finite, R.NON_FINITE_STEP),
            (small, R.PREDICTED_DECREASE_BELOW_TOLERANCE),
            (raised, R.STEP_RAISED_COST),
            (jnp.asarray(lm) & ~accept & (lam_up > MAX_DAMPING), R.NO_STEP_LOWERS_COST),
        )
        reason = jnp.asarray(-1, jnp.int32)
        for cond, code in reversed(conditions):
            reason = jnp.where(cond, jnp.int32(code), reason)
        go = accept & (reason < 0)
        if lm:
            lam = jnp.where(go, jnp.maximum(st["lam"] / DAMPING_FACTOR, MIN_DAMPING), lam_up)
            nu = jnp.where(go, DAMPING_FACTOR, 2 * st["nu"])
        else:
            lam, nu = st["lam"], st["nu"]
        lam = jnp.where(reason < 0, lam, st["lam"])
        x = jax.tree_util.tree_map(lambda a, b: jnp.where(go, a, b), trial, st["x"])
        return dict(
            x=x,
            cost=c,
            H=H,
            g=g,
            fresh=~go,
            lam=lam,
            nu=nu,
            it=st["it"] + go.astype(jnp.int32),
            reason=reason,
        )

    st = jax.lax.while_loop(lambda st: st["reason"] < 0, body, st0)
    return Solution(
        variables=st["x"],
        cost=st["cost"],
        initial_cost=c0,
        iterations=st["it"],
        stop_reason=st["reason"],
        converged=jnp.isin(st["reason"], jnp.asarray([int(c) for c in _CONVERGED])),
        damping=st["lam"],
    )


# -- implicit differentiation ----------------------------------------------------------


def _tangent_gradient(factors, x):
    """∇_δ cost(x ⊕ δ) at δ = 0, flat."""
    n = _offsets(x)[-1]
    return jax.grad(lambda d: cost(factors, _retract(x, d)))(jnp.zeros((n,), _dtype(x)))


@functools.partial(jax.custom_vjp, nondiff_argnums=(0,))
def _solve_values(opts, factors, variables, fixed):
    return _minimise(opts, factors, variables, fixed)


def _solve_fwd(opts, factors, variables, fixed):
    sol = _minimise(opts, factors, variables, fixed)
    return sol, (factors, variables, sol, fixed)


def _solve_bwd(opts, res, cot):
    factors, initial, sol, fixed = res
    x = sol.variables
    n = _offsets(x)[-1]
    dtype = _dtype(x)
    zero = jnp.zeros((n,), dtype)
    # The cotangent of the parameters, pulled back to x's tangent: d/dδ ⟨x̄, x ⊕ δ⟩ at 0.
    _, pull = jax.vjp(lambda d: _retract(x, d), zero)
    (xbar,) = pull(cot.variables)
    free = _free_mask(x, fixed)
    H = jax.hessian(lambda d: cost(factors, _retract(x, d)))(zero)
    diag = jnp.diagonal(H)
    D = sol.damping * (jnp.maximum(diag, DAMPING_FLOOR) if opts.diagonal_damping else 1.0)
    w = -_damped_solve(H, xbar, D, free)  # (H + λD)⁻¹ x̄ on the free coordinates
    w = jnp.where(jnp.all(jnp.isfinite(w)), w, 0.0)

    # θ̄ = −(∂G/∂θ)ᵀ w, G(θ) the tangent gradient at the fixed x; the costs at x* and at the
    # initial values depend on θ directly (at x*, ∂cost/∂x = 0).
    def through(fs):
        return _tangent_gradient(fs, x), cost(fs, x), cost(fs, initial)

    _, pull_theta = jax.vjp(through, factors)
    (fbar,) = pull_theta((-w, cot.cost, cot.initial_cost))
    return fbar, None, None


_solve_values.defvjp(_solve_fwd, _solve_bwd)


@functools.partial(jax.jit, static_argnums=(0,))
def _solve(opts, factors, variables, fixed):
    return _solve_values(opts, factors, variables, fixed)


def solve(
    factors: Sequence[Factor],
    variables: Sequence[Variable],
    *,
    fixed: Optional[Sequence[Optional[jax.Array]]] = None,
    method: Literal["lm", "gn"] = "lm",
    max_iterations: int = 100,
    tolerance: float = 1e-7,
    initial_damping: float = 1e-5,
    diagonal_damping: bool = False,
) -> Solution:
    """Minimise ½ Σ ρ(‖r‖²) over the variables, from their given values.

    Args:
        factors: the ``Factor`` s of the problem.
        variables: the variable sets, each a group element with one batch axis ``(n,)`` or an
            array ``(n, d)``; their values are the initial estimate.
        fixed: None, or one entry per set: None, or a bool array ``(n,)``, true for the
            elements held at their initial value.
        method: ``"lm"``, Levenberg–Marquardt: (H + λD)δ = −g, a step kept only if it lowers
            the cost, then λ ← max(λ/10, 10⁻¹⁵); after one that does not, λ ← λν and ν ← 2ν
            (ν = 10 after every kept step). ``"gn"``, Gauss–Newton (λ = 0): every step taken,
            stopping with the previous estimate if one raises the cost.
        max_iterations: the most accepted steps.
        tolerance: it stops when an accepted step lowers the cost by less than this
            relative, or when the first (least damped) step of an iteration is predicted to.
        initial_damping: λ at the start (``"lm"``).
        diagonal_damping: D = max(diag H, 10⁻⁶) (Marquardt) instead of D = I.

    Returns:
        A ``Solution``. Under ``jax.vmap`` (initial values, data and indices batched over
        problems of one structure) each problem is solved as it would be alone; under
        ``jax.grad`` the derivative with respect to the factors' data is the implicit one
        described in the module docstring.

    Raises:
        ValueError / IndexError at trace time: a set without exactly one batch axis, a
        factor naming a set that does not exist, indices that are not ``(F,)`` ints or
        (when concrete) out of range, residuals that are not vectors; ``method`` or an
        option out of range.
    """
    if method not in ("lm", "gn"):
        raise ValueError(f"least_squares.solve: method must be 'lm' or 'gn', got {method!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 0):
        raise ValueError(
            f"least_squares.solve: max_iterations must be a non-negative int, got "
            f"{max_iterations!r}"
        )
    for name, value in (("tolerance", tolerance), ("initial_damping", initial_damping)):
        if not value > 0:
            raise ValueError(f"least_squares.solve: {name} must be positive, got {value!r}")
    variables = tuple(variables)
    factors = tuple(factors)
    _check(factors, variables)
    if fixed is not None:
        fixed = tuple(fixed)
        if len(fixed) != len(variables):
            raise ValueError(
                f"least_squares.solve: fixed has {len(fixed)} entries for {len(variables)} sets"
            )
    opts = _Options(method, max_iterations, float(tolerance), float(initial_damping),
                    bool(diagonal_damping))  # fmt: skip
    return _solve(opts, factors, variables, fixed)


def marginal_covariances(factors: Sequence[Factor], solution: Solution) -> jax.Array:
    """The Laplace covariance of the solution, (JᵀWJ)⁻¹ at it, as GTSAM's ``Marginals``:
    a dense ``(N, N)`` array in the flat tangent (the sets in order, each set's elements in
    order, each element's tangent in the group's ordering); a block of it is the joint
    marginal of those elements. Each residual is whitened, so this is in the units of the
    variables' tangents."""
    _, H, _ = _normal_equations(tuple(factors), tuple(solution.variables))
    c = jax.scipy.linalg.cho_factor(H, lower=True)
    return jax.scipy.linalg.cho_solve(c, jnp.eye(H.shape[0], dtype=H.dtype))
