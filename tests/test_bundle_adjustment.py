"""``jaxlie_geo.bundle`` and ``least_squares``' Schur solver: the BAL reader against GTSAM's
(counts), the residual against a NumPy evaluation of the BAL model and against GTSAM's
``PinholeCamera<Cal3Bundler>`` projection, the closed-form Jacobian against autodiff, the
Schur step against the dense one, the optimum of a dubrovnik file against GTSAM's
Levenberg–Marquardt on ``GeneralSFMFactor``, and the implicit derivative against central
differences of the solution. Float64 (the suite's default)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from benchmarks.bundle_adjustment import gtsam_problem
from jaxlie_geo import SE3, bundle
from jaxlie_geo import least_squares as ls

gtsam = pytest.importorskip("gtsam")
DUBROVNIK = "dubrovnik-3-7-pre.txt"
HUBER = ("huber", 2.0)


def _gtsam_problem(problem: bundle.Problem, robust):
    """GTSAM's graph and values for the same cost (the benchmark's conversion: cameras turned
    to GTSAM's z-forward, camera-to-world pose, the image y axis negated)."""
    return gtsam_problem(gtsam, problem, robust)


def test_reader_counts_match_gtsam() -> None:
    path = gtsam.findExampleDataFile(DUBROVNIK)
    problem = bundle.read_bal(path)
    sfm = gtsam.SfmData.FromBalFile(path)
    assert problem.cameras.get_batch_axes() == (sfm.numberCameras(),)
    assert problem.points.shape == (sfm.numberTracks(), 3)
    n = sum(sfm.track(j).numberMeasurements() for j in range(sfm.numberTracks()))
    assert problem.observations.shape == (n, 2) == problem.camera_index.shape + (2,)


def test_residual_against_numpy_and_gtsam() -> None:
    path = gtsam.findExampleDataFile(DUBROVNIK)
    problem = bundle.read_bal(path)
    with open(path) as stream:
        rows = np.asarray(stream.read().split()[3 + 4 * len(problem.observations) :], float)
    camera = rows[:27].reshape(3, 9)
    o = 5
    i, j = int(problem.camera_index[o]), int(problem.point_index[o])
    # BAL's model by hand: P = R X + t, p = −P/P_z, u = f (1 + k₁‖p‖² + k₂‖p‖⁴) p.
    P = Rotation.from_rotvec(camera[i, :3]).as_matrix() @ rows[27 + 3 * j : 30 + 3 * j]
    P = P + camera[i, 3:6]
    p = -P[:2] / P[2]
    s = p @ p
    u = camera[i, 6] * (1 + camera[i, 7] * s + camera[i, 8] * s * s) * p
    r = bundle.reprojection_residual(
        problem.cameras[i], problem.intrinsics[i], problem.points[j], problem.observations[o]
    )
    np.testing.assert_allclose(r, u - np.asarray(problem.observations[o]), rtol=1e-12)
    sfm = gtsam.SfmData.FromBalFile(path)
    ours = bundle.project(problem.cameras[i], problem.intrinsics[i], problem.points[j])
    theirs = sfm.camera(i).project(sfm.track(j).point3())
    np.testing.assert_allclose(np.asarray(ours) * [1.0, -1.0], theirs, rtol=1e-10)


def test_closed_form_jacobian_is_autodiffs() -> None:
    problem = bundle.read_bal(gtsam.findExampleDataFile(DUBROVNIK))
    c, k, x = problem.cameras[problem.camera_index], problem.intrinsics, problem.points
    args = (c, k[problem.camera_index], x[problem.point_index], problem.observations)

    def tangent(T, K, X, z):
        def at(d):
            return bundle.reprojection_residual(T @ SE3.exp(d[:6]), K + d[6:9], X + d[9:], z)

        return at(jnp.zeros(12)), jax.jacfwd(at)(jnp.zeros(12))

    (r0, J0), (r1, J1) = jax.jit(
        lambda a: (jax.vmap(bundle.reprojection_jacobian)(*a), jax.vmap(tangent)(*a))
    )(args)
    np.testing.assert_allclose(r0, r1, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(J0, J1, rtol=1e-9, atol=1e-9 * float(jnp.abs(J1).max()))


def test_schur_steps_equal_dense_steps() -> None:
    initial, _ = bundle.synthetic(6, 30, 3)
    factors = (bundle.factor(initial, HUBER),)
    fixed = (jnp.arange(6) == 0, None, jnp.arange(30) == 4)
    out = [
        ls.solve(factors, initial.variables, fixed=fixed, max_iterations=2, linear_solver=s)
        for s in ("dense", "schur")
    ]
    for a, b in zip(jax.tree.leaves(out[0].variables), jax.tree.leaves(out[1].variables)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-10)
    # The two factorisations round differently: steps agree to about 1e-12 relative, and
    # the cost after two iterations (not yet at the optimum, so first order in the step) to
    # the same order (1.4e-12 seen on AMD EPYC); 1e-10 leaves room and still fails on any
    # wrong step.
    np.testing.assert_allclose(out[0].cost, out[1].cost, rtol=1e-10)


def _gtsam_optimum(graph, values) -> float:
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(0.0)
    params.setMaxIterations(1000)
    return graph.error(gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize())


def test_optimum_equals_gtsams() -> None:
    """The dubrovnik files have more unknowns than residuals (3 cameras × 9 + 7 points × 3
    against 2 × 19) and a minimum of 0, which GTSAM's optimiser approaches more slowly (it
    stops near 0.018 pixels²): ours must reach at least its optimum. A small synthetic
    problem, determined, has one optimum both must reach within 10⁻⁶ relative."""
    problem = bundle.read_bal(gtsam.findExampleDataFile(DUBROVNIK))
    synthetic, _ = bundle.synthetic(8, 60, 4, key=1)
    for p, determined in ((problem, False), (synthetic, True)):
        graph, values = _gtsam_problem(p, HUBER)
        factors = (bundle.factor(p, HUBER),)
        np.testing.assert_allclose(graph.error(values), ls.cost(factors, p.variables), rtol=1e-12)
        theirs = _gtsam_optimum(graph, values)
        ours = ls.solve(
            factors, p.variables, linear_solver="schur", tolerance=1e-14, max_iterations=1000
        )
        assert bool(ours.converged)
        assert float(ours.cost) <= theirs * (1 + 1e-6)
        assert theirs <= float(ours.cost) * (1 + 1e-6) or not determined


def test_implicit_gradient_equals_central_differences() -> None:
    initial, _ = bundle.synthetic(5, 20, 5, key=3)
    fixed = (jnp.arange(5) < 2, None, None)  # two cameras held: no gauge freedom
    weights = jnp.asarray(np.random.default_rng(0).normal(size=(20, 3)))
    direction = jnp.asarray(np.random.default_rng(1).normal(size=initial.observations.shape))

    @jax.jit
    def loss(observations):
        problem = bundle.Problem(
            initial.cameras, initial.intrinsics, initial.points,
            initial.camera_index, initial.point_index, observations,
        )  # fmt: skip
        sol = ls.solve(
            (bundle.factor(problem),), problem.variables, fixed=fixed,
            linear_solver="dense", tolerance=1e-15, max_iterations=200,
        )  # fmt: skip
        return jnp.sum(weights * sol.variables[2])

    grad = jax.jit(jax.grad(loss))(initial.observations)
    eps = 1e-3
    central = (
        loss(initial.observations + eps * direction) - loss(initial.observations - eps * direction)
    ) / (2 * eps)
    np.testing.assert_allclose(jnp.sum(grad * direction), central, rtol=1e-6)
