"""Least-squares fit of a spline to time-stamped elements on the group, through the loop
of ``_least_squares`` with the spline's exact control-point Jacobians."""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Optional, Tuple, Union

import jax
import jax.numpy as jnp
import numpy as onp

from .. import _least_squares as lsq
from .. import hints
from .._base import GroupT, MatrixLieGroup
from .._least_squares import Solution
from .._sparse import Factors
from .._xla import matmul
from ._curve import Spline, SplineTime, _evaluate, _jacobians


@dataclasses.dataclass(frozen=True)
class SplineFit(Solution):
    """What ``fit`` returns: the record of the least-squares loop (``costs``, ½ Σ wᵢ ‖rᵢ‖²
    before the first step and after each accepted one; ``times``; ``iterations``, the
    accepted steps; ``time``; ``stop_reason``; ``converged``), and

    Attributes:
        spline: the fitted ``Spline``.
    """

    spline: Any


@dataclasses.dataclass(frozen=True)
class _FitModel:
    """The fit's cost as a ``_least_squares.Model``: x the control points' parameters
    ``(n, P)``; the data the samples' ``SplineTime``, the parameters of the Zᵢ and the
    weights ``(N, tangent_dim)``. One factor per sample, on the ``order`` control points
    that shape it."""

    group: Any
    degree: int
    t0: Union[int, float]
    dt: Union[int, float]

    def _spline(self, x: jax.Array) -> Spline[Any]:
        return Spline(self.group(x), degree=self.degree, t0=self.t0, dt=self.dt)

    def _residual(self, x: jax.Array, data: Tuple[SplineTime, jax.Array, jax.Array]):
        where, poses, w = data
        value = _evaluate(self._spline(x), where, 0).value
        return self.group(poses)._between(value).log(), jnp.sqrt(w)

    def cost(self, x: jax.Array, data: Tuple[SplineTime, jax.Array, jax.Array]) -> jax.Array:
        r, s = self._residual(x, data)
        return 0.5 * jnp.sum((s * r) ** 2)

    def linearise(self, x: jax.Array, data: Tuple[SplineTime, jax.Array, jax.Array]):
        r, s = self._residual(x, data)
        jac = _jacobians(self._spline(x), data[0])
        J = matmul(self.group.jac_right_inv(r)[:, None], jac.value)  # (N, order, k, k)
        e = s * r
        variables = jac.first[:, None] + jnp.arange(self.degree + 1)
        return 0.5 * jnp.sum(e * e), (Factors(variables, e, s[:, None, :, None] * J),)

    def retract(self, x: jax.Array, delta: jax.Array) -> jax.Array:
        return (self.group(x) @ self.group.exp(delta)).parameters()


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
    lsq.check_options(
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
    model = _FitModel(G, degree, start, dt)
    data = (where, poses.parameters(), w)
    variables = onp.asarray(where.segment)[:, None] + onp.arange(degree + 1)
    linear = lsq.system(model, data, [variables], n, k, linear_solver, diagonal_damping=True)
    x, record = lsq.minimise(
        model, initial.control_points.parameters(), data, linear, method=method,
        max_iterations=max_iterations, tolerance=tolerance, initial_damping=initial_damping,
        progress=progress, start=clock,
    )  # fmt: skip
    fields = {f.name: getattr(record, f.name) for f in dataclasses.fields(record)}
    return SplineFit(**fields, spline=model._spline(x))
