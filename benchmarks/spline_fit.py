"""Spline fits: ``jaxlie_geo.splines.fit`` with a dense and with sparse factorisations.

A cubic SE(3) spline with n control points (knot spacing Δt = 0.1) is fitted to 10 noisy
poses per knot interval, N = 10 (n − 3) samples: a smooth ground-truth trajectory
T(t) = exp(ξ(t)) with ξ(t) = (0.3 sin 0.2t, 0.2 cos 0.13t, 0.5, cos 0.1t, sin 0.1t, 0.1),
each sample right-multiplied by exp(ε), ε ~ N(0, 0.01² I₆). Every fit starts from the
default initial spline and runs ``splines.fit``'s Levenberg–Marquardt loop (float64,
tolerance 1e-10) with one linear solver:

  dense    LAPACK Cholesky of the full (6n × 6n) normal matrix (``linear_solver="dense"``)
  banded   LAPACK banded Cholesky of the same matrix (its band holds 6 (degree + 1) − 1
           off-diagonals; ``"banded"``)
  cholmod  CHOLMOD's supernodal sparse Cholesky through cvxopt (``"cholmod"``), where
           installed
  qdldl    QDLDL's sparse LDLᵀ (``"qdldl"``)

Each case runs in its own Python process, so its peak resident memory (``VmHWM``) is that
case's alone; the table shows it and its increase over the process's peak before the first
fit (JAX, the data and the initial spline). Times: the first call (tracing and compiling
included) and the second, warm call, on the same data. The dense solver is not run where
its matrix alone would take more than half the machine's available memory; the table says
how much it would need. Every solver must reach the same final cost, to 1e-9 relative, at
each size.

Usage:
  python -m benchmarks.spline_fit                         # print the table
  python -m benchmarks.spline_fit --save                  # and replace this machine's file
  python -m benchmarks.spline_fit --sizes 100 1000 --solvers banded qdldl
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from benchmarks import common as C
from benchmarks.report import save

SIZES = (100, 1000, 10000)
SOLVERS = ("dense", "banded", "cholmod", "qdldl")
SAMPLES_PER_KNOT = 10
DT = 0.1
DEGREE = 3
DIM = 6


def _proc_kib(field: str) -> int:
    """A ``/proc/self/status`` field in KiB (Linux); 0 where it is not available."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def available_bytes() -> int:
    return C.available_bytes() or 0


def dense_bytes(n: int) -> int:
    """The dense normal matrix alone, float64."""
    return (DIM * n) ** 2 * 8


def one_case(n: int, solver: str) -> dict:
    """Fit once cold and once warm in this process; the record of the warm fit."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from jaxlie_geo import SE3, splines

    samples = SAMPLES_PER_KNOT * (n - DEGREE)
    t = np.arange(samples) * (DT / SAMPLES_PER_KNOT)
    xi = np.stack(
        [
            0.3 * np.sin(0.2 * t),
            0.2 * np.cos(0.13 * t),
            np.full_like(t, 0.5),
            np.cos(0.1 * t),
            np.sin(0.1 * t),
            np.full_like(t, 0.1),
        ],
        -1,
    )
    noise = np.random.default_rng(0).normal(scale=0.01, size=(samples, DIM))
    poses = SE3.exp(jnp.asarray(xi)) @ SE3.exp(jnp.asarray(noise))
    jax.block_until_ready(poses)
    before = _proc_kib("VmHWM")

    def fit():
        start = time.perf_counter()
        result = splines.fit(t, poses, dt=DT, degree=DEGREE, linear_solver=solver, tolerance=1e-10)
        jax.block_until_ready(result.spline)
        return result, time.perf_counter() - start

    _, first = fit()
    result, warm = fit()
    peak = _proc_kib("VmHWM")
    return {
        "control_points": result.spline.control_points.get_batch_axes()[0],
        "samples": samples,
        "solver": solver,
        "first_s": first,
        "warm_s": warm,
        "iterations": int(result.iterations),
        "final_cost": float(result.costs[-1]),
        "stop_reason": str(result.stop_reason),
        "peak_gb": peak * 1024 / 1e9,
        "before_gb": before * 1024 / 1e9,
    }


def run_case(n: int, solver: str) -> dict:
    """``one_case`` in a fresh process, for its own peak memory."""
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.spline_fit", "--case", str(n), solver],
        cwd=C.REPO_ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    if out.returncode != 0:
        raise RuntimeError(f"{n} control points, {solver}: {out.stderr.strip()[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def default_solvers() -> list:
    from jaxlie_geo._sparse import installed

    return [s for s in SOLVERS if s not in ("cholmod", "qdldl") or installed(s)]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", nargs="+", type=int, default=list(SIZES))
    p.add_argument("--solvers", nargs="+", choices=SOLVERS, default=None)
    p.add_argument("--case", nargs=2, metavar=("N", "SOLVER"), help=argparse.SUPPRESS)
    C.add_save_arguments(p)
    args = p.parse_args(argv)
    if args.case:
        print(json.dumps(one_case(int(args.case[0]), args.case[1])))
        return 0
    solvers = args.solvers or default_solvers()
    # The machine and the tree as the run starts (an edit during the run is not measured).
    info = C.machine_info(
        "benchmarks.spline_fit",
        dtype="float64",
        scipy=C.version_of("scipy"),
        qdldl=C.version_of("qdldl"),
        cvxopt=C.version_of("cvxopt"),
        memory_available_gb=available_bytes() / 1e9,
    )
    start = time.perf_counter()
    rows = []
    for n in args.sizes:
        costs = []
        for solver in solvers:
            if solver == "dense" and dense_bytes(n) > available_bytes() / 2:
                row = {"control_points": n, "solver": solver, "skipped_gb": dense_bytes(n) / 1e9}
                print(f"{n:>6} {solver:>8}  not run: its matrix needs {row['skipped_gb']:.1f} GB")
            else:
                row = run_case(n, solver)
                costs.append(row["final_cost"])
                print(
                    f"{n:>6} {solver:>8}  first {row['first_s']:7.2f} s  warm "
                    f"{row['warm_s']:7.2f} s  it {row['iterations']:>2}  cost "
                    f"{row['final_cost']:.10e}  peak {row['peak_gb']:.2f} GB "
                    f"(+{row['peak_gb'] - row['before_gb']:.2f})"
                )
            rows.append(row)
        if costs and (max(costs) - min(costs)) > 1e-9 * max(costs):
            raise SystemExit(f"{n} control points: the solvers disagree on the cost: {costs}")
    elapsed = time.perf_counter() - start
    print(f"total benchmark time: {elapsed:.0f} s")
    save("spline-fit", {"machine": info, "results": rows, "elapsed_s": elapsed}, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
