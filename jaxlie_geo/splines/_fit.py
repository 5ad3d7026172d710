"""Least-squares fit of a spline to time-stamped elements on the group: one factor per
sample on the ``degree + 1`` control points that shape it, with the spline's exact
control-point Jacobians, solved by ``least_squares.solve``."""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import Any, Optional, Tuple, Union

import jax
import jax.numpy as jnp
import numpy as onp

from .. import _sparse, hints, least_squares
from .._base import GroupT, MatrixLieGroup
from .._record import Record, Solve, callback, check_options, recording
from .._xla import matmul
from ._curve import Spline, SplineTime, _evaluate, _jacobians


@dataclasses.dataclass(frozen=True)
class SplineFit(Solve):
    """What ``fit`` returns: the record of the solve (``costs``, ½ Σ wᵢ ‖rᵢ‖² before the
    first step and after each accepted one; ``times``; ``iterations``; ``time``;
    ``stop_reason``; ``converged``), and

    Attributes:
        spline: the fitted ``Spline``.
    """

    spline: Any


@dataclasses.dataclass(frozen=True)
class _Sample:
    """One sample's residual √w ⊙ log(Z⁻¹ T(t)) as a ``least_squares`` residual of the
    ``degree + 1`` control points that shape it (the sample's segment as the first of a
    spline of those points), its data ``(fraction, Z, √w)``; and its closed-form Jacobian,
    ``Spline.jacobians`` composed with J_r⁻¹ of the residual."""

    degree: int
    dt: Union[int, float]

    def _local(self, points: Tuple[Any, ...], fraction: jax.Array):
        cp = jax.tree_util.tree_map(lambda *p: jnp.stack(p), *points)
        spline = Spline(cp, degree=self.degree, t0=0, dt=self.dt)
        return spline, SplineTime(jnp.zeros((), jnp.int32), fraction)

    def __call__(self, *args: Any) -> jax.Array:
        *points, (fraction, Z, s) = args
        spline, where = self._local(tuple(points), fraction)
        return s * Z._between(_evaluate(spline, where, 0).value).log()

    def jacobian(self, *args: Any) -> Tuple[jax.Array, jax.Array]:
        *points, (fraction, Z, s) = args
        spline, where = self._local(tuple(points), fraction)
        r = Z._between(_evaluate(spline, where, 0).value).log()
        J = matmul(type(Z).jac_right_inv(r), _jacobians(spline, where).value)  # (order, k, k)
        return s * r, s[:, None] * jnp.concatenate(list(J), axis=-1)


@functools.lru_cache(maxsize=None)
def _sample(degree: int, dt: Union[int, float]) -> _Sample:
    """One ``_Sample`` per degree and knot spacing: ``jit`` keys the loop on the residual
    and on its bound ``jacobian``, which compare by the instance's identity."""
    return _Sample(degree, dt)


def fit(
    times: hints.Array,
    poses: GroupT,
    *,
    dt: Union[int, float],
    degree: int = 3,
    t0: Optional[Union[int, float]] = None,
    weights: Optional[hints.Array] = None,
    initial: Optional[Spline[GroupT]] = None,
    method: hints.SolverMethod = "lm",
    linear_solver: hints.LinearSolver = "auto",
    max_iterations: int = 50,
    tolerance: float = 1e-12,
    initial_damping: float = 1e-6,
    progress: bool = False,
) -> SplineFit:
    """Least-squares fit of a spline to time-stamped elements, on the group.

    Minimises ½ Σᵢ ‖ √wᵢ ⊙ log(Zᵢ⁻¹ T(tᵢ)) ‖² over the control points by
    Levenberg–Marquardt (or Gauss–Newton), with the exact Jacobians (``Spline.jacobians``
    composed with J_r⁻¹ of the residual) and steps T_m → T_m exp(δ_m); the loop, damping
    and stopping rules are those of ``pose_graph.solve``. Each sample's residual depends on
    ``degree + 1`` consecutive control points, so the normal equations are block-banded:
    time and memory grow linearly with the number of control points (docs/splines.md times
    a fit of 10⁴ control points).

    Args:
        times: concrete ``(N,)`` time stamps (float or integer, on the host).
        poses: the elements Zᵢ, batch ``(N,)``.
        dt: knot spacing.
        degree: 1 to 5.
        t0: start of the spline (default: the earliest time); the spline covers every
            time, with ``ceil((max(times) − t0)/dt) + degree`` control points.
        weights: ``(N,)`` (per sample) or ``(N, tangent_dim)`` (per residual coordinate),
            ≥ 0, default 1: inverse variances.
        initial: starting spline (same ``degree``, ``t0`` and ``dt``); default: each
            control point the sample nearest in time to its centre t0 + (i − (degree−1)/2)·dt.
        method: ``"lm"`` Levenberg–Marquardt or ``"gn"`` Gauss–Newton.
        linear_solver: as ``pose_graph.solve``'s; ``"auto"`` is CHOLMOD or QDLDL when
            installed, else the banded Cholesky (LAPACK, always available).
        max_iterations: the most accepted steps.
        tolerance: stop when a step lowers the cost by less than this fraction of it, or
            the linear model predicts less.
        initial_damping: Levenberg–Marquardt's first λ (damping λ diag(H)).
        progress: draw a progress line on stderr.

    Returns:
        ``SplineFit``: the spline and the loop's record.

    Raises:
        ValueError: inconsistent shapes, negative weights, an ``initial`` spline of other
            knots, or an option out of range.
    """
    clock = time.perf_counter()
    check_options(
        "splines.fit", method, linear_solver, max_iterations,
        tolerance=tolerance, initial_damping=initial_damping,
    )  # fmt: skip
    t_np = onp.asarray(times)
    if t_np.ndim != 1 or t_np.size == 0:
        raise ValueError(f"splines.fit: `times` must have shape (N,), got {t_np.shape}.")
    if not isinstance(poses, MatrixLieGroup) or poses.get_batch_axes() != t_np.shape:
        raise ValueError(
            f"splines.fit: `poses` must be a group element of batch {t_np.shape}, got "
            f"{getattr(poses, 'get_batch_axes', lambda: type(poses).__name__)()}."
        )
    G = type(poses)
    dtype = poses.parameters().dtype
    start = t_np.min() if t0 is None else t0
    start = start.item() if isinstance(start, onp.generic) else start
    span = (t_np.max() - start) / dt
    n = max(int(onp.ceil(span - 1e-9)), 1) + degree
    if initial is None:
        centres = start + (onp.arange(n) - (degree - 1) / 2) * dt
        order = onp.argsort(t_np, kind="stable")
        ts = t_np[order]
        right = onp.clip(onp.searchsorted(ts, centres), 1, len(ts) - 1) if len(ts) > 1 else 0
        left = right - 1 if len(ts) > 1 else 0
        closer_left = onp.abs(centres - ts[left]) <= onp.abs(ts[right] - centres)
        nearest = order[onp.where(closer_left, left, right)]
        initial = Spline(poses[jnp.asarray(nearest)], degree=degree, t0=start, dt=dt)
    elif (initial.degree, initial.t0, initial.dt) != (degree, start, dt):
        raise ValueError("splines.fit: `initial` must have the requested degree, t0 and dt.")
    where = initial.locate(t_np)
    N, k = t_np.size, G.tangent_dim
    w_np = onp.ones((N, k)) if weights is None else onp.asarray(weights, dtype=onp.float64)
    if w_np.shape not in ((N,), (N, k)) or not onp.all(w_np >= 0):
        raise ValueError(
            f"splines.fit: `weights` must be ≥ 0 of shape ({N},) or ({N}, {k}), got shape "
            f"{w_np.shape}."
        )
    w = jnp.asarray(onp.broadcast_to(w_np.reshape(N, -1), (N, k)), dtype)
    sample = _sample(degree, dt)
    first = onp.asarray(where.segment)
    factor = least_squares.Factor(
        sample,
        (0,) * (degree + 1),
        tuple(jnp.asarray(first + m) for m in range(degree + 1)),
        (jnp.broadcast_to(where.fraction, (N,)), poses, jnp.sqrt(w)),
        jacobian=sample.jacobian,
    )
    if linear_solver in ("auto", "cholesky"):
        installed: list[hints.LinearSolver] = [
            b for b in ("cholmod", "qdldl") if _sparse.installed(b)
        ]
        fallback: hints.LinearSolver = "banded" if linear_solver == "auto" else "qdldl"
        linear_solver = installed[0] if installed else fallback
    record = Record(clock, progress, max_iterations)
    with recording(record):
        sol = least_squares.solve(
            [factor], (initial.control_points,), method=method,
            max_iterations=max_iterations, tolerance=tolerance,
            initial_damping=initial_damping, diagonal_damping=True,
            linear_solver=linear_solver, callback=callback,
        )  # fmt: skip
        sol = jax.block_until_ready(sol)  # every callback has run
    iterations = int(sol.iterations)
    reason = least_squares.StopReason(int(sol.stop_reason)).description
    record.close(reason)
    costs, times = record.arrays(iterations)
    spline = Spline(sol.variables[0], degree=degree, t0=start, dt=dt)
    return SplineFit(
        costs=costs, times=times, iterations=iterations, time=time.perf_counter() - clock,
        stop_reason=reason, converged=bool(sol.converged), spline=spline,
    )  # fmt: skip
