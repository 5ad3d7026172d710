"""``least_squares.solve`` on batches of small problems, beside GTSAM and optimistix, and its
implicit derivative against central differences of the solution.

Two batches, float64, each of B independent problems of one structure:

- **pose fits**: each problem fits one SE(3) pose T to K point correspondences, residuals
  (T p_i − q_i)/σ, q_i = T_true p_i + N(0, σ² I), σ = 0.01, from T_true ⊕ N(0, 0.3² I₆);
  the closed-form minimiser is Kabsch's (``SE3.align``), the reference every solution is
  checked against;
- **pose graphs**: copies of one SE(3) pose graph (a loop of P poses, odometry between
  neighbours and loop closures every 4 poses, isotropic σ = 0.1, a prior on the first pose),
  each with its own measurement noise and its own perturbed initial estimate.

Solvers:

- **ours**: ``jax.jit(jax.vmap(least_squares.solve))`` over the B problems, one call, the
  factors with their closed-form Jacobians (``Factor.jacobian``, ``jaxlie_geo.jacobians``);
- **GTSAM**: ``LevenbergMarquardtOptimizer`` (default parameters) on each problem in a
  Python loop, the factor graphs built beforehand (building is not timed); the pose fit's
  factor is ``KnownLandmarkFactorPose3``, whose residual T⁻¹ q − p has the same norm as ours;
- **optimistix** (pose fits): ``optimistix.least_squares`` with ``LevenbergMarquardt`` on the
  Euclidean parameterisation δ ↦ r(x₀ ⊕ δ), δ ∈ R⁶ (x₀ the initial estimate), vmapped.

Reported per problem: run time (median of 5 calls), compile time, the largest ratio of our
final cost to the peer's (both evaluated by our cost function), and for the pose fits the
largest distance of each solver's pose from Kabsch's (rotation angle, translation).

Derivatives: of a scalar s of the solution with respect to the measurements, the implicit
one (``jax.grad``) against central differences of the solution along random directions d,
Richardson-extrapolated, D = (4 D(h/2) − D(h))/3 with D(h) = (s(θ + hd) − s(θ − hd))/2h and
h = 10⁻³ (error O(h⁴) from the differences, the solves converged to rounding); the largest
relative error |∇s·d − D|/|D| over the directions (for measured poses, d's quaternion part
orthogonal to the quaternion: the closed-form Jacobians hold on the group, and a step off it
changes what a solve converges to), on one problem of each kind: a pose fit
(s = ‖t‖², ours and optimistix's implicit adjoint), a pose graph (s = ‖t_last‖²) and a
cubic B-spline fit on SE(3) (s = ‖t(τ)‖² of the spline at a time τ).

Usage:
  python -m benchmarks.least_squares             # B = 1000, K = 8 points, P = 12 poses
  python -m benchmarks.least_squares --save      # raw/<machine>/least-squares.json, page
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import common as C

jax.config.update("jax_enable_x64", True)

import jaxlie_geo as jl  # noqa: E402
from jaxlie_geo import jacobians  # noqa: E402
from jaxlie_geo import least_squares as ls  # noqa: E402
from jaxlie_geo.splines import Spline, SplineTime  # noqa: E402

POINT_SIGMA = 0.01
SIGMA = 0.1
FD_STEP = 1e-3
TIGHT = 1e-14  # the tolerance of the solves whose derivatives are checked


def timed(fn, *args, runs: int = 5) -> float:
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def compiled(fn, *args):
    """``jax.jit(fn)`` compiled for ``args``, and the seconds that took."""
    t = time.perf_counter()
    out = jax.jit(fn).lower(*args).compile()
    return out, time.perf_counter() - t


def fd_error(s, theta, grad, seed: int, directions: int = 3, poses: bool = False) -> float:
    """The largest relative error of ``grad`` (∇s at θ) along random directions, against
    Richardson-extrapolated central differences of ``s``. With ``poses``, θ holds SE(3)
    parameters (wxyz_xyz) and each direction's quaternion part is made orthogonal to the
    quaternion, so that θ ± hd stays on the group to first order (the central difference
    cancels the second)."""
    rng = np.random.default_rng(seed)
    s = jax.jit(s)
    worst = 0.0
    for _ in range(directions):
        d = rng.standard_normal(theta.shape)
        if poses:
            q = np.asarray(theta[..., :4])
            d[..., :4] -= np.sum(d[..., :4] * q, axis=-1, keepdims=True) * q
        d = jnp.asarray(d)

        def central(h, d=d):
            return (float(s(theta + h * d)) - float(s(theta - h * d))) / (2 * h)

        fd = (4 * central(FD_STEP / 2) - central(FD_STEP)) / 3
        worst = max(worst, abs(float(jnp.sum(grad * d)) - fd) / abs(fd))
    return worst


# -- pose fits ---------------------------------------------------------------------------


def pose_fits(B: int, K: int, seed: int):
    """Per problem the body points p ``(B, K, 3)``, their measured images q, the true pose
    and the initial estimate (SE3, batch (B,))."""
    rng = np.random.default_rng(seed)
    truth = jl.SE3.exp(jnp.asarray(rng.standard_normal((B, 6))))
    p = jnp.asarray(rng.standard_normal((B, K, 3)))
    q = truth[:, None] @ p + POINT_SIGMA * jnp.asarray(rng.standard_normal((B, K, 3)))
    init = truth @ jl.SE3.exp(jnp.asarray(0.3 * rng.standard_normal((B, 6))))
    return p, q, truth, init


def point(T, pq):
    p, q = pq
    return (T @ p - q) / POINT_SIGMA


def point_jacobian(T, pq):
    p, q = pq
    J_T, _ = jacobians.apply(T, p)
    return (T @ p - q) / POINT_SIGMA, J_T / POINT_SIGMA


def fit_factors(p, q):
    zeros = jnp.zeros(p.shape[0], jnp.int32)
    return [ls.Factor(point, (0,), (zeros,), (p, q), jacobian=point_jacobian)]


def fit_one(p, q, x0, tolerance=1e-10):
    return ls.solve(fit_factors(p, q), (jl.SE3(x0)[None],), tolerance=tolerance)


def fit_euclidean(delta, args):
    p, q, x0 = args
    return jax.vmap(point, (None, 0))(jl.SE3(x0) @ jl.SE3.exp(delta), (p, q)).ravel()


def fit_optimistix(p, q, x0, tolerance=1e-10):
    import optimistix as optx

    solver = optx.LevenbergMarquardt(rtol=tolerance, atol=tolerance)
    sol = optx.least_squares(
        fit_euclidean, solver, jnp.zeros(6, x0.dtype), (p, q, x0), max_steps=200, throw=False
    )
    return jl.SE3(x0) @ jl.SE3.exp(sol.value)


def pose_distance(A, B) -> tuple:
    """The largest rotation angle and translation distance between two batches of poses."""
    E = A.inverse() @ B
    return (
        float(jnp.max(jnp.linalg.norm(E.rotation().log(), axis=-1))),
        float(jnp.max(jnp.linalg.norm(A.translation() - B.translation(), axis=-1))),
    )


def gtsam_fits(p, q, init) -> tuple:
    import gtsam

    noise = gtsam.noiseModel.Isotropic.Sigma(3, POINT_SIGMA)
    P, Q, X = np.asarray(p), np.asarray(q), np.asarray(init.as_matrix())
    problems = []
    for k in range(P.shape[0]):
        g = gtsam.NonlinearFactorGraph()
        for i in range(P.shape[1]):
            g.add(gtsam.KnownLandmarkFactorPose3(0, Q[k, i], P[k, i], noise))
        v = gtsam.Values()
        v.insert(0, gtsam.Pose3(X[k]))
        problems.append((g, v))
    t = time.perf_counter()
    results = [gtsam.LevenbergMarquardtOptimizer(g, v).optimize() for g, v in problems]
    elapsed = time.perf_counter() - t
    return elapsed, np.stack([r.atPose3(0).matrix() for r in results])


def run_pose_fits(B: int, K: int, seed: int) -> dict:
    p, q, truth, init = pose_fits(B, K, seed)
    x0 = init.parameters()
    kabsch = jl.SE3.align(p, q)
    cost_of = jax.jit(jax.vmap(lambda p, q, x: ls.cost(fit_factors(p, q), (jl.SE3(x)[None],))))

    ours_fn, compile_ours = compiled(jax.vmap(fit_one), p, q, x0)
    run_ours = timed(ours_fn, p, q, x0)
    ours = ours_fn(p, q, x0)
    ours_x = jl.SE3(ours.variables[0].parameters()[:, 0])
    costs_ours = np.asarray(cost_of(p, q, ours_x.parameters()))

    run_gt, gt_matrices = gtsam_fits(p, q, init)
    gt_x = jl.SE3.from_matrix(jnp.asarray(gt_matrices))
    costs_gt = np.asarray(cost_of(p, q, gt_x.parameters()))

    optx_fn, compile_optx = compiled(jax.vmap(fit_optimistix), p, q, x0)
    run_optx = timed(optx_fn, p, q, x0)
    optx_x = optx_fn(p, q, x0)
    costs_optx = np.asarray(cost_of(p, q, optx_x.parameters()))

    # s(q) = |t|² of problem 0's fitted pose.
    p0, q0, x00 = p[0], q[0], x0[0]

    def s_ours(q):
        return jnp.sum(fit_one(p0, q, x00, TIGHT).variables[0].translation() ** 2)

    def s_optx(q):
        return jnp.sum(fit_optimistix(p0, q, x00, 1e-13).translation() ** 2)

    g_ours = jax.jit(jax.grad(s_ours))(q0)
    g_optx = jax.jit(jax.grad(s_optx))(q0)
    return {
        "problem": "pose fits",
        "problems": B,
        "points": K,
        "run_ours_s": run_ours,
        "run_gtsam_s": run_gt,
        "run_optimistix_s": run_optx,
        "compile_ours_s": compile_ours,
        "compile_optimistix_s": compile_optx,
        "cost_ratio_gtsam_max": float(np.max(costs_ours / costs_gt)),
        "cost_ratio_optimistix_max": float(np.max(costs_ours / costs_optx)),
        "kabsch_ours": pose_distance(ours_x, kabsch),
        "kabsch_gtsam": pose_distance(gt_x, kabsch),
        "kabsch_optimistix": pose_distance(optx_x, kabsch),
        "iterations_max": int(np.max(np.asarray(ours.iterations))),
        "converged": int(np.sum(np.asarray(ours.converged))),
        "gradient_rel_error_max": fd_error(s_ours, q0, g_ours, seed=1),
        "optimistix_gradient_rel_error_max": fd_error(s_ours, q0, g_optx, seed=1),
    }


# -- pose graphs -------------------------------------------------------------------------


def graph(P: int, B: int, seed: int):
    """Edges, and per copy the measurements and initial estimates (SE3, batch (B, E))."""
    rng = np.random.default_rng(seed)
    a = np.concatenate([np.arange(P), np.arange(0, P - 4, 4)])
    b = np.concatenate([(np.arange(P) + 1) % P, np.arange(4, P, 4)])
    angles = 2 * np.pi * np.arange(P) / P
    tangent = np.zeros((P, 6))
    tangent[:, 0], tangent[:, 1], tangent[:, 5] = 5 * np.cos(angles), 5 * np.sin(angles), angles
    truth = jl.SE3.exp(jnp.asarray(tangent))
    noise = jl.SE3.exp(jnp.asarray(0.05 * rng.standard_normal((B, len(a), 6))))
    meas = (truth[a].inverse() @ truth[b])[None] @ noise
    init = truth[None] @ jl.SE3.exp(jnp.asarray(0.2 * rng.standard_normal((B, P, 6))))
    return a, b, truth, meas, init


def between(A, Bp, Z):
    return (Z.inverse() @ (A.inverse() @ Bp)).log() / SIGMA


def between_jacobian(A, Bp, Z):
    error = Z.inverse() @ (A.inverse() @ Bp)
    J = jacobians.log(error) @ jnp.concatenate(jacobians.between(A, Bp), axis=-1)
    return error.log() / SIGMA, J / SIGMA


def prior(A, Z):
    return (Z.inverse() @ A).log() / 1e-3


def prior_jacobian(A, Z):
    error = Z.inverse() @ A
    return error.log() / 1e-3, jacobians.log(error) / 1e-3


def factors(a, b, meas, anchor):
    return [
        ls.Factor(between, (0, 0), (a, b), meas, jacobian=between_jacobian),
        ls.Factor(prior, (0,), (np.array([0]),), anchor, jacobian=prior_jacobian),
    ]


def run_gtsam(a, b, meas, init, anchor) -> tuple[float, list]:
    import gtsam

    noise = gtsam.noiseModel.Isotropic.Sigma(6, SIGMA)
    prior_noise = gtsam.noiseModel.Isotropic.Sigma(6, 1e-3)
    M, X, A0 = (np.asarray(t.as_matrix()) for t in (meas, init, anchor))
    problems = []
    for k in range(M.shape[0]):
        g = gtsam.NonlinearFactorGraph()
        g.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(A0[0]), prior_noise))
        for e in range(len(a)):
            g.add(gtsam.BetweenFactorPose3(int(a[e]), int(b[e]), gtsam.Pose3(M[k, e]), noise))
        v = gtsam.Values()
        for i in range(X.shape[1]):
            v.insert(i, gtsam.Pose3(X[k, i]))
        problems.append((g, v))
    t = time.perf_counter()
    results = [gtsam.LevenbergMarquardtOptimizer(g, v).optimize() for g, v in problems]
    elapsed = time.perf_counter() - t
    poses = [np.stack([r.atPose3(i).matrix() for i in range(X.shape[1])]) for r in results]
    return elapsed, poses


def run_pose_graphs(B: int, P: int, seed: int) -> dict:
    a, b, truth, meas, init = graph(P, B, seed)
    anchor = truth[np.array([0])]

    def one(m, x0, tolerance=1e-10):
        return ls.solve(factors(a, b, jl.SE3(m), anchor), (jl.SE3(x0),), tolerance=tolerance)

    M, X = meas.parameters(), init.parameters()
    ours_fn, compile_ours = compiled(jax.vmap(one), M, X)
    run_ours = timed(ours_fn, M, X)
    ours = ours_fn(M, X)
    cost_of = jax.jit(
        jax.vmap(lambda m, x: ls.cost(factors(a, b, jl.SE3(m), anchor), (jl.SE3(x),)))
    )
    costs_ours = np.asarray(cost_of(M, ours.variables[0].parameters()))
    run_gt, gt_poses = run_gtsam(a, b, meas, init, anchor)
    gt_params = jl.SE3.from_matrix(jnp.asarray(np.stack(gt_poses))).parameters()
    costs_gt = np.asarray(cost_of(M, gt_params))

    # s(m) = |t_last|² of the solution of copy 0.
    def s(m):
        return jnp.sum(one(m, X[0], TIGHT).variables[0].translation()[P - 1] ** 2)

    grad = jax.jit(jax.grad(s))(M[0])
    return {
        "problem": "pose graphs",
        "problems": B,
        "poses": P,
        "edges": len(a),
        "run_ours_s": run_ours,
        "run_gtsam_s": run_gt,
        "compile_ours_s": compile_ours,
        "cost_ratio_gtsam_max": float(np.max(costs_ours / costs_gt)),
        "iterations_max": int(np.max(np.asarray(ours.iterations))),
        "converged": int(np.sum(np.asarray(ours.converged))),
        "gradient_rel_error_max": fd_error(s, M[0], grad, seed=2, poses=True),
    }


# -- a spline fit ------------------------------------------------------------------------


def _segment(points, u):
    spline = Spline(jl.SE3(jnp.stack([c.parameters() for c in points])), degree=3, t0=0, dt=1)
    return spline, SplineTime(jnp.zeros((), jnp.int32), u)


def spline_sample(c0, c1, c2, c3, data):
    """log(Z⁻¹ T(u)) / σ of a sample at fraction u of the segment that c0 … c3 shape."""
    u, Z = data
    spline, where = _segment((c0, c1, c2, c3), u)
    return (Z.inverse() @ spline.evaluate(where, derivatives=0).value).log() / SIGMA


def spline_sample_jacobian(c0, c1, c2, c3, data):
    """The residual and J_r⁻¹(r) times the spline's control-point Jacobians."""
    u, Z = data
    spline, where = _segment((c0, c1, c2, c3), u)
    r = (Z.inverse() @ spline.evaluate(where, derivatives=0).value).log()
    J = jl.SE3.jac_right_inv(r) @ spline.jacobians(where).value  # (4, 6, 6)
    return r / SIGMA, jnp.concatenate(list(J), axis=-1) / SIGMA


def run_spline_fit(n: int = 10, per_segment: int = 6, seed: int = 3) -> dict:
    """A cubic SE(3) spline of n control points fitted to noisy samples of a smooth
    trajectory, solved by ``least_squares.solve``; s = |t(τ)|² at τ inside the fit."""
    rng = np.random.default_rng(seed)
    segments = n - 3
    t = (np.arange(segments * per_segment) + 0.5) / per_segment
    xi = np.stack([np.sin(0.4 * t), np.cos(0.3 * t), 0.2 * t, t, np.sin(0.5 * t), 0.1 * t], -1)
    noisy = jl.SE3.exp(jnp.asarray(xi + 0.02 * rng.standard_normal(xi.shape)))
    seg = np.floor(t).astype(np.int32)
    u = jnp.asarray(t - seg)
    # Control point i is centred at time i − 1; it starts at the sample nearest to it.
    nearest = np.minimum(np.searchsorted(t, np.arange(n) - 1.0), len(t) - 1)
    initial = noisy[jnp.asarray(nearest)]

    def fit(Z_parameters):
        factor = ls.Factor(
            spline_sample, (0, 0, 0, 0), tuple(jnp.asarray(seg + m) for m in range(4)),
            (u, jl.SE3(Z_parameters)),
        )  # fmt: skip
        return ls.solve([factor], (initial,), tolerance=TIGHT)

    tau = 0.5 * segments

    def s(Z_parameters):
        spline = Spline(fit(Z_parameters).variables[0], degree=3, t0=0, dt=1)
        return jnp.sum(spline.evaluate(jnp.asarray(tau), derivatives=0).value.translation() ** 2)

    theta = noisy.parameters()
    grad = jax.jit(jax.grad(s))(theta)
    return {
        "problem": "spline fit",
        "control_points": n,
        "samples": len(t),
        "converged": bool(jax.jit(fit)(theta).converged),
        "gradient_rel_error_max": fd_error(s, theta, grad, seed=4, poses=True),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=int, default=1000)
    p.add_argument("--points", type=int, default=8)
    p.add_argument("--poses", type=int, default=12)
    p.add_argument("--seed", type=int, default=0)
    C.add_save_arguments(p)
    args = p.parse_args(argv)
    results = [
        run_pose_fits(args.problems, args.points, args.seed),
        run_pose_graphs(args.problems, args.poses, args.seed),
        run_spline_fit(),
    ]
    for r in results:
        print(f"{r['problem']}:")
        for k, v in r.items():
            print(f"  {k:36s} {v}")
        if "run_gtsam_s" in r:
            B, ours, gt = r["problems"], r["run_ours_s"], r["run_gtsam_s"]
            print(
                f"  per problem: ours {C.fmt_ns(ours / B * 1e9)}, GTSAM {C.fmt_ns(gt / B * 1e9)} "
                f"({gt / ours:.1f}x)"
            )
    from benchmarks.report import save

    info = C.machine_info(
        "benchmarks.least_squares",
        dtype="float64",
        gtsam=C.version_of("gtsam"),
        optimistix=C.version_of("optimistix"),
    )
    save("least-squares", {"machine": info, "results": results}, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
