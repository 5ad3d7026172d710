"""Bundle adjustment: ``least_squares.solve`` with the points eliminated (``"schur"``) beside
GTSAM's Levenberg–Marquardt on ``GeneralSFMFactor<PinholeCamera<Cal3Bundler>>``, in one
process.

Problems: the dubrovnik BAL files in gtsam's data folder (``gtsam.findExampleDataFile``),
read by ``bundle.read_bal``, and ``bundle.synthetic`` (100 cameras, 10⁴ points, 10⁵
observations). GTSAM's graph is built from the same values (cameras turned to GTSAM's
z-forward camera-to-world pose, the image y axis negated), so both sides minimise the same
cost ½ Σ ρ(‖u − z‖²) with Huber's ρ (k = 2 pixels) from the same initial values; the script
checks that the two initial costs agree. No prior or gauge constraint on either side.

GTSAM runs ``LevenbergMarquardtOptimizer`` with its default parameters (relative and absolute
error tolerances 1e-5); its time is that of ``optimize()``, construction included. Ours runs
``solve(linear_solver="schur", tolerance=1e-5)``: once cold (tracing and compiling
included), then warm; the table shows each side's fastest warm run. Final costs are each
side's own evaluation of the same cost at its solution.

The implicit-gradient row: d/dz of Σ wᵢ·Xᵢ (the points of the solution, fixed random
weights) along a random direction of the observations, on a small synthetic problem (5
cameras, the first two held, 20 points seen by all, no robust kernel, float64), against the
central difference with step 10⁻³ pixels.

Raw file ``bundle-adjustment.json``: ``{"machine": {...}, "rows": [{"problem", "cameras",
"points", "observations", "robust": [kind, k], "initial_cost", "ours_cost", "gtsam_cost",
"ours_iterations", "gtsam_iterations", "ours_cold_s", "ours_s", "ours_runs_s": [...],
"gtsam_s", "gtsam_runs_s": [...]}], "implicit_gradient": {"problem", "step", "implicit",
"central_difference", "relative_error"}}``.

Usage:
  python -m benchmarks.bundle_adjustment            # print the table
  python -m benchmarks.bundle_adjustment --save     # and write this machine's raw file
  python -m benchmarks.bundle_adjustment --quick    # a 20-camera synthetic problem
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks import common as C

ROBUST = ("huber", 2.0)
DUBROVNIK = ("dubrovnik-3-7-pre.txt", "dubrovnik-3-7-18-pre.txt")
REPEATS = 3


def gtsam_problem(gtsam, problem, robust):
    """GTSAM's graph and values for the same cost as ``bundle.factor(problem, robust)``."""
    R = np.asarray(problem.cameras.rotation().as_matrix())
    t = np.asarray(problem.cameras.translation())
    K, X = np.asarray(problem.intrinsics), np.asarray(problem.points)
    values, graph = gtsam.Values(), gtsam.NonlinearFactorGraph()
    for i in range(len(K)):
        pose = gtsam.Pose3(gtsam.Rot3(R[i].T @ np.diag([1.0, -1.0, -1.0])), -R[i].T @ t[i])
        calibration = gtsam.Cal3Bundler(K[i, 0], K[i, 1], K[i, 2], 0.0, 0.0)
        values.insert(gtsam.symbol("c", i), gtsam.PinholeCameraCal3Bundler(pose, calibration))
    for j in range(len(X)):
        values.insert(gtsam.symbol("p", j), X[j])
    noise = gtsam.noiseModel.Isotropic.Sigma(2, 1.0)
    if robust is not None:
        huber = gtsam.noiseModel.mEstimator.Huber.Create(robust[1])
        noise = gtsam.noiseModel.Robust.Create(huber, noise)
    z = np.asarray(problem.observations) * [1.0, -1.0]
    cams, pts = np.asarray(problem.camera_index), np.asarray(problem.point_index)
    for o, (i, j) in enumerate(zip(cams, pts)):
        key_c, key_p = gtsam.symbol("c", int(i)), gtsam.symbol("p", int(j))
        graph.add(gtsam.GeneralSFMFactorCal3Bundler(z[o], noise, key_c, key_p))
    return graph, values


def measure(name, problem) -> dict:
    import gtsam
    import jax

    from jaxlie_geo import bundle, least_squares

    factors = (bundle.factor(problem, ROBUST),)
    graph, values = gtsam_problem(gtsam, problem, ROBUST)
    initial = float(least_squares.cost(factors, problem.variables))
    assert abs(graph.error(values) - initial) <= 1e-9 * initial, (graph.error(values), initial)

    def ours():
        t = time.perf_counter()
        sol = least_squares.solve(factors, problem.variables, linear_solver="schur", tolerance=1e-5)
        jax.block_until_ready(sol)
        return time.perf_counter() - t, sol

    def theirs():
        t = time.perf_counter()
        opt = gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams())
        result = opt.optimize()
        return time.perf_counter() - t, (graph.error(result), opt.iterations())

    cold, _ = ours()
    ours_runs, gtsam_runs = [], []
    for _ in range(REPEATS):
        s, sol = ours()
        ours_runs.append(s)
        s, (gtsam_cost, gtsam_iterations) = theirs()
        gtsam_runs.append(s)
    return {
        "problem": name,
        "cameras": int(problem.intrinsics.shape[0]),
        "points": int(problem.points.shape[0]),
        "observations": int(problem.observations.shape[0]),
        "robust": list(ROBUST),
        "initial_cost": initial,
        "ours_cost": float(sol.cost),
        "gtsam_cost": float(gtsam_cost),
        "ours_iterations": int(sol.iterations),
        "gtsam_iterations": int(gtsam_iterations),
        "ours_cold_s": cold,
        "ours_s": min(ours_runs),
        "ours_runs_s": ours_runs,
        "gtsam_s": min(gtsam_runs),
        "gtsam_runs_s": gtsam_runs,
    }


def implicit_gradient() -> dict:
    import dataclasses

    import jax
    import jax.numpy as jnp

    from jaxlie_geo import bundle, least_squares

    initial, _ = bundle.synthetic(5, 20, 5, key=3)
    fixed = (jnp.arange(5) < 2, None, None)
    weights = jnp.asarray(np.random.default_rng(0).normal(size=(20, 3)))
    direction = jnp.asarray(np.random.default_rng(1).normal(size=initial.observations.shape))

    @jax.jit
    def loss(z):
        problem = dataclasses.replace(initial, observations=z)
        sol = least_squares.solve(
            (bundle.factor(problem),), problem.variables, fixed=fixed,
            linear_solver="dense", tolerance=1e-15, max_iterations=200,
        )  # fmt: skip
        return jnp.sum(weights * sol.variables[2])

    z, step = initial.observations, 1e-3
    implicit = float(jnp.sum(jax.grad(loss)(z) * direction))
    central = float((loss(z + step * direction) - loss(z - step * direction)) / (2 * step))
    return {
        "problem": "synthetic, 5 cameras (2 held), 20 points, 100 observations",
        "step": step,
        "implicit": implicit,
        "central_difference": central,
        "relative_error": abs(implicit - central) / abs(central),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a 20-camera synthetic problem")
    C.add_save_arguments(parser)
    args = parser.parse_args()
    import gtsam
    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxlie_geo import bundle

    rows = [measure(f, bundle.read_bal(gtsam.findExampleDataFile(f))) for f in DUBROVNIK]
    size = (20, 1000, 5) if args.quick else (100, 10_000, 10)
    initial, _ = bundle.synthetic(*size)
    rows.append(measure(f"synthetic {size[0]} × {size[1]} × {size[2]}", initial))
    data = {
        "machine": C.machine_info(
            "benchmarks.bundle_adjustment", dtype="float64", gtsam=C.version_of("gtsam")
        ),
        "rows": rows,
        "implicit_gradient": implicit_gradient(),
    }
    print(f"{'problem':34} {'ours s':>8} {'GTSAM s':>8} {'ours cost':>14} {'GTSAM cost':>14}")
    for r in rows:
        print(
            f"{r['problem']:34} {r['ours_s']:8.3f} {r['gtsam_s']:8.3f} "
            f"{r['ours_cost']:14.8g} {r['gtsam_cost']:14.8g}"
        )
    g = data["implicit_gradient"]
    print(f"implicit gradient vs central difference: relative error {g['relative_error']:.2e}")
    from benchmarks.report import save

    save("bundle-adjustment", data, args)


if __name__ == "__main__":
    main()
