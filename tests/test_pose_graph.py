"""The pose-graph solver (``jaxlie_geo.pose_graph.solve``) against independent references.

The references:

- the minimum found by ``scipy.optimize.least_squares`` (MINPACK's Levenberg–Marquardt) on
  the whitened residuals written here in NumPy: homogeneous matrices, the rotation
  logarithm of ``scipy.spatial.transform.Rotation`` and the textbook closed forms of the
  SE(2)/SE(3) exponential and logarithm (checked against ``scipy.linalg.expm``/``logm``
  first), with the first pose held fixed;
- the gradient of the cost by ``jax.grad`` through the library's group operations (not the
  solver's closed-form Jacobians), which vanishes at a stationary point;
- the cost's symmetries: invariance under T ↦ S T (the solution moves with the anchor);
- ground truth, for the robust kernels with a gross outlier;
- the kernels' definitions and a finite-difference derivative of ρ;
- GTSAM's ``BetweenFactorPose2``/``BetweenFactorPose3`` and its Levenberg–Marquardt
  optimiser, where ``gtsam`` is installed;
- the same solve sharded over four host devices, in a subprocess.

Compiling dominates: every test uses one generated graph per group (30 poses, 29 odometry
edges and 10 loop closures; the outlier graph has the same shapes), so the solver's
programs compile once per group and kernel.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, Tuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import expm_ref, hat_ref, logm_ref, vee_ref
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from jaxlie_geo import SE2, SE3, pose_graph
from jaxlie_geo._xla import x64
from jaxlie_geo.pose_graph import Cauchy, Huber, PoseGraph, graph_cost, solve

REPO = Path(__file__).resolve().parents[1]
NUM_POSES, NUM_LOOPS = 30, 10
GROUP = {2: SE2, 3: SE3}
TIGHT = 1e-14
"""A tolerance at which the solves stop only when rounding ends the descent: the
comparisons of optima use it, so that they do not depend on the default tolerance."""
OMEGA_V = [3, 4, 5, 0, 1, 2]
"""GTSAM's Pose3 tangent is (ω, v); this library's is (v, ω)."""

over_dims = pytest.mark.parametrize("dim", [2, 3], ids=["SE2", "SE3"])


# ---------------------------------------------------------------------------------------
# Independent references: homogeneous matrices, closed-form exp and log in NumPy.


def _matrix(dim: int, row: np.ndarray) -> np.ndarray:
    """Homogeneous matrices of vertex-layout rows ``(·, 3)``/``(·, 7)`` (scipy's quaternions
    are (x, y, z, w), as in the layout)."""
    row = np.asarray(row, np.float64)
    T = np.zeros(row.shape[:-1] + (dim + 1, dim + 1))
    T[..., -1, -1] = 1.0
    if dim == 2:
        c, s = np.cos(row[..., 2]), np.sin(row[..., 2])
        T[..., 0, 0], T[..., 0, 1], T[..., 1, 0], T[..., 1, 1] = c, -s, s, c
        T[..., :2, 2] = row[..., :2]
    else:
        T[..., :3, :3] = Rotation.from_quat(row[..., 3:]).as_matrix()
        T[..., :3, 3] = row[..., :3]
    return T


def _row(dim: int, T: np.ndarray) -> np.ndarray:
    """Vertex-layout rows of homogeneous matrices."""
    if dim == 2:
        return np.concatenate(
            [T[..., :2, 2], np.arctan2(T[..., 1, 0], T[..., 0, 0])[..., None]], axis=-1
        )
    return np.concatenate([T[..., :3, 3], Rotation.from_matrix(T[..., :3, :3]).as_quat()], -1)


def _coefficients(theta: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(1 − cos θ)/θ², (θ − sin θ)/θ³ and sin θ/θ, with Taylor series below 1e-3."""
    small = theta < 1e-3
    t = np.where(small, 1.0, theta)
    t2 = theta * theta
    a = np.where(small, 0.5 - t2 / 24 + t2 * t2 / 720, (1 - np.cos(t)) / t**2)
    b = np.where(small, 1 / 6 - t2 / 120 + t2 * t2 / 5040, (t - np.sin(t)) / t**3)
    c = np.where(small, 1 - t2 / 6 + t2 * t2 / 120, np.sin(t) / t)
    return a, b, c


def _skew(w: np.ndarray) -> np.ndarray:
    z = np.zeros(w.shape[:-1])
    x, y, u = w[..., 0], w[..., 1], w[..., 2]
    return np.stack(
        [np.stack([z, -u, y], -1), np.stack([u, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


def _left_jacobian(dim: int, phi: np.ndarray) -> np.ndarray:
    """V = ∫₀¹ exp(s φ̂) ds, the translation block of exp: t = V v."""
    if dim == 2:
        a, _, c = _coefficients(np.abs(phi))
        return np.stack([np.stack([c, -a * phi], -1), np.stack([a * phi, c], -1)], -2)
    a, b, _ = _coefficients(np.linalg.norm(phi, axis=-1))
    K = _skew(phi)
    return np.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K)


def _exp(dim: int, xi: np.ndarray) -> np.ndarray:
    """exp(hat(ξ)) of tangents (v, θ) / (v, ω), batched: R from the angle (rotation vector),
    t = V v."""
    T = np.zeros(xi.shape[:-1] + (dim + 1, dim + 1))
    T[..., -1, -1] = 1.0
    phi = xi[..., 2] if dim == 2 else xi[..., 3:]
    if dim == 2:
        c, s = np.cos(phi), np.sin(phi)
        T[..., 0, 0], T[..., 0, 1], T[..., 1, 0], T[..., 1, 1] = c, -s, s, c
    else:
        T[..., :3, :3] = Rotation.from_rotvec(phi).as_matrix()
    T[..., :dim, dim] = np.einsum("...ab,...b->...a", _left_jacobian(dim, phi), xi[..., :dim])
    return T


def _log(dim: int, T: np.ndarray) -> np.ndarray:
    """The principal logarithm of homogeneous matrices: the rotation's angle (vector), then
    v = V⁻¹ t."""
    if dim == 2:
        phi = np.arctan2(T[..., 1, 0], T[..., 0, 0])
    else:
        phi = Rotation.from_matrix(T[..., :3, :3]).as_rotvec()
    v = np.linalg.solve(_left_jacobian(dim, phi), T[..., :dim, dim : dim + 1])[..., 0]
    return np.concatenate([v, phi[..., None] if dim == 2 else phi], axis=-1)


class _Residuals:
    """The whitened residuals W_ij log(Z_ij⁻¹ T_i⁻¹ T_j), ``(E, k)``, of poses given as
    homogeneous matrices; W_ij any square root of the information (WᵀW = Ω)."""

    def __init__(self, graph: PoseGraph):
        self.dim = graph.dim
        self.i, self.j = graph.edges[:, 0], graph.edges[:, 1]
        self.Z_inv = np.linalg.inv(_matrix(graph.dim, graph.measurements))
        self.W = np.swapaxes(np.linalg.cholesky(graph.information), -1, -2)

    def __call__(self, T: np.ndarray) -> np.ndarray:
        E = self.Z_inv @ np.linalg.inv(T[self.i]) @ T[self.j]
        return np.einsum("eab,eb->ea", self.W, _log(self.dim, E))


def _cost_reference(graph: PoseGraph, rho=lambda s: s) -> float:
    """½ Σ ρ(‖W r‖²) at ``graph.poses``."""
    e = _Residuals(graph)(_matrix(graph.dim, graph.poses))
    return 0.5 * float(np.sum(rho(np.sum(e * e, axis=-1))))


# ---------------------------------------------------------------------------------------
# The graphs.


@dataclasses.dataclass(frozen=True)
class _Case:
    graph: PoseGraph
    truth: np.ndarray  # (N, m, m) ground-truth poses, truth[0] = initial pose 0
    outlier: int  # the loop closure that ``_outlier_graph`` corrupts


@functools.lru_cache(maxsize=None)
def _case(dim: int) -> _Case:
    """A ground-truth trajectory (a planar spiral / a helix with random steps), odometry
    edges i → i+1 and random loop closures; measurements Z = T_i⁻¹ T_j exp(n) with n drawn
    from each edge's covariance (random, correlated); the information is its inverse; the
    initial estimate chains the odometry measurements from the true first pose."""
    rng = np.random.default_rng(dim)
    k = 3 if dim == 2 else 6
    step = np.array([1.0, 0.0, 0.25]) if dim == 2 else np.array([0.6, 0, 0.08, 0.03, 0.05, 0.3])
    steps = _exp(dim, step + 0.1 * rng.normal(size=(NUM_POSES - 1, k)))
    truth = [np.eye(dim + 1)]
    for S in steps:
        truth.append(truth[-1] @ S)
    pairs = [(i, i + 1) for i in range(NUM_POSES - 1)]
    while len(pairs) < NUM_POSES - 1 + NUM_LOOPS:
        i, j = sorted(int(a) for a in rng.choice(NUM_POSES, 2, replace=False))
        if j > i + 1 and (i, j) not in pairs:
            pairs.append((i, j))
    sigma = np.where(np.arange(k) < dim, 0.05, 0.02)  # metres, radians
    measured, information = [], []
    for i, j in pairs:
        C = rng.normal(size=(k, k))
        C = C @ C.T + k * np.eye(k)
        d = sigma / np.sqrt(np.diag(C))
        covariance = d[:, None] * C * d[None, :]
        noise = np.linalg.cholesky(covariance) @ rng.normal(size=k)
        measured.append(np.linalg.inv(truth[i]) @ truth[j] @ _exp(dim, noise))
        info = np.linalg.inv(covariance)
        information.append(0.5 * (info + info.T))
    initial = [truth[0]]
    for Z in measured[: NUM_POSES - 1]:
        initial.append(initial[-1] @ Z)
    graph = PoseGraph(
        dim,
        np.arange(NUM_POSES, dtype=np.int64),
        _row(dim, np.array(initial)),
        np.array(pairs, dtype=np.int64),
        _row(dim, np.array(measured)),
        np.array(information),
    )
    lengths = [j - i for i, j in pairs[NUM_POSES - 1 :]]
    return _Case(graph, np.array(truth), NUM_POSES - 1 + int(np.argmin(lengths)))


@functools.lru_cache(maxsize=None)
def _solved(dim: int, **options: Any) -> pose_graph.Solution:
    """``solve`` of ``_case(dim).graph``, once per set of options."""
    return solve(_case(dim).graph, **options)


def _outlier_graph(dim: int) -> PoseGraph:
    """The graph with its shortest loop closure (two odometry edges span it, so it is
    checked by few measurements) replaced by a gross outlier: the true relative pose
    composed with a 5 m translation and a 1 rad rotation.

    (Where an outlier spans a long chain of odometry, a convex kernel such as Huber's can
    spread its error over the chain instead: on the SE2 graph, an outlier on the loop
    closure 4 → 28 leaves Huber's solution as far from the truth as least squares.)"""
    case = _case(dim)
    g, e = case.graph, case.outlier
    i, j = g.edges[e]
    error = np.eye(dim + 1)
    if dim == 2:
        error[:2, :2] = [[np.cos(1.0), -np.sin(1.0)], [np.sin(1.0), np.cos(1.0)]]
    else:
        error[:3, :3] = Rotation.from_rotvec(np.array([1.0, 1.0, 1.0]) / np.sqrt(3)).as_matrix()
    error[:dim, dim] = 5.0 * np.ones(dim) / np.sqrt(dim)
    measurements = g.measurements.copy()
    measurements[e] = _row(dim, np.linalg.inv(case.truth[i]) @ case.truth[j] @ error)
    return dataclasses.replace(g, measurements=measurements)


def _matrices(solution: pose_graph.Solution) -> np.ndarray:
    return np.asarray(solution.poses.as_matrix(), np.float64)


# ---------------------------------------------------------------------------------------
# The optimum.


def test_closed_forms_match_expm_and_logm() -> None:
    """The NumPy closed forms the references use are ``scipy.linalg.expm``/``logm`` of the
    Lie-algebra matrices (built from the generators written in conftest), at generic
    angles, at 1e-4 and at zero."""
    rng = np.random.default_rng(0)
    for dim, G in GROUP.items():
        k = G.tangent_dim
        xi = rng.normal(size=(4, k))
        rot = slice(2, 3) if dim == 2 else slice(3, 6)
        xi[1, rot] *= 1e-4 / np.linalg.norm(xi[1, rot])
        xi[2, rot] = 0.0
        np.testing.assert_allclose(_exp(dim, xi), expm_ref(G, xi), rtol=0, atol=1e-13)
        np.testing.assert_allclose(_log(dim, expm_ref(G, xi)), xi, rtol=0, atol=1e-12)
        np.testing.assert_allclose(
            _log(dim, expm_ref(G, xi)), vee_ref(G, logm_ref(expm_ref(G, xi))), atol=1e-12
        )
        np.testing.assert_allclose(hat_ref(G, xi), logm_ref(_exp(dim, xi)), rtol=0, atol=1e-12)


@over_dims
def test_optimum_matches_scipy_least_squares(dim: int) -> None:
    """The Levenberg–Marquardt optimum is the one MINPACK's Levenberg–Marquardt
    (``scipy.optimize.least_squares(method="lm")``) finds on the whitened residuals written
    in NumPy, T_i = T_i⁰ exp(ξ_i) with T_0 held fixed (which the anchor does up to
    O(σ²)): at a tight tolerance the same cost to 1e-9 relative and the same poses to 1e-6;
    at the default tolerance a cost above the minimum by less than that tolerance."""
    graph = _case(dim).graph
    k = GROUP[dim].tangent_dim
    start = _matrix(dim, graph.poses)
    residuals = _Residuals(graph)

    def poses(x: np.ndarray) -> np.ndarray:
        xi = np.concatenate([np.zeros((1, k)), x.reshape(-1, k)])
        return start @ _exp(dim, xi)

    x0 = np.zeros((graph.num_poses - 1) * k)
    ref = least_squares(
        lambda x: residuals(poses(x)).ravel(), x0, method="lm", ftol=1e-14, xtol=1e-14,
        gtol=1e-14,
    )  # fmt: skip
    assert ref.success, ref.message
    assert ref.cost < 0.2 * _cost_reference(graph)  # it moved: the start is not the optimum
    tight = _solved(dim, tolerance=TIGHT)
    assert tight.converged, tight.stop_reason
    np.testing.assert_allclose(tight.costs[-1], ref.cost, rtol=1e-9)
    default = _solved(dim)
    tolerance = inspect.signature(solve).parameters["tolerance"].default
    assert default.converged, default.stop_reason
    assert ref.cost * (1 - 1e-9) <= default.costs[-1] <= ref.cost * (1 + tolerance)
    T = _matrices(tight)
    want = poses(ref.x)
    np.testing.assert_allclose(T[:, :dim, dim], want[:, :dim, dim], rtol=0, atol=1e-6)
    np.testing.assert_allclose(T[:, :dim, :dim], want[:, :dim, :dim], rtol=0, atol=1e-6)
    np.testing.assert_allclose(T[0], start[0], rtol=0, atol=1e-9)  # the anchor holds


@over_dims
def test_gradient_vanishes_at_the_optimum(dim: int) -> None:
    """``jax.grad`` of ½ Σ ‖W log(Z⁻¹ (T_i exp δ_i)⁻¹ (T_j exp δ_j))‖², written with the
    library's group operations, with respect to the right perturbations δ: at the solution
    (at a tight tolerance), below 1e-6 of its norm at the initial estimate. The edges' cost
    alone is stationary: it is invariant under T ↦ S T, so a gradient that vanishes on
    every pose but the anchored one vanishes there too."""
    graph = _case(dim).graph
    G = GROUP[dim]
    with x64(True):
        Z = G(jnp.asarray(graph.measurement_group().parameters(), jnp.float64))
        W = jnp.asarray(np.swapaxes(np.linalg.cholesky(graph.information), -1, -2))
        i, j = graph.edges[:, 0], graph.edges[:, 1]

        @jax.jit
        def gradient(params: jax.Array) -> jax.Array:
            def cost(delta: jax.Array) -> jax.Array:
                T = G(params) @ G.exp(delta)
                r = (Z.inverse() @ T[i].inverse() @ T[j]).log()
                e = jnp.einsum("eab,eb->ea", W, r)
                return 0.5 * jnp.sum(e * e)

            return jax.grad(cost)(jnp.zeros((len(params), G.tangent_dim), jnp.float64))

        def norm_at(poses: Any) -> float:
            g = np.asarray(gradient(jnp.asarray(poses.parameters(), jnp.float64)))
            assert g.dtype == np.float64
            return float(np.linalg.norm(g))

        at_start = norm_at(graph.pose_group())
        at_optimum = norm_at(_solved(dim, tolerance=TIGHT).poses)
    assert at_start > 100.0
    assert at_optimum < 1e-6 * at_start, (at_optimum, at_start)


@over_dims
def test_gauss_newton_and_levenberg_marquardt_with_cholesky_and_pcg_agree(dim: int) -> None:
    """Gauss–Newton, and Levenberg–Marquardt with each sparse Cholesky (CHOLMOD, QDLDL) and
    with conjugate gradients, converge to the same cost (1e-8 relative) and poses (1e-7), at
    a tight tolerance; ``"cholesky"`` is CHOLMOD where cvxopt is installed (it is, with the
    test extra)."""
    solutions = {
        "gn": _solved(dim, method="gn", tolerance=TIGHT),
        "lm-cholesky": _solved(dim, linear_solver="cholesky", tolerance=TIGHT),
        "lm-cholmod": _solved(dim, linear_solver="cholmod", tolerance=TIGHT),
        "lm-qdldl": _solved(dim, linear_solver="qdldl", tolerance=TIGHT),
        "lm-pcg": _solved(dim, linear_solver="pcg", tolerance=TIGHT),
    }
    assert solutions["lm-cholesky"].costs.tolist() == solutions["lm-cholmod"].costs.tolist()
    want = solutions["lm-cholesky"]
    for name, solution in solutions.items():
        assert solution.converged, (name, solution.stop_reason)
        np.testing.assert_allclose(solution.costs[0], want.costs[0], rtol=1e-12, err_msg=name)
        np.testing.assert_allclose(solution.costs[-1], want.costs[-1], rtol=1e-8, err_msg=name)
        np.testing.assert_allclose(_matrices(solution), _matrices(want), atol=1e-7, err_msg=name)
    assert _solved(dim, tolerance=TIGHT).costs[-1] == want.costs[-1]  # "auto": Cholesky on a CPU
    one_device = solve(_case(dim).graph, tolerance=TIGHT, devices=jax.devices()[:1])
    assert one_device.costs[-1] == want.costs[-1]


@pytest.mark.parametrize(
    ("backend", "supernodal"),
    [("cholmod", True), ("cholmod", False), ("qdldl", True), ("banded", True), ("dense", True)],
)
def test_sparse_cholesky_solves_each_damping_against_numpy(backend: str, supernodal: bool) -> None:
    """The host factorisations, refactorised at several dampings of one pattern (as a
    Levenberg–Marquardt loop does), each solve (H + λD) δ = −g to rounding against
    ``numpy.linalg.solve`` of the dense matrix; the pattern holds factors on two variables
    and, repeated, on three."""
    from jaxlie_geo._sparse import BandedCholesky, BlockPattern, SparseCholesky

    rng = np.random.default_rng(3)
    n, k = 12, 6
    edge_i = np.concatenate([np.arange(n - 1), rng.integers(0, n, 8)])
    edge_j = np.concatenate([np.arange(1, n), rng.integers(0, n, 8)])
    keep = edge_i != edge_j
    triples = np.array([[2, 3, 4], [2, 3, 4], [7, 8, 9]])
    pattern = BlockPattern([np.stack([edge_i[keep], edge_j[keep]], -1), triples], n, k)
    assert pattern.segment_counts[1] == 2 and pattern.segment_ids[1].tolist() == [0, 0, 1]
    size = pattern.size
    # A positive definite matrix on the pattern: its upper triangle, as the solver stores it.
    dense = np.zeros((size, size))
    rows = pattern.indices
    cols = pattern.columns
    dense[rows, cols] = rng.normal(size=pattern.nnz)
    dense = dense + dense.T + 4.0 * size * np.eye(size)
    data = dense[rows, cols]
    if backend in ("banded", "dense"):
        solver = BandedCholesky(pattern, dense=backend == "dense")
    else:
        solver = SparseCholesky(pattern, backend, supernodal)
    g = rng.normal(size=size)
    for lam in (0.0, 1e-3, 10.0, 0.0):
        damping = lam * np.abs(np.diagonal(dense))
        got = solver.solve(data, damping, g)
        want = np.linalg.solve(dense + np.diag(damping), -g)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14, err_msg=f"λ = {lam}")
    # −H is not positive definite: a Cholesky factorisation refuses it (NaN, so that the
    # loop raises λ), an LDLᵀ one (QDLDL, simplicial CHOLMOD) solves it.
    got = solver.solve(-data, 0.0 * damping, g)
    if backend in ("banded", "dense") or (backend == "cholmod" and supernodal):
        assert np.isnan(got).all()
    else:
        np.testing.assert_allclose(got, np.linalg.solve(-dense, -g), rtol=1e-12, atol=1e-14)


def test_cholesky_falls_back_to_qdldl_without_cvxopt(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without cvxopt (an optional, GPL-licensed extra), ``"cholesky"`` and ``"auto"``
    factorise with QDLDL, step for step as ``linear_solver="qdldl"``, and ``"cholmod"``
    raises ``ImportError`` naming the extra to install."""
    want = _solved(3, linear_solver="qdldl", tolerance=TIGHT)
    monkeypatch.setitem(sys.modules, "cvxopt", None)  # makes `import cvxopt` fail
    monkeypatch.setitem(sys.modules, "cvxopt.cholmod", None)
    graph = _case(3).graph
    for name in ("cholesky", "auto"):
        got = solve(graph, linear_solver=name, tolerance=TIGHT)
        assert got.costs.tolist() == want.costs.tolist(), name
    with pytest.raises(ImportError, match=r"jaxlie_geo\[cholmod\]"):
        solve(graph, linear_solver="cholmod")


def test_auto_is_pcg_only_without_a_direct_solver(monkeypatch: pytest.MonkeyPatch) -> None:
    """``"auto"`` is the factorisation whenever cvxopt or qdldl imports, also where JAX's
    default device is a GPU (the linearisation stays there, the factorisation runs on the
    host), and PCG, step for step, only when neither package does."""
    gpu = type("Device", (), {"platform": "gpu", "device_kind": "a GPU"})()
    with monkeypatch.context() as patch:
        patch.setattr(jax, "devices", lambda *backend: [gpu])
        got = solve(_case(3).graph, tolerance=TIGHT)
    factorised = _solved(3, linear_solver="cholesky", tolerance=TIGHT)
    assert got.costs.tolist() == factorised.costs.tolist()
    want = _solved(3, linear_solver="pcg", tolerance=TIGHT)
    for module in ("cvxopt", "cvxopt.cholmod", "qdldl"):
        monkeypatch.setitem(sys.modules, module, None)
    got = solve(_case(3).graph, tolerance=TIGHT)
    assert got.costs.tolist() == want.costs.tolist()


@over_dims
def test_solution_record(dim: int) -> None:
    """The record: costs never increase, one per accepted step and one before, the first
    the NumPy cost of the initial estimate; times never decrease; it converged; the
    returned graph is the input with the optimised poses (the input untouched), and its
    cost is the last one. With ``max_iterations=1`` it stops after the same first step,
    not converged."""
    graph = _case(dim).graph
    poses_before = graph.poses.copy()
    s = _solved(dim)
    assert isinstance(s.stop_reason, str) and s.stop_reason
    assert s.converged is True
    assert isinstance(s.iterations, int) and s.iterations >= 1
    assert s.iterations == len(s.costs) - 1 == len(s.times) - 1
    assert np.all(np.diff(s.costs) <= 0), s.costs
    assert s.costs[-1] < s.costs[0]
    assert np.all(np.diff(s.times) >= 0) and s.times[0] >= 0, s.times
    assert s.time >= s.times[-1]
    np.testing.assert_allclose(s.costs[0], _cost_reference(graph), rtol=1e-12)
    # The graph: everything but the poses is the input's; the poses are the solution's.
    assert s.graph.dim == graph.dim
    for field in ("ids", "edges", "measurements", "information"):
        np.testing.assert_array_equal(getattr(s.graph, field), getattr(graph, field))
    np.testing.assert_array_equal(graph.poses, poses_before)
    assert s.graph.poses.dtype == np.float64 and s.graph.poses.shape == graph.poses.shape
    np.testing.assert_allclose(_matrix(dim, s.graph.poses), _matrices(s), rtol=0, atol=1e-14)
    assert not np.allclose(s.graph.poses, graph.poses)
    np.testing.assert_allclose(graph_cost(s.graph), s.costs[-1], rtol=1e-12)
    np.testing.assert_allclose(_cost_reference(s.graph), s.costs[-1], rtol=1e-12)
    # Stopped by the iteration limit: not converged, and the same first step.
    one = solve(graph, max_iterations=1)
    assert one.iterations == 1 and one.converged is False
    assert "max_iterations" in one.stop_reason
    np.testing.assert_array_equal(one.costs, s.costs[:2])


@over_dims
def test_solution_moves_with_a_left_transformation(dim: int) -> None:
    """The cost is invariant under T ↦ S T and the anchor holds the first pose where it
    starts, so the solution of the graph with every initial pose left-multiplied by S is
    S times the solution."""
    graph = _case(dim).graph
    rng = np.random.default_rng(5)
    rotation_dim = 1 if dim == 2 else 3
    S = _exp(dim, np.concatenate([3.0 * rng.normal(size=dim), rng.normal(size=rotation_dim)]))
    moved = graph.with_poses(_row(dim, S @ _matrix(dim, graph.poses)))
    got = solve(moved)
    want = S @ _matrices(_solved(dim))
    assert got.converged, got.stop_reason
    np.testing.assert_allclose(got.costs[-1], _solved(dim).costs[-1], rtol=1e-10)
    np.testing.assert_allclose(_matrices(got), want, rtol=0, atol=1e-10)


# ---------------------------------------------------------------------------------------
# Robust kernels.


def _huber(k: float):
    return lambda s: np.where(np.sqrt(s) <= k, s, 2 * k * np.sqrt(s) - k * k)


def _cauchy(k: float):
    return lambda s: k * k * np.log1p(s / (k * k))


@pytest.mark.parametrize(
    ("kernel", "definition"),
    [
        (Huber(), _huber(1.345)),
        (Huber(0.5), _huber(0.5)),
        (Cauchy(), _cauchy(1.0)),
        (Cauchy(2.5), _cauchy(2.5)),
    ],
    ids=["huber-1.345", "huber-0.5", "cauchy-1", "cauchy-2.5"],
)
def test_kernel_rho_and_weight(kernel, definition) -> None:
    """ρ(s) is its definition on the squared whitened norm s = u² (Huber: s inside the
    threshold k, 2ku − k² beyond; Cauchy: k² log(1 + s/k²)), and the weight is ρ'(s), the
    central difference of ρ (away from Huber's kink at s = k², where ρ' is continuous)."""
    k = kernel.threshold
    s = np.concatenate([np.geomspace(1e-6, 0.9, 8), np.geomspace(1.1, 1e4, 8)]) * k * k
    with x64(True):
        rho, weight = (np.asarray(a) for a in kernel.rho_and_weight(jnp.asarray(s)))
        h = 1e-6 * s
        up, _ = kernel.rho_and_weight(jnp.asarray(s + h))
        down, _ = kernel.rho_and_weight(jnp.asarray(s - h))
        at_kink = [float(a) for a in kernel.rho_and_weight(jnp.asarray(k * k))]
    np.testing.assert_allclose(rho, definition(s), rtol=1e-14)
    np.testing.assert_allclose(weight, (np.asarray(up) - np.asarray(down)) / (2 * h), rtol=1e-7)
    np.testing.assert_allclose(weight, (definition(s + h) - definition(s - h)) / (2 * h), rtol=1e-7)
    assert np.all(weight > 0) and np.all(weight <= 1)
    kink_weight = 1.0 if isinstance(kernel, Huber) else 0.5
    np.testing.assert_allclose(at_kink, [definition(k * k), kink_weight], rtol=1e-15)


@over_dims
def test_robust_costs_are_their_definition(dim: int) -> None:
    """``graph_cost`` with a kernel is ½ Σ ρ(‖W r‖²) by the NumPy residuals and the
    kernels' definitions; with every whitened residual norm below Huber's threshold (the
    information scaled down) it is the least-squares cost."""
    graph = _outlier_graph(dim)
    for kernel, rho in [(Huber(), _huber(1.345)), (Cauchy(), _cauchy(1.0))]:
        np.testing.assert_allclose(
            graph_cost(graph, robust=kernel), _cost_reference(graph, rho), rtol=1e-12
        )
    plain = _case(dim).graph
    e = _Residuals(plain)(_matrix(dim, plain.poses))
    largest = float(np.max(np.linalg.norm(e, axis=-1)))
    assert largest > 1.345  # the threshold is active here ...
    c = (1.3 / largest) ** 2  # ... and not once the information is scaled by c
    scaled = dataclasses.replace(plain, information=c * plain.information)
    np.testing.assert_allclose(graph_cost(scaled, robust=Huber()), graph_cost(scaled), rtol=1e-14)
    np.testing.assert_allclose(graph_cost(scaled), c * graph_cost(plain), rtol=1e-14)
    assert graph_cost(plain, robust=Huber()) < graph_cost(plain)


@over_dims
def test_robust_kernels_resist_an_outlier(dim: int) -> None:
    """With one loop closure off by 5 m and 1 rad, Huber's and Cauchy's solutions stay
    much closer to the ground truth than the least-squares one (RMS position error below
    half of it), and within 2.5 times the least-squares error without the outlier."""
    case = _case(dim)
    graph = _outlier_graph(dim)

    def position_error(solution: pose_graph.Solution) -> float:
        assert solution.converged, solution.stop_reason
        d = _matrices(solution)[:, :dim, dim] - case.truth[:, :dim, dim]
        return float(np.sqrt(np.mean(np.sum(d * d, axis=-1))))

    plain = position_error(solve(graph))
    huber = position_error(solve(graph, robust=Huber()))
    cauchy = position_error(solve(graph, robust=Cauchy()))
    clean = position_error(_solved(dim))
    assert max(huber, cauchy) < 0.5 * plain, (plain, huber, cauchy)
    assert max(huber, cauchy) < 2.5 * clean, (clean, huber, cauchy)


# ---------------------------------------------------------------------------------------
# GTSAM (optional: not a test dependency).


def _gtsam_graph(gtsam, graph: PoseGraph):
    """The graph's edges as GTSAM between factors with the information reordered to GTSAM's
    tangent, and a constructor of GTSAM poses from vertex-layout rows."""
    if graph.dim == 2:
        pose, between, order = lambda r: gtsam.Pose2(*r), gtsam.BetweenFactorPose2, slice(None)
    else:

        def pose(r):
            return gtsam.Pose3(gtsam.Rot3.Quaternion(r[6], r[3], r[4], r[5]), gtsam.Point3(*r[:3]))

        between, order = gtsam.BetweenFactorPose3, np.array(OMEGA_V)
    factors = gtsam.NonlinearFactorGraph()
    for (i, j), z, info in zip(graph.edges, graph.measurements, graph.information):
        noise = gtsam.noiseModel.Gaussian.Information(info[order][:, order])
        factors.add(between(int(i), int(j), pose(z), noise))
    return factors, pose


def _gtsam_values(gtsam, pose, rows: np.ndarray):
    values = gtsam.Values()
    for n, r in enumerate(rows):
        values.insert(n, pose(r))
    return values


@over_dims
def test_cost_and_optimum_against_gtsam(dim: int) -> None:
    """GTSAM's ``graph.error`` of the same between factors equals ``graph_cost`` at random
    poses (1e-12 relative); GTSAM's Levenberg–Marquardt, with a prior of the same σ on the
    first pose, ends at a cost no lower than ours (1e-6 relative) and at the same poses
    (1e-6, against our solution at a tight tolerance)."""
    gtsam = pytest.importorskip("gtsam")
    graph = _case(dim).graph
    factors, pose = _gtsam_graph(gtsam, graph)
    rng = np.random.default_rng(11)
    for scale in (0.05, 0.5):
        xi = scale * rng.normal(size=(graph.num_poses, GROUP[dim].tangent_dim))
        rows = _row(dim, _matrix(dim, graph.poses) @ _exp(dim, xi))
        np.testing.assert_allclose(
            graph_cost(graph.with_poses(rows)),
            factors.error(_gtsam_values(gtsam, pose, rows)),
            rtol=1e-12,
        )
    prior = gtsam.PriorFactorPose2 if dim == 2 else gtsam.PriorFactorPose3
    k = GROUP[dim].tangent_dim
    factors.add(prior(0, pose(graph.poses[0]), gtsam.noiseModel.Isotropic.Sigma(k, 1e-6)))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    params.setMaxIterations(100)
    optimizer = gtsam.LevenbergMarquardtOptimizer(
        factors, _gtsam_values(gtsam, pose, graph.poses), params
    )
    result = optimizer.optimize()
    theirs = factors.error(result)
    ours = _solved(dim)
    assert theirs * (1 - 1e-9) <= ours.costs[-1] <= theirs * (1 + 1e-6), (ours.costs[-1], theirs)
    at = result.atPose2 if dim == 2 else result.atPose3
    gtsam_poses = np.array([at(n).matrix() for n in range(graph.num_poses)])
    tight = _solved(dim, tolerance=TIGHT)
    np.testing.assert_allclose(_matrices(tight), gtsam_poses, rtol=0, atol=1e-6)


# ---------------------------------------------------------------------------------------
# Errors and progress.


def test_errors() -> None:
    """Out-of-range arguments and a graph with an information matrix that is not positive
    definite raise ``ValueError`` naming the culprit; so do kernels with a threshold that
    is not a positive number."""
    graph = _case(2).graph
    bad = [
        ("method", dict(method="newton")),
        ("linear_solver", dict(linear_solver="qr")),
        ("anchor_sigma", dict(anchor_sigma=0.0)),
        ("anchor_sigma", dict(anchor_sigma=-1.0)),
        ("anchor_sigma", dict(anchor_sigma=float("inf"))),
        ("tolerance", dict(tolerance=0.0)),
        ("tolerance", dict(tolerance=-1e-9)),
        ("initial_damping", dict(initial_damping=0.0)),
        ("max_iterations", dict(max_iterations=-1)),
    ]
    for match, options in bad:
        with pytest.raises(ValueError, match=match):
            solve(graph, **options)
    information = graph.information.copy()
    information[7] = np.diag([1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="edge 7 .*not positive definite"):
        solve(dataclasses.replace(graph, information=information))
    information[7] = np.zeros((3, 3))
    with pytest.raises(ValueError, match="not positive definite"):
        solve(dataclasses.replace(graph, information=information))
    edges = graph.edges.copy()
    edges[:, 1] = np.where(edges[:, 1] == 5, 4, edges[:, 1])  # nothing reaches pose 5
    edges[:, 0] = np.where(edges[:, 0] == 5, 3, edges[:, 0])
    edges[edges[:, 0] == edges[:, 1], 1] = 6
    with pytest.raises(ValueError, match="pose 5 .*not joined"):
        solve(dataclasses.replace(graph, edges=edges))
    for field, value, match in [
        ("information", np.triu(graph.information + 1.0), "edge 0 is not symmetric"),
        ("poses", np.where(np.arange(graph.num_poses)[:, None] == 2, np.inf, graph.poses),
         "poses: a non-finite value in row 2"),
        ("edges", graph.edges.astype(float), "edges: expected numbers"),
        ("measurements", graph.measurements[:-1], "measurements: expected shape"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match=match):
            dataclasses.replace(graph, **{field: value})
    as_lists = dataclasses.replace(graph, poses=graph.poses.astype(np.float32).tolist())
    assert as_lists.poses.dtype == np.float64 and as_lists.poses.shape == graph.poses.shape
    edges = graph.edges.copy()
    edges[3] = [4, 4]
    with pytest.raises(ValueError, match="itself"):
        solve(dataclasses.replace(graph, edges=edges))
    for kernel, threshold in [(Huber, 0), (Huber, -1.0), (Huber, float("nan")),
                              (Huber, float("inf")), (Cauchy, -1), (Cauchy, 0.0)]:  # fmt: skip
        with pytest.raises(ValueError, match="threshold"):
            kernel(threshold)


def test_damping_never_reaches_zero() -> None:
    """λ has a floor: from the smallest positive initial damping, and after more
    accepted steps than it takes to divide λ down to 0 in float64, Levenberg–Marquardt
    still ends at the optimum, with finite costs, instead of retrying a step at λ = 0."""
    reference = _solved(2, tolerance=TIGHT)
    solution = solve(_case(2).graph, initial_damping=5e-324, tolerance=TIGHT, max_iterations=400)
    assert np.all(np.isfinite(solution.costs))
    assert solution.converged, solution.stop_reason
    np.testing.assert_allclose(solution.costs[-1], reference.costs[-1], rtol=1e-9)


def test_progress_lines(capsys) -> None:
    """``progress=True`` writes one line per cost to stderr (stderr is not a terminal
    here) with the iteration, cost and step, then the stop reason; nothing otherwise."""
    solution = solve(_case(2).graph, progress=True)
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert lines[-1] == f"stopped: {solution.stop_reason}"
    body = lines[:-1]
    assert len(body) == solution.iterations + 1
    for n, (line, cost) in enumerate(zip(body, solution.costs)):
        for word in ("iteration", "cost", "step"):
            assert word in line, line
        assert f"iteration {n:4d}" in line, line
        assert f"cost {cost:.9e}" in line, line
    solve(_case(2).graph)
    assert capsys.readouterr().err == ""


# ---------------------------------------------------------------------------------------
# Sharded over four host devices, in a subprocess (the device count is fixed at start-up).

_SHARDED_SCRIPT = """
import json, sys
import jax
import numpy as np
from jaxlie_geo.pose_graph import PoseGraph, solve
from jaxlie_geo.pose_graph._solver import _problem
from jaxlie_geo._xla import x64

data = np.load(sys.argv[1])
names = ("ids", "poses", "edges", "measurements", "information")
graph = PoseGraph(3, *(data[name] for name in names))
devices = jax.devices()
with x64(True):
    p, _ = _problem(graph, 1e-6, devices)
out = {
    "devices": len(devices),
    "platform": devices[0].platform,
    "edge_devices": [len(a.sharding.device_set) for a in p[:4]],
    "padded_edges": int(p.edge_i.shape[0]),
    "padding_weight": float(np.abs(np.asarray(p.sqrt_information)[graph.num_edges:]).sum()),
    "dtype": str(p.measurements.dtype),
}
for name in ("pcg", "cholesky"):
    s = solve(graph, devices=devices, linear_solver=name, tolerance=float(sys.argv[2]))
    out[name] = {"costs": s.costs.tolist(), "poses": s.graph.poses.tolist(),
                 "converged": s.converged}
print(json.dumps(out))
"""


def test_sharded_over_four_host_devices(tmp_path: Path) -> None:
    """The SE3 graph solved with its edges sharded over four host devices, by conjugate
    gradients and by the Cholesky path, in a process with four CPU devices (the count is
    fixed when JAX starts): every edge array is split over the four devices (the 39 edges
    padded to 40 with an edge of zero weight), and both solutions (at a tight tolerance)
    have the costs (1e-9 relative) and poses (1e-7) of the one-device solve of the same
    graph in this process."""
    graph = _case(3).graph
    data = tmp_path / "graph.npz"
    names = ("ids", "poses", "edges", "measurements", "information")
    np.savez(data, **{name: getattr(graph, name) for name in names})
    script = tmp_path / "sharded.py"
    script.write_text(_SHARDED_SCRIPT)
    env = dict(os.environ)  # with the persistent compilation cache's settings
    env["XLA_FLAGS"] = (
        env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=4"
    ).strip()
    env["JAX_PLATFORMS"] = "cpu"
    run = subprocess.run(
        [sys.executable, str(script), str(data), repr(TIGHT)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert out["devices"] == 4 and out["platform"] == "cpu"
    assert out["edge_devices"] == [4, 4, 4, 4]
    assert out["padded_edges"] == 40 and out["padding_weight"] == 0.0
    assert out["dtype"] == "float64"
    here = _solved(3, tolerance=TIGHT)
    for name in ("pcg", "cholesky"):
        got = out[name]
        assert got["converged"], name
        np.testing.assert_allclose(got["costs"][0], here.costs[0], rtol=1e-12, err_msg=name)
        np.testing.assert_allclose(got["costs"][-1], here.costs[-1], rtol=1e-9, err_msg=name)
        np.testing.assert_allclose(
            _matrix(3, np.array(got["poses"])), _matrices(here), rtol=0, atol=1e-7, err_msg=name
        )
