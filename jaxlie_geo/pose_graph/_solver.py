"""Gauss–Newton and Levenberg–Marquardt on a pose graph: the graph as a least-squares
problem for the shared loop (``jaxlie_geo._least_squares``, where the damping policy is
described), each step one compiled call traced once per graph size (number of poses and
edges) and reused by every iteration and every later solve of a graph of that size.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import time
from typing import Any, Optional, Sequence, Type

import jax
import jax.numpy as jnp
import numpy as onp
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .. import _least_squares as lsq
from .. import hints
from .._xla import x64
from ._factors import Group, Problem, RobustKernel, cost, linearise, retract
from ._graph import TANGENT_DIM, PoseGraph, from_group, to_group


@dataclasses.dataclass(frozen=True)
class Solution(lsq.Solution):
    """What ``solve`` returns: the record of the least-squares loop (``costs``, ``times``,
    ``iterations``, ``time``, ``stop_reason``, ``converged``; the costs are
    ½ Σ ρ(‖W r‖²) + the anchor's ½ ‖r_0/σ‖²), and

    Attributes:
        graph: the input graph with the optimised poses (``graph.poses``), ready to write.
        poses: the optimised poses, a group element of batch ``(N,)``, float64.
    """

    graph: PoseGraph
    poses: Group


@dataclasses.dataclass(frozen=True)
class _GraphModel:
    """The pose graph's cost as a ``_least_squares.Model``: x the poses' parameters
    ``(N, P)``, the data a ``Problem``."""

    group: Type[Group]
    robust: Optional[RobustKernel]

    def linearise(self, x: jax.Array, data: Problem):
        return linearise(self.group, x, data, self.robust)

    def cost(self, x: jax.Array, data: Problem) -> jax.Array:
        return cost(self.group, x, data, self.robust)

    def retract(self, x: jax.Array, delta: jax.Array) -> jax.Array:
        return retract(self.group, x, delta)


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


def solve(
    graph: PoseGraph,
    *,
    method: hints.SolverMethod = "lm",
    linear_solver: hints.LinearSolver = "auto",
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
            else QDLDL), ``"banded"`` or ``"dense"`` (LAPACK's Cholesky on the host, of H
            by diagonals or whole: for small graphs), ``"pcg"`` (conjugate gradients on
            the device, block-Jacobi preconditioner), or ``"auto"``: ``"cholesky"`` when
            one of its packages is installed, whatever device holds the poses (the
            linearisation stays on the device, the factorisation runs on the host), else
            ``"banded"`` when H's band is narrow (a graph without loop closures), else
            PCG.
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
    lsq.check_options(
        "solve", method, linear_solver, max_iterations,
        anchor_sigma=anchor_sigma, tolerance=tolerance, initial_damping=initial_damping,
    )  # fmt: skip
    if graph.num_poses < 2 or graph.num_edges < 1:
        raise ValueError(
            f"solve: a graph needs 2 poses and 1 edge, got {graph.num_poses} and {graph.num_edges}"
        )
    if onp.any(graph.edges[:, 0] == graph.edges[:, 1]):
        raise ValueError("solve: an edge joins a pose to itself")
    _check_connected(graph)
    start = time.perf_counter()
    with x64(True):
        p, poses = _problem(graph, anchor_sigma, devices)
        indices = [onp.stack([onp.asarray(p.edge_i), onp.asarray(p.edge_j)], -1), onp.zeros((1, 1))]
        model = _GraphModel(graph.group, robust)
        linear = lsq.system(
            model, p, indices, graph.num_poses, TANGENT_DIM[graph.dim], linear_solver,
            diagonal_damping, cg_tolerance, cg_max_iterations,
        )  # fmt: skip
        poses, record = lsq.minimise(
            model, poses, p, linear, method=method, max_iterations=max_iterations,
            tolerance=tolerance, initial_damping=initial_damping, progress=progress, start=start,
        )  # fmt: skip
        T = graph.group(jax.device_get(poses))
    fields = {f.name: getattr(record, f.name) for f in dataclasses.fields(record)}
    return Solution(**fields, graph=graph.with_poses(from_group(T)), poses=T)


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


def graph_cost(
    graph: PoseGraph, *, robust: Optional[RobustKernel] = None, anchor_sigma: float = 1e-6
) -> float:
    """The cost ``solve`` minimises, at ``graph.poses`` (the anchor at the first pose
    itself, so it adds 0): ½ Σ ρ(‖Wᵢⱼ rᵢⱼ‖²), float64."""
    with x64(True):
        p, poses = _problem(graph, anchor_sigma, None)
        return float(_cost_jit(graph.group, robust, poses, p))


@functools.partial(jax.jit, static_argnums=(0, 1))
def _cost_jit(G, robust, poses, p):
    return cost(G, poses, p, robust)
