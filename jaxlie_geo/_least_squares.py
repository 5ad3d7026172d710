"""Levenberg–Marquardt and Gauss–Newton on block-sparse least squares: the loop that
``pose_graph.solve`` and ``splines.fit`` share.

A problem is a ``Model`` (how to linearise, evaluate and retract, static under ``jit``),
its variables x (an array whose leading axis is the n variables, each of tangent dimension
k) and its data (a pytree of device arrays), and the host arrays naming each factor's
variables (``_sparse.Factors``). The loop runs on the host; each of its steps is one
compiled call, traced once per model and problem size and reused by every iteration and
every later call of that size.

Levenberg–Marquardt (Levenberg, *A method for the solution of certain non-linear problems
in least squares*, 1944) solves (H + λD) δ = −g with D = I, or D = diag(H) (Marquardt,
*An algorithm for least-squares estimation of nonlinear parameters*, 1963), accepts a step
only if it lowers the cost, then divides λ by 10; after a step that does not, it multiplies
λ by ν and doubles ν (ν = 10 after every success). With D = I this is close to GTSAM's
``LevenbergMarquardtOptimizer`` with its default parameters; GTSAM also multiplies λ by a
fixed 10 after a failure, accepts a step only if its gain ratio (actual over predicted
decrease) exceeds 10⁻³, and gives up at λ = 10⁵ (here 10¹⁶).

A leaf module: it knows the variables only as arrays, through the model.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
import time
from typing import Any, Optional, Protocol, Sequence, Tuple, get_args

import jax
import jax.numpy as jnp
import numpy as onp

from . import hints
from ._sparse import (
    DAMPING_FLOOR,
    BandedCholesky,
    BlockPattern,
    Factors,
    SparseCholesky,
    diagonal_blocks,
    gradient,
    hessian_values,
    installed,
    pcg,
)

#: λ is divided by this after a step that lowers the cost, and multiplied by it (then by
#: twice it, and so on) after one that does not.
DAMPING_FACTOR = 10.0

#: λ is never divided below this, so that a failed step can still raise it.
MIN_DAMPING = 1e-15

#: λ beyond which Levenberg–Marquardt gives up: no damped step lowers the cost.
MAX_DAMPING = 1e16

#: The names ``linear_solver`` accepts.
LINEAR_SOLVERS = get_args(hints.LinearSolver)

#: ``"auto"`` takes the banded Cholesky (when neither sparse package is installed) only if
#: the band holds at most this many times the pattern's stored entries.
BAND_FILL_LIMIT = 4


class Model(Protocol):
    """A least-squares problem: hashable (a frozen dataclass), since ``jit`` keys its
    programs on it."""

    def linearise(self, x: jax.Array, data: Any) -> Tuple[jax.Array, Tuple[Factors, ...]]:
        """The cost ½ Σ ‖e_f‖² and the factors' whitened residuals and Jacobians at x."""
        ...

    def cost(self, x: jax.Array, data: Any) -> jax.Array:
        """The cost at x, a scalar."""
        ...

    def retract(self, x: jax.Array, delta: jax.Array) -> jax.Array:
        """x ⊕ δ, δ ``(n, k)``."""
        ...


@dataclasses.dataclass(frozen=True)
class Solution:
    """The record of a least-squares solve.

    Attributes:
        costs: ``(iterations + 1,)``, the cost before the first and after every accepted
            step.
        times: ``(iterations + 1,)``, for each cost the wall-clock seconds from the start
            of the call to its evaluation (the first includes building the problem and, for
            a new problem size, compiling).
        iterations: accepted steps.
        time: wall-clock seconds of the whole call.
        stop_reason: why it stopped, in words.
        converged: whether it stopped at a minimum: on the tolerance, or with no step
            lowering the cost at any damping (rather than at the iteration limit or, for
            Gauss–Newton, on a step that raised the cost or a singular system).
    """

    costs: onp.ndarray
    times: onp.ndarray
    iterations: int
    time: float
    stop_reason: str
    converged: bool


def check_options(
    caller: str,
    method: hints.SolverMethod,
    linear_solver: hints.LinearSolver,
    max_iterations: int,
    **positive: float,
) -> None:
    """``ValueError`` naming the argument, for a method, linear solver or iteration limit
    out of range, or a value of ``positive`` that is not a positive finite number."""
    if method not in get_args(hints.SolverMethod):
        raise ValueError(f"{caller}: method must be 'lm' or 'gn', got {method!r}")
    if linear_solver not in LINEAR_SOLVERS:
        names = ", ".join(repr(s) for s in LINEAR_SOLVERS)
        raise ValueError(f"{caller}: linear_solver must be one of {names}, got {linear_solver!r}")
    for name, value in positive.items():
        if not (value > 0 and math.isfinite(value)):
            raise ValueError(f"{caller}: {name} must be a positive number, got {value!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 0):
        raise ValueError(
            f"{caller}: max_iterations must be a non-negative int, got {max_iterations!r}"
        )


def choose_linear_solver(name: str, pattern: BlockPattern) -> str:
    """The solver ``name`` stands for: ``"cholesky"`` is CHOLMOD if cvxopt imports, else
    QDLDL; ``"auto"`` is ``"cholesky"`` if either imports, else the banded Cholesky if
    ``pattern`` is narrow (its band at most ``BAND_FILL_LIMIT`` times its entries), else
    PCG."""
    if name == "auto":
        if installed("cholmod") or installed("qdldl"):
            name = "cholesky"
        elif (pattern.bandwidth + 1) * pattern.size <= BAND_FILL_LIMIT * pattern.nnz:
            name = "banded"
        else:
            name = "pcg"
    if name == "cholesky":
        name = "cholmod" if installed("cholmod") else "qdldl"
    return name


# -- compiled pieces (static: the model, the number of variables, the tuple counts) -------


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _host_system(model: Model, n: int, counts: Tuple[int, ...], x, data, segment_ids):
    c, factors = model.linearise(x, data)
    return c, hessian_values(factors, segment_ids, counts), gradient(factors, n)


@functools.partial(jax.jit, static_argnums=(0, 1))
def _device_system(model: Model, n: int, x, data):
    c, factors = model.linearise(x, data)
    return c, factors, gradient(factors, n), diagonal_blocks(factors, n)


@functools.partial(jax.jit, static_argnums=(4, 5, 6))
def _pcg_step(factors, g, D, lam, diagonal_damping, tolerance, max_iterations):
    diag = jnp.diagonal(D, axis1=-2, axis2=-1)
    damping = lam * (jnp.maximum(diag, DAMPING_FLOOR) if diagonal_damping else jnp.ones_like(diag))
    delta = pcg(factors, g, D, damping, tolerance, max_iterations)
    predicted = 0.5 * (jnp.sum(damping * delta * delta) - jnp.sum(g * delta))
    return delta, predicted


@functools.partial(jax.jit, static_argnums=(0,))
def _try_step(model: Model, x, delta, data):
    new = model.retract(x, delta)
    return new, model.cost(new, data)


class HostSystem:
    """Linearise on the device; assemble and factorise on the host (CHOLMOD, QDLDL, banded
    or dense Cholesky)."""

    def __init__(self, model: Model, data: Any, pattern: BlockPattern, k: int,
                 diagonal_damping: bool, backend: str):  # fmt: skip
        self.model, self.data, self.pattern, self.k = model, data, pattern, k
        self.n = pattern.size // k
        self.diagonal_damping = diagonal_damping
        self.segment_ids = tuple(None if s is None else jnp.asarray(s) for s in pattern.segment_ids)
        self.counts = tuple(pattern.segment_counts)
        self.solver: Any = (
            BandedCholesky(pattern, dense=backend == "dense")
            if backend in ("banded", "dense")
            else SparseCholesky(pattern, backend)
        )

    def linearise(self, x: jax.Array) -> float:
        c, values, g = _host_system(self.model, self.n, self.counts, x, self.data, self.segment_ids)
        self.dtype = x.dtype
        self.values = self.pattern.assemble(onp.asarray(values, onp.float64))
        self.g = onp.asarray(g, onp.float64).ravel()
        diag = self.values[self.pattern.diagonal]
        self.D = onp.maximum(diag, DAMPING_FLOOR) if self.diagonal_damping else onp.ones_like(diag)
        return float(c)

    def step(self, lam: float) -> Tuple[jax.Array, float]:
        damping = lam * self.D
        delta = self.solver.solve(self.values, damping, self.g)
        predicted = 0.5 * (float(damping @ (delta * delta)) - float(self.g @ delta))
        return jnp.asarray(delta.reshape(self.n, self.k), self.dtype), predicted


class DeviceSystem:
    """Linearise and solve on the device(s), by PCG."""

    def __init__(self, model: Model, data: Any, n: int, diagonal_damping: bool,
                 tolerance: float, max_iterations: int):  # fmt: skip
        self.model, self.data, self.n = model, data, n
        self.diagonal_damping = diagonal_damping
        self.tolerance, self.max_iterations = tolerance, max_iterations

    def linearise(self, x: jax.Array) -> float:
        c, self.factors, self.g, self.D = _device_system(self.model, self.n, x, self.data)
        return float(c)

    def step(self, lam: float) -> Tuple[jax.Array, float]:
        delta, predicted = _pcg_step(
            self.factors, self.g, self.D, jnp.asarray(lam, self.g.dtype),
            self.diagonal_damping, self.tolerance, self.max_iterations,
        )  # fmt: skip
        return delta, float(predicted)


class Progress:
    """One status line on stderr: iteration, cost, step size, λ and time; redrawn in place
    on a terminal, one line per iteration otherwise."""

    def __init__(self, enabled: bool, max_iterations: int):
        self.enabled, self.max_iterations = enabled, max_iterations
        self.tty = enabled and sys.stderr.isatty()

    def update(self, it: int, cost: float, step: float, lam: float, seconds: float) -> None:
        if not self.enabled:
            return
        width = 20
        filled = min(width, round(width * it / max(self.max_iterations, 1)))
        line = (
            f"[{'#' * filled}{'.' * (width - filled)}] iteration {it:4d}  cost {cost:.9e}  "
            f"step {step:.2e}  λ {lam:.1e}  {seconds:7.2f} s"
        )
        sys.stderr.write(("\r" + line) if self.tty else (line + "\n"))
        sys.stderr.flush()

    def close(self, reason: str) -> None:
        if self.enabled:
            sys.stderr.write(("\n" if self.tty else "") + f"stopped: {reason}\n")
            sys.stderr.flush()


def system(
    model: Model,
    data: Any,
    indices: Sequence[onp.ndarray],
    n: int,
    k: int,
    linear_solver: hints.LinearSolver,
    diagonal_damping: bool = False,
    cg_tolerance: float = 1e-10,
    cg_max_iterations: int = 2000,
) -> Any:
    """The linear system of a problem: a ``HostSystem`` or a ``DeviceSystem``, by
    ``choose_linear_solver``; ``indices`` are the host arrays ``(F, m)`` of each factor
    set's variables."""
    if linear_solver == "pcg":  # matrix-free: no pattern to build
        return DeviceSystem(model, data, n, diagonal_damping, cg_tolerance, cg_max_iterations)
    pattern = BlockPattern(indices, n, k)
    chosen = choose_linear_solver(linear_solver, pattern)
    if chosen == "pcg":
        return DeviceSystem(model, data, n, diagonal_damping, cg_tolerance, cg_max_iterations)
    return HostSystem(model, data, pattern, k, diagonal_damping, chosen)


def minimise(
    model: Model,
    x: jax.Array,
    data: Any,
    linear: Any,
    *,
    method: hints.SolverMethod = "lm",
    max_iterations: int = 100,
    tolerance: float = 1e-7,
    initial_damping: float = 1e-5,
    progress: bool = False,
    start: Optional[float] = None,
) -> Tuple[jax.Array, Solution]:
    """Levenberg–Marquardt (``method="lm"``) or Gauss–Newton (``"gn"``: every step taken;
    it stops, keeping the previous x, if a step raises the cost) from x, with the linear
    system ``linear`` (from ``system``).

    It stops after ``max_iterations`` accepted steps; when a step's relative decrease of
    the cost, or the decrease the linear model predicts for an iteration's first (least
    damped) step, falls below ``tolerance``; or when λ passes ``MAX_DAMPING`` (no step
    lowers the cost: a minimum to working precision, as a zero-residual problem ends).
    All but the first are convergence.

    Returns:
        The final x and the ``Solution`` record; ``start`` (``time.perf_counter()``) is when
        the record's times begin, by default the start of this call.
    """
    start = time.perf_counter() if start is None else start
    bar = Progress(progress, max_iterations)
    current = linear.linearise(x)
    costs, times = [current], [time.perf_counter() - start]
    lam, nu = (initial_damping if method == "lm" else 0.0), DAMPING_FACTOR
    bar.update(0, current, 0.0, lam, times[-1])
    reason, converged = f"reached max_iterations = {max_iterations}", False
    for it in range(1, max_iterations + 1):
        accepted, first_try = False, True
        while True:
            delta, predicted = linear.step(lam)
            if not math.isfinite(predicted):  # a singular or overflowing system
                if method == "gn":
                    reason = "the linear system gave a non-finite step"
                    break
            elif first_try and not predicted > tolerance * current:
                # Only the first, least damped step of an iteration speaks for the model:
                # raising λ after a failure shrinks every prediction.
                reason = "the linear model predicts a relative decrease below tolerance"
                converged = True
                break
            else:
                new_x, new = _try_step(model, x, delta, linear.data)
                new = float(new)
                if method == "gn" or new < current:
                    accepted = True
                    break
            first_try = False
            lam, nu = lam * nu, 2.0 * nu
            if lam > MAX_DAMPING:
                # A step of length |g|/λ along −g that does not lower the cost: the
                # gradient is below the cost's rounding, a minimum to working precision.
                reason = f"no step lowers the cost (λ > {MAX_DAMPING:g})"
                converged = True
                break
        if not accepted:
            break
        if method == "gn" and not new <= current:  # also a NaN cost
            reason = "a Gauss–Newton step raised the cost; the previous estimate is kept"
            break
        if method == "lm":
            lam, nu = max(lam / DAMPING_FACTOR, MIN_DAMPING), DAMPING_FACTOR
        # The decrease between the costs recorded at the linearisation points: at the
        # rounding floor of a zero-residual problem the trial cost ``new`` can sit below
        # ``current`` by a large relative amount that the linearisation does not repeat.
        previous, x = current, new_x
        current = linear.linearise(x)
        decrease = (previous - current) / previous if previous > 0 else 0.0
        costs.append(current)
        times.append(time.perf_counter() - start)
        if bar.enabled:
            bar.update(it, current, float(jnp.max(jnp.abs(delta))), lam, times[-1])
        if decrease < tolerance:
            reason, converged = "the relative decrease of the cost fell below tolerance", True
            break
    bar.close(reason)
    record = Solution(
        costs=onp.asarray(costs),
        times=onp.asarray(times),
        iterations=len(costs) - 1,
        time=time.perf_counter() - start,
        stop_reason=reason,
        converged=converged,
    )
    return x, record
