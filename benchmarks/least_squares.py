"""``least_squares.solve`` on a batch of small pose graphs, beside GTSAM and optimistix.

The problem: B copies of one SE(3) pose graph (a loop of P poses, odometry between
neighbours and loop closures every 4 poses, isotropic σ = 0.1, a prior on the first pose),
each copy with its own measurement noise and its own perturbed initial estimate, float64.

- **ours**: ``jax.jit(jax.vmap(least_squares.solve))`` over the B copies, one call;
- **GTSAM**: ``LevenbergMarquardtOptimizer`` (default parameters) on each copy in a Python
  loop, the factor graphs built beforehand (building is not timed);
- **optimistix**: ``optimistix.least_squares`` with ``LevenbergMarquardt`` on a Euclidean
  parameterisation of the same cost, δ ↦ r(x₀ ⊕ δ), δ ∈ R^{6P} (x₀ the initial estimate),
  vmapped over the copies.

Reported per problem: run time (median of 5 calls), compile time (ours, optimistix), the
final costs (each evaluated by our cost function), and the implicit derivative of a scalar
of our solution (the squared norm of the last pose's translation) with respect to the
measurements against central differences of the solution (step 1e-6, two random
directions), and optimistix's derivative (its implicit adjoint) of the same scalar.

Usage:
  python -m benchmarks.least_squares             # B = 1000, P = 12
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
from jaxlie_geo import least_squares as ls  # noqa: E402

SIGMA = 0.1


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


def prior(A, Z):
    return (Z.inverse() @ A).log() / 1e-3


def factors(a, b, meas, anchor):
    return [
        ls.Factor(between, (0, 0), (a, b), meas),
        ls.Factor(prior, (0,), (np.array([0]),), anchor),
    ]


def timed(fn, *args, runs: int = 5) -> float:
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t)
    return statistics.median(times)


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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=int, default=1000)
    p.add_argument("--poses", type=int, default=12)
    p.add_argument("--seed", type=int, default=0)
    C.add_save_arguments(p)
    args = p.parse_args(argv)
    B, P = args.problems, args.poses
    a, b, truth, meas, init = graph(P, B, args.seed)
    anchor = truth[np.array([0])]

    def one(m, x0):
        return ls.solve(factors(a, b, jl.SE3(m), anchor), (jl.SE3(x0),), tolerance=1e-10)

    batched = jax.jit(jax.vmap(one))
    t = time.perf_counter()
    compiled = batched.lower(meas.parameters(), init.parameters()).compile()
    compile_ours = time.perf_counter() - t
    run_ours = timed(compiled, meas.parameters(), init.parameters())
    ours = compiled(meas.parameters(), init.parameters())
    cost_of = jax.jit(
        jax.vmap(lambda m, x: ls.cost(factors(a, b, jl.SE3(m), anchor), (jl.SE3(x),)))
    )
    costs_ours = np.asarray(cost_of(meas.parameters(), ours.variables[0].parameters()))

    run_gt, gt_poses = run_gtsam(a, b, meas, init, anchor)
    gt_params = jl.SE3.from_matrix(jnp.asarray(np.stack(gt_poses))).parameters()
    costs_gt = np.asarray(cost_of(meas.parameters(), gt_params))

    import optimistix as optx

    def euclidean(delta, m_x0):
        m, x0 = m_x0
        x = jl.SE3(x0) @ jl.SE3.exp(delta.reshape(P, 6))
        edges = jax.vmap(between)(x[a], x[b], jl.SE3(m))
        return jnp.concatenate([edges.ravel(), prior(x[0], anchor[0])])

    solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)

    def optx_one(m, x0):
        sol = optx.least_squares(
            euclidean, solver, jnp.zeros(6 * P), args=(m, x0), max_steps=200, throw=False
        )
        return jl.SE3(x0) @ jl.SE3.exp(sol.value.reshape(P, 6))

    optx_batched = jax.jit(jax.vmap(optx_one))
    t = time.perf_counter()
    optx_compiled = optx_batched.lower(meas.parameters(), init.parameters()).compile()
    compile_optx = time.perf_counter() - t
    run_optx = timed(optx_compiled, meas.parameters(), init.parameters())
    costs_optx = np.asarray(
        cost_of(meas.parameters(), optx_compiled(meas.parameters(), init.parameters()).parameters())
    )

    # Derivatives of s(m) = |t_last|² of the solution of copy 0.
    m0, x00 = meas.parameters()[0], init.parameters()[0]

    def s_ours(m):
        return jnp.sum(one(m, x00).variables[0].translation()[P - 1] ** 2)

    def s_optx(m):
        return jnp.sum(optx_one(m, x00).translation()[P - 1] ** 2)

    g_ours = jax.jit(jax.grad(s_ours))(m0)
    g_optx = jax.jit(jax.grad(s_optx))(m0)
    s_jit = jax.jit(s_ours)
    rng = np.random.default_rng(1)
    errors, optx_errors = [], []
    for _ in range(2):
        d = jnp.asarray(rng.standard_normal(m0.shape))
        fd = (s_jit(m0 + 1e-6 * d) - s_jit(m0 - 1e-6 * d)) / 2e-6
        errors.append(abs(float(jnp.sum(g_ours * d) - fd)) / abs(float(fd)))
        optx_errors.append(abs(float(jnp.sum(g_optx * d) - fd)) / abs(float(fd)))

    result = {
        "problems": B,
        "poses": P,
        "edges": len(a),
        "run_ours_s": run_ours,
        "run_gtsam_s": run_gt,
        "run_optimistix_s": run_optx,
        "compile_ours_s": compile_ours,
        "compile_optimistix_s": compile_optx,
        "cost_ratio_gtsam_max": float(np.max(costs_ours / costs_gt)),
        "cost_ratio_optimistix_max": float(np.max(costs_ours / costs_optx)),
        "gradient_rel_error_max": max(errors),
        "optimistix_gradient_rel_error_max": max(optx_errors),
        "converged": int(np.sum(np.asarray(ours.converged))),
    }
    for k, v in result.items():
        print(f"{k:36s} {v}")
    print(
        f"per problem: ours {C.fmt_ns(run_ours / B * 1e9)}, GTSAM {C.fmt_ns(run_gt / B * 1e9)} "
        f"({run_gt / run_ours:.1f}x), optimistix {C.fmt_ns(run_optx / B * 1e9)}"
    )
    from benchmarks.report import save

    info = C.machine_info(
        "benchmarks.least_squares",
        dtype="float64",
        gtsam=C.version_of("gtsam"),
        optimistix=C.version_of("optimistix"),
    )
    save("least-squares", {"machine": info, "results": [result]}, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
