"""Gauss–Newton and Levenberg–Marquardt on a pose graph.

The loop runs on the host; each of its steps is one compiled call, traced once per graph
size (number of poses and edges) and reused by every iteration and every later solve of a
graph of that size.

Levenberg–Marquardt (Levenberg, *A method for the solution of certain non-linear problems
in least squares*, 1944) solves (H + λD) δ = −g with D = I, or D = diag(H) (Marquardt,
*An algorithm for least-squares estimation of nonlinear parameters*, 1963), accepts a step
only if it lowers the cost, then divides λ by 10; after a step that does not, it multiplies
λ by ν and doubles ν (ν = 10 after every success). With D = I this is close to GTSAM's
``LevenbergMarquardtOptimizer`` with its default parameters; GTSAM also multiplies λ by a
fixed 10 after a failure, accepts a step only if its gain ratio (actual over predicted
decrease) exceeds 10⁻³, and gives up at λ = 10⁵ (here 10¹⁶).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import math
import sys
import time
from typing import Any, Literal, Optional, Sequence, Type

import jax
import jax.numpy as jnp
import numpy as onp
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._factors import Group, Problem, RobustKernel, cost, linearise, retract
from ._graph import TANGENT_DIM, PoseGraph, from_group, to_group
from ._linear import (
    DAMPING_FLOOR,
    BlockPattern,
    SparseCholesky,
    gradient_and_diagonal,
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


@dataclasses.dataclass(frozen=True)
class Solution:
    """What ``solve`` returns.

    Attributes:
        graph: the input graph with the optimised poses (``graph.poses``), ready to write.
        poses: the optimised poses, a group element of batch ``(N,)``, float64.
        costs: ``(iterations + 1,)``, the cost before the first and after every iteration,
            ½ Σ ρ(‖W r‖²) + the anchor's ½ ‖r_0/σ‖².
        times: ``(iterations + 1,)``, seconds since the call began at which each cost was
            reached (the first includes building the problem and, for a new graph size,
            compiling).
        iterations: accepted steps.
        time: wall-clock seconds of the whole call.
        stop_reason: why it stopped, in words.
        converged: whether it stopped on the tolerance (rather than the iteration limit,
            the damping limit or, for Gauss–Newton, a step that raised the cost).
    """

    graph: PoseGraph
    poses: Group
    costs: onp.ndarray
    times: onp.ndarray
    iterations: int
    time: float
    stop_reason: str
    converged: bool


def _problem(
    graph: PoseGraph, anchor_sigma: float, devices: Optional[Sequence[Any]]
) -> tuple[Problem, jax.Array]:
    """Device arrays of the graph, float64; edges padded to a multiple of the devices and
    sharded over them."""
    G = graph.group
    params = onp.asarray(to_group(graph.dim, graph.poses).normalize().parameters(), onp.float64)
    meas = onp.asarray(
        to_group(graph.dim, graph.measurements).normalize().parameters(), onp.float64
    )
    info = 0.5 * (graph.information + onp.swapaxes(graph.information, -1, -2))
    try:
        W = onp.swapaxes(onp.linalg.cholesky(info), -1, -2)
    except onp.linalg.LinAlgError:
        bad = int(onp.argmin(onp.linalg.eigvalsh(info)[:, 0]))
        raise ValueError(
            f"solve: the information of edge {bad} (of {len(info)}) is not positive definite"
        ) from None
    edge_i, edge_j = graph.edges[:, 0].astype(onp.int32), graph.edges[:, 1].astype(onp.int32)
    mesh = None
    if devices is not None and len(devices) > 1:
        pad = -len(edge_i) % len(devices)
        # Padding edges (0, 1) of zero weight add nothing to the cost, g or H (with the
        # Cholesky path, at most a block of zeros to H's pattern).
        edge_i = onp.concatenate([edge_i, onp.zeros(pad, onp.int32)])
        edge_j = onp.concatenate([edge_j, onp.ones(pad, onp.int32)])
        identity = onp.asarray(G.identity().parameters(), onp.float64)
        meas = onp.concatenate([meas, onp.broadcast_to(identity, (pad, meas.shape[1]))])
        W = onp.concatenate([W, onp.zeros((pad,) + W.shape[1:])])
        mesh = Mesh(onp.asarray(devices), ("edges",))
    p = Problem(
        jnp.asarray(edge_i),
        jnp.asarray(edge_j),
        jnp.asarray(meas),
        jnp.asarray(W),
        jnp.asarray(params[0]),
        jnp.asarray(1.0 / anchor_sigma, jnp.float64),
    )
    poses = jnp.asarray(params)
    if mesh is not None:
        sharded = lambda x: jax.device_put(x, NamedSharding(mesh, PartitionSpec("edges")))  # noqa: E731
        replicated = NamedSharding(mesh, PartitionSpec())
        p = Problem(*(sharded(x) for x in p[:4]), *(jax.device_put(x, replicated) for x in p[4:]))
        poses = jax.device_put(poses, replicated)
    elif devices is not None and len(devices) == 1:
        p, poses = jax.device_put((p, poses), devices[0])
    return p, poses


# -- compiled pieces (static: the group, the kernel, the number of poses) ----------------


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _cholesky_system(
    G: Type[Group], robust: Optional[RobustKernel], n: int, poses: jax.Array, p: Problem
):
    lin = linearise(G, poses, p, robust)
    g, _ = gradient_and_diagonal(lin, p, n)
    return lin.cost, hessian_values(lin), g


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _pcg_system(
    G: Type[Group], robust: Optional[RobustKernel], n: int, poses: jax.Array, p: Problem
):
    lin = linearise(G, poses, p, robust)
    g, D = gradient_and_diagonal(lin, p, n)
    return lin, g, D


@functools.partial(jax.jit, static_argnums=(5, 6, 7))
def _pcg_step(lin, p, g, D, lam, diagonal_damping, tolerance, max_iterations):
    diag = jnp.diagonal(D, axis1=-2, axis2=-1)
    damping = lam * (jnp.maximum(diag, DAMPING_FLOOR) if diagonal_damping else jnp.ones_like(diag))
    delta = pcg(lin, p, g, D, damping, tolerance, max_iterations)
    predicted = 0.5 * (jnp.sum(damping * delta * delta) - jnp.sum(g * delta))
    return delta, predicted


@functools.partial(jax.jit, static_argnums=(0, 1))
def _try_step(
    G: Type[Group], robust: Optional[RobustKernel], poses: jax.Array, delta: jax.Array, p: Problem
):
    new = retract(G, poses, delta)
    return new, cost(G, new, p, robust)


class _CholeskyPath:
    """Linearise on the device, assemble and factorise on the host."""

    def __init__(
        self, G, robust, graph: PoseGraph, p: Problem, diagonal_damping: bool, backend: str
    ):
        self.G, self.robust, self.n, self.p = G, robust, graph.num_poses, p
        self.diagonal_damping = diagonal_damping
        k = TANGENT_DIM[graph.dim]
        self.k = k
        self.pattern = BlockPattern(onp.asarray(p.edge_i), onp.asarray(p.edge_j), self.n, k)
        self.cholesky = SparseCholesky(self.pattern, backend)

    def linearise(self, poses: jax.Array) -> float:
        c, values, g = _cholesky_system(self.G, self.robust, self.n, poses, self.p)
        self.data = self.pattern.assemble(onp.asarray(values))
        self.g = onp.asarray(g).ravel()
        diag = self.data[self.pattern.diagonal]
        self.D = onp.maximum(diag, DAMPING_FLOOR) if self.diagonal_damping else onp.ones_like(diag)
        return float(c)

    def step(self, lam: float) -> tuple[jax.Array, float]:
        damping = lam * self.D
        delta = self.cholesky.solve(self.data, damping, self.g)
        predicted = 0.5 * (float(damping @ (delta * delta)) - float(self.g @ delta))
        return jnp.asarray(delta.reshape(self.n, self.k)), predicted


class _PCGPath:
    """Linearise and solve on the device(s)."""

    def __init__(
        self,
        G,
        robust,
        graph: PoseGraph,
        p: Problem,
        diagonal_damping: bool,
        tolerance: float,
        max_iterations: int,
    ):
        self.G, self.robust, self.n, self.p = G, robust, graph.num_poses, p
        self.diagonal_damping = diagonal_damping
        self.tolerance, self.max_iterations = tolerance, max_iterations

    def linearise(self, poses: jax.Array) -> float:
        self.lin, self.g, self.D = _pcg_system(self.G, self.robust, self.n, poses, self.p)
        return float(self.lin.cost)

    def step(self, lam: float) -> tuple[jax.Array, float]:
        delta, predicted = _pcg_step(
            self.lin, self.p, self.g, self.D, jnp.asarray(lam, jnp.float64),
            self.diagonal_damping, self.tolerance, self.max_iterations,
        )  # fmt: skip
        return delta, float(predicted)


class _Progress:
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


def solve(
    graph: PoseGraph,
    *,
    method: Literal["lm", "gn"] = "lm",
    linear_solver: Literal["auto", "cholesky", "cholmod", "qdldl", "pcg"] = "auto",
    robust: Optional[RobustKernel] = None,
    anchor_sigma: float = 1e-6,
    max_iterations: int = 100,
    tolerance: float = 1e-7,
    initial_damping: float = 1e-5,
    diagonal_damping: bool = False,
    cg_tolerance: float = 1e-10,
    cg_max_iterations: int = 2000,
    devices: Optional[Sequence[Any]] = None,
    progress: bool = False,
) -> Solution:
    """Minimise ½ Σ_edges ρ(‖Wᵢⱼ rᵢⱼ‖²) + ½ ‖log(P⁻¹ T₀)/σ‖² over the poses.

    rᵢⱼ = log(Zᵢⱼ⁻¹ Tᵢ⁻¹ Tⱼ) and Wᵢⱼ is the upper-triangular square root of the
    edge's information (WᵢⱼᵀWᵢⱼ = Ωᵢⱼ); ρ(s) = s without a robust kernel; P is the
    first pose's initial value. This is the cost GTSAM's ``BetweenFactor`` and
    ``PriorFactor`` define, in this library's tangent order. Computed in float64 whatever
    ``jax_enable_x64`` says.

    Arguments:
        graph: the graph; ``graph.poses`` is the initial estimate.
        method: ``"lm"`` Levenberg–Marquardt, or ``"gn"`` Gauss–Newton (every step taken;
            it stops, keeping the previous estimate, if a step raises the cost).
        linear_solver: ``"cholmod"`` (CHOLMOD's supernodal Cholesky on the host, through
            ``cvxopt``: the ``cholmod`` extra, GPL-3), ``"qdldl"`` (QDLDL's sparse LDLᵀ on
            the host: the ``pose-graph`` extra), ``"cholesky"`` (CHOLMOD if installed,
            else QDLDL), ``"pcg"`` (conjugate gradients on the device, block-Jacobi
            preconditioner), or ``"auto"``: ``"cholesky"`` when one of its packages is
            installed, whatever device holds the poses (the linearisation stays on the
            device, the factorisation runs on the host), PCG otherwise.
        robust: ``Huber(k)`` or ``Cauchy(k)``, on every edge (not the anchor).
        anchor_sigma: σ of the prior that holds the first pose at its initial value.
        max_iterations: the most accepted steps.
        tolerance: stop when a step's relative decrease of the cost, or the decrease the
            linear model predicts for an iteration's first (least damped) step, falls
            below it (GTSAM's default is 1e-5, Ceres
            Solver's 1e-6).
        initial_damping: Levenberg–Marquardt's first λ.
        diagonal_damping: damp with λ diag(H) (Marquardt's scaling, each entry at least
            ``DAMPING_FLOOR``) instead of λI. λI is the default, as in GTSAM: from the
            odometry of w20000 it reached a cost of 6,919 in 82 iterations, diag(H) 12,141
            after 100 (``docs/design/pose-graph-solver.md``).
        cg_tolerance: PCG's relative residual.
        cg_max_iterations: PCG's iteration limit.
        devices: several devices to shard the edges over (residuals, Jacobians and the
            conjugate-gradient products); ``None`` for the default device.
        progress: draw a progress line on stderr.

    Returns:
        A ``Solution``.

    Raises:
        ValueError: an argument out of range, an information matrix that is not
            positive definite, or a graph that is not connected.
    """
    if method not in ("lm", "gn"):
        raise ValueError(f"solve: method must be 'lm' or 'gn', got {method!r}")
    if linear_solver not in ("auto", "cholesky", "cholmod", "qdldl", "pcg"):
        raise ValueError(
            "solve: linear_solver must be 'auto', 'cholesky', 'cholmod', 'qdldl' or 'pcg', "
            f"got {linear_solver!r}"
        )
    for name, value in [
        ("anchor_sigma", anchor_sigma),
        ("tolerance", tolerance),
        ("initial_damping", initial_damping),
    ]:
        if not (value > 0 and math.isfinite(value)):
            raise ValueError(f"solve: {name} must be a positive number, got {value!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 0):
        raise ValueError(
            f"solve: max_iterations must be a non-negative int, got {max_iterations!r}"
        )
    if graph.num_poses < 2 or graph.num_edges < 1:
        raise ValueError(
            f"solve: a graph needs 2 poses and 1 edge, got {graph.num_poses} and {graph.num_edges}"
        )
    if onp.any(graph.edges[:, 0] == graph.edges[:, 1]):
        raise ValueError("solve: an edge joins a pose to itself")
    _check_connected(graph)
    chosen = linear_solver
    if chosen == "auto":
        chosen = "cholesky" if installed("cholmod") or installed("qdldl") else "pcg"
    if chosen == "cholesky":
        chosen = "cholmod" if installed("cholmod") else "qdldl"
    with jax.enable_x64(True):
        return _solve(
            graph, method, chosen, robust, anchor_sigma, max_iterations, tolerance,
            initial_damping, diagonal_damping, cg_tolerance, cg_max_iterations, devices, progress,
        )  # fmt: skip


def _check_connected(graph: PoseGraph) -> None:
    """Every pose must be joined to the first through edges: the anchor fixes only the
    first pose's component, and any other leaves H singular."""
    sparse = importlib.import_module("scipy.sparse")  # installed with jax, which needs it
    csgraph = importlib.import_module("scipy.sparse.csgraph")
    n = graph.num_poses
    i, j = graph.edges[:, 0], graph.edges[:, 1]
    adjacency = sparse.coo_matrix((onp.ones(len(i)), (i, j)), shape=(n, n))
    count, labels = csgraph.connected_components(adjacency, directed=False)
    if count > 1:
        loose = int(onp.flatnonzero(labels != labels[0])[0])
        raise ValueError(
            f"solve: the graph has {count} connected components; pose {loose} (id "
            f"{graph.ids[loose]}) is not joined to the first pose by any chain of edges"
        )


def _solve(
    graph, method, linear_solver, robust, anchor_sigma, max_iterations, tolerance,
    initial_damping, diagonal_damping, cg_tolerance, cg_max_iterations, devices, progress,
) -> Solution:  # fmt: skip
    start = time.perf_counter()
    G = graph.group
    p, poses = _problem(graph, anchor_sigma, devices)
    system: Any
    if linear_solver in ("cholmod", "qdldl"):
        system = _CholeskyPath(G, robust, graph, p, diagonal_damping, linear_solver)
    else:
        system = _PCGPath(G, robust, graph, p, diagonal_damping, cg_tolerance, cg_max_iterations)
    bar = _Progress(progress, max_iterations)
    current = system.linearise(poses)
    costs, times = [current], [time.perf_counter() - start]
    lam, nu = (initial_damping if method == "lm" else 0.0), DAMPING_FACTOR
    bar.update(0, current, 0.0, lam, times[-1])
    reason, converged = f"reached max_iterations = {max_iterations}", False
    for it in range(1, max_iterations + 1):
        accepted, first_try = False, True
        while True:
            delta, predicted = system.step(lam)
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
                new_poses, new = _try_step(G, robust, poses, delta, p)
                new = float(new)
                if method == "gn" or new < current:
                    accepted = True
                    break
            first_try = False
            lam, nu = lam * nu, 2.0 * nu
            if lam > MAX_DAMPING:
                reason = f"no step lowers the cost (λ > {MAX_DAMPING:g})"
                break
        if not accepted:
            break
        if method == "gn" and not new <= current:  # also a NaN cost
            reason = "a Gauss–Newton step raised the cost; the previous estimate is kept"
            break
        if method == "lm":
            lam, nu = max(lam / DAMPING_FACTOR, MIN_DAMPING), DAMPING_FACTOR
        decrease = (current - new) / current if current > 0 else 0.0
        poses = new_poses
        current = system.linearise(poses)
        costs.append(current)
        times.append(time.perf_counter() - start)
        if bar.enabled:
            bar.update(it, current, float(jnp.max(jnp.abs(delta))), lam, times[-1])
        if decrease < tolerance:
            reason, converged = "the relative decrease of the cost fell below tolerance", True
            break
    bar.close(reason)
    T = G(jax.device_get(poses))
    elapsed = time.perf_counter() - start
    return Solution(
        graph=graph.with_poses(from_group(T)),
        poses=T,
        costs=onp.asarray(costs),
        times=onp.asarray(times),
        iterations=len(costs) - 1,
        time=elapsed,
        stop_reason=reason,
        converged=converged,
    )


def graph_cost(
    graph: PoseGraph, *, robust: Optional[RobustKernel] = None, anchor_sigma: float = 1e-6
) -> float:
    """The cost ``solve`` minimises, at ``graph.poses`` (the anchor at the first pose
    itself, so it adds 0): ½ Σ ρ(‖Wᵢⱼ rᵢⱼ‖²), float64."""
    with jax.enable_x64(True):
        p, poses = _problem(graph, anchor_sigma, None)
        return float(_cost_jit(graph.group, robust, poses, p))


@functools.partial(jax.jit, static_argnums=(0, 1))
def _cost_jit(G, robust, poses, p):
    return cost(G, poses, p, robust)
