"""Gauss–Newton and Levenberg–Marquardt on a pose graph: the graph as a problem of
``jaxlie_geo.least_squares`` (one variable set, the poses, and a second, the landmarks,
where the graph has them; the edges, the anchor and the landmark observations as factors
with closed-form Jacobians), solved in one compiled loop traced once per graph size
(number of poses and edges) and linear solver, and reused by every later solve of a graph
of that size.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import time
from typing import Any, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as onp
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .. import _sparse, hints, least_squares
from .._record import Record, Solve, callback, check_options, recording
from .._xla import x64
from ._factors import Group, Observations, Problem, RobustKernel, factors
from ._graph import TANGENT_DIM, PoseGraph, from_group, to_group

#: ``"auto"`` takes the banded Cholesky (when neither sparse package is installed) only if
#: the band holds at most this many times the pattern's stored entries.
BAND_FILL_LIMIT = 4


@dataclasses.dataclass(frozen=True)
class Solution(Solve):
    """What ``solve`` returns: the record of the solve (``costs``, ``times``, ``iterations``,
    ``time``, ``stop_reason``, ``converged``; the costs are ½ Σ ρ(‖W r‖²) + the anchor's
    ½ ‖r_0/σ‖²), and

    Attributes:
        graph: the input graph with the optimised poses (``graph.poses``) and landmarks
            (``graph.landmarks``), ready to write.
        poses: the optimised poses, a group element of batch ``(N,)``, float64.
        landmarks: the optimised landmark positions, ``(M, dim)`` float64 (``(0, dim)``
            for a graph without landmarks).
    """

    graph: PoseGraph
    poses: Group
    landmarks: onp.ndarray


def _sqrt_information(information: onp.ndarray, what: str) -> onp.ndarray:
    """W, upper triangular with WᵀW = Ω, of every matrix ``(·, k, k)``."""
    info = 0.5 * (information + onp.swapaxes(information, -1, -2))
    try:
        return onp.swapaxes(onp.linalg.cholesky(info), -1, -2)
    except onp.linalg.LinAlgError:
        bad = int(onp.argmin(onp.linalg.eigvalsh(info)[:, 0]))
        raise ValueError(
            f"solve: the information of {what} {bad} (of {len(info)}) is not positive definite"
        ) from None


def _observations(graph: PoseGraph) -> tuple[Optional[Observations], Optional[jax.Array]]:
    """Device arrays of the landmark observations and the landmarks, float64; None for a
    graph without landmarks."""
    if not graph.num_landmarks:
        return None, None
    W = _sqrt_information(graph.observation_information, "observation")
    o = Observations(
        jnp.asarray(graph.observations[:, 0].astype(onp.int32)),
        jnp.asarray(graph.observations[:, 1].astype(onp.int32)),
        jnp.asarray(graph.observation_measurements, jnp.float64),
        jnp.asarray(W),
    )
    return o, jnp.asarray(graph.landmarks, jnp.float64)


def _problem(
    graph: PoseGraph, anchor_sigma: float, devices: Optional[Sequence[Any]]
) -> tuple[Problem, jax.Array]:
    """Device arrays of the graph's poses and edges, float64; edges padded to a multiple of
    the devices and sharded over them."""
    G = graph.group
    params = onp.asarray(to_group(graph.dim, graph.poses).normalize().parameters(), onp.float64)
    meas = onp.asarray(
        to_group(graph.dim, graph.measurements).normalize().parameters(), onp.float64
    )
    W = _sqrt_information(graph.information, "edge")
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
    """Minimise ½ Σ_edges ρ(‖Wᵢⱼ rᵢⱼ‖²) + ½ ‖log(P⁻¹ T₀)/σ‖² + ½ Σ_observations
    ρ(‖Wᵢₘ rᵢₘ‖²) over the poses (and the landmarks).

    rᵢⱼ = log(Zᵢⱼ⁻¹ Tᵢ⁻¹ Tⱼ) and Wᵢⱼ is the upper-triangular square root of the
    edge's information (WᵢⱼᵀWᵢⱼ = Ωᵢⱼ); ρ(s) = s without a robust kernel; P is the
    first pose's initial value. This is the cost GTSAM's ``BetweenFactor`` and
    ``PriorFactor`` define, in this library's tangent order. A graph with landmarks adds
    its observations, rᵢₘ = Tᵢ⁻¹ lₘ − zᵢₘ = Rᵢᵀ(lₘ − tᵢ) − zᵢₘ, whitened likewise, and
    optimises the landmark positions lₘ with the poses. Computed in float64 whatever
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
        robust: ``Huber(k)`` or ``Cauchy(k)``, on every edge and landmark observation (not
            the anchor).
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
            conjugate-gradient products; landmark observations are replicated); ``None``
            for the default device.
        progress: draw a progress line on stderr.

    Returns:
        A ``Solution``.

    Raises:
        ValueError: an argument out of range, an information matrix that is not
            positive definite, or a graph that is not connected.
    """
    check_options(
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
    record = Record(start, progress, max_iterations)
    solver = _linear_solver(linear_solver, graph)
    with x64(True):
        p, poses = _problem(graph, anchor_sigma, devices)
        o, landmarks = _observations(graph)
        if o is not None and devices is not None:
            o, landmarks = jax.device_put((o, landmarks), poses.sharding)
        G = graph.group
        variables = (G(poses),) if landmarks is None else (G(poses), landmarks)
        with recording(record):
            sol = least_squares.solve(
                factors(G, p, robust, o), variables, method=method,
                max_iterations=max_iterations, tolerance=tolerance,
                initial_damping=initial_damping, diagonal_damping=diagonal_damping,
                linear_solver=solver,
                cg_tolerance=cg_tolerance, cg_max_iterations=cg_max_iterations,
                callback=callback,
            )  # fmt: skip
            sol = jax.block_until_ready(sol)  # every callback has run
        T = G(jax.device_get(sol.variables[0].parameters()))
        L = (
            onp.asarray(jax.device_get(sol.variables[1]), onp.float64)
            if landmarks is not None
            else graph.landmarks
        )
        iterations = int(sol.iterations)
    reason = least_squares.StopReason(int(sol.stop_reason))
    record.close(reason.description)
    costs, times = record.arrays(iterations)
    return Solution(
        costs=costs,
        times=times,
        iterations=iterations,
        time=time.perf_counter() - start,
        stop_reason=reason.description,
        converged=bool(sol.converged),
        graph=graph.with_poses(from_group(T), L),
        poses=T,
        landmarks=L,
    )


def _linear_solver(name: hints.LinearSolver, graph: PoseGraph) -> hints.LinearSolver:
    """``least_squares.solve``'s name for ``name``: ``"cholesky"`` is CHOLMOD if cvxopt
    imports, else QDLDL; ``"auto"`` is ``"cholesky"`` if either imports, else (for a graph
    without landmarks) the banded Cholesky if H's band is narrow (at most
    ``BAND_FILL_LIMIT`` times its stored entries), else PCG."""
    if name == "auto":
        if _sparse.installed("cholmod") or _sparse.installed("qdldl"):
            name = "cholesky"
        elif graph.num_landmarks:  # the landmarks' columns follow every pose's: no band
            name = "pcg"
        else:
            k, n = TANGENT_DIM[graph.dim], graph.num_poses
            i, j = onp.sort(graph.edges, axis=1).T
            pairs = onp.unique(i * n + j).size
            bandwidth = int(onp.max(j - i)) * k + k - 1
            nnz = n * k * (k + 1) // 2 + pairs * k * k
            name = "banded" if (bandwidth + 1) * n * k <= BAND_FILL_LIMIT * nnz else "pcg"
    if name == "cholesky":
        name = "cholmod" if _sparse.installed("cholmod") else "qdldl"
    return name


def _check_connected(graph: PoseGraph) -> None:
    """Every pose and landmark must be joined to the first pose through edges and
    observations: the anchor fixes only the first pose's component, and any other leaves H
    singular."""
    sparse = importlib.import_module("scipy.sparse")  # installed with jax, which needs it
    csgraph = importlib.import_module("scipy.sparse.csgraph")
    n, m = graph.num_poses, graph.num_landmarks
    i = onp.concatenate([graph.edges[:, 0], graph.observations[:, 0]])
    j = onp.concatenate([graph.edges[:, 1], n + graph.observations[:, 1]])
    adjacency = sparse.coo_matrix((onp.ones(len(i)), (i, j)), shape=(n + m, n + m))
    count, labels = csgraph.connected_components(adjacency, directed=False)
    if count > 1:
        loose = int(onp.flatnonzero(labels != labels[0])[0])
        what = (
            f"pose {loose} (id {graph.ids[loose]})"
            if loose < n
            else f"landmark {loose - n} (id {graph.landmark_ids[loose - n]})"
        )
        raise ValueError(
            f"solve: the graph has {count} connected components; {what} is not joined to "
            "the first pose by any chain of edges and observations"
        )


def graph_cost(
    graph: PoseGraph, *, robust: Optional[RobustKernel] = None, anchor_sigma: float = 1e-6
) -> float:
    """The cost ``solve`` minimises, at ``graph.poses`` and ``graph.landmarks`` (the anchor
    at the first pose itself, so it adds 0): ½ Σ ρ(‖Wᵢⱼ rᵢⱼ‖²) + ½ Σ ρ(‖Wᵢₘ rᵢₘ‖²),
    float64."""
    with x64(True):
        p, poses = _problem(graph, anchor_sigma, None)
        o, landmarks = _observations(graph)
        return float(_cost_jit(robust, graph.group(poses), p, o, landmarks))


@functools.partial(jax.jit, static_argnums=(0,))
def _cost_jit(robust, poses, p, o, landmarks):
    variables = (poses,) if landmarks is None else (poses, landmarks)
    return least_squares.cost(factors(type(poses), p, robust, o), variables)
