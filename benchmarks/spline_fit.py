"""Spline fits: ``jaxlie_geo.splines.fit`` with a dense, a banded and sparse factorisations.

A cubic SE(3) spline of n control points (Δt = 0.1) fitted to 10 noisy poses per knot
interval of the trajectory exp(ξ(t)), ξ(t) = (0.3 sin 0.2t, 0.2 cos 0.13t, 0.5, cos 0.1t,
sin 0.1t, 0.1), each right-multiplied by exp(ε), ε ~ N(0, 0.01² I₆); float64, tolerance
1e-10, one ``linear_solver`` per row (dense, banded, and CHOLMOD and QDLDL where installed).
Each case runs in its own process, so that its peak resident memory (``VmHWM``) is its own;
every solver must reach the same final cost to 1e-9 relative. The method is on the results
page (``methods.md``: spline-fit).

Usage:
  python -m benchmarks.spline_fit [--save]
  python -m benchmarks.spline_fit --sizes 100,1000 --solvers banded,qdldl
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import jax

from benchmarks import common as C
from benchmarks.report import save, spline_fit_table

SOLVERS, PER_KNOT, DT, DEGREE = ("dense", "banded", "cholmod", "qdldl"), 10, 0.1, 3


def _peak_gb() -> float:
    """The process's peak resident set (``VmHWM``, Linux), 0 where there is none."""
    try:
        text = Path("/proc/self/status").read_text()
        return (
            next(int(x.split()[1]) for x in text.splitlines() if x.startswith("VmHWM:"))
            / 1e6
            * 1.024
        )
    except (OSError, StopIteration):
        return 0.0


def one_case(n: int, solver: str) -> dict:
    """Fit once cold and once warm in this process; the record of the warm fit."""
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from jaxlie_geo import SE3, splines

    samples = PER_KNOT * (n - DEGREE)
    t = np.arange(samples) * (DT / PER_KNOT)
    one = np.ones_like(t)
    xi = np.stack(
        [
            0.3 * np.sin(0.2 * t),
            0.2 * np.cos(0.13 * t),
            0.5 * one,
            np.cos(0.1 * t),
            np.sin(0.1 * t),
            0.1 * one,
        ],
        -1,
    )
    noise = np.random.default_rng(0).normal(scale=0.01, size=(samples, 6))
    poses = jax.block_until_ready(SE3.exp(jnp.asarray(xi)) @ SE3.exp(jnp.asarray(noise)))
    before = _peak_gb()

    def fit():
        result = splines.fit(t, poses, dt=DT, degree=DEGREE, linear_solver=solver, tolerance=1e-10)
        return jax.block_until_ready(result.spline) and result

    _, first = C.timed_call(fit, ())
    result, warm = C.timed_call(fit, ())
    return {
        "control_points": result.spline.control_points.get_batch_axes()[0],
        "samples": samples,
        "solver": solver,
        "first_s": first,
        "warm_s": warm,
        "iterations": int(result.iterations),
        "final_cost": float(result.costs[-1]),
        "stop_reason": str(result.stop_reason),
        "peak_gb": _peak_gb(),
        "before_gb": before,
    }


def main(argv=None) -> int:
    from jaxlie_geo._sparse import installed

    p = C.parser(__doc__, solvers=SOLVERS)
    p.add_argument("--sizes", default="100,1000,10000", help="control points (default %(default)s)")
    p.add_argument("--case", nargs=2, metavar=("N", "SOLVER"), help="one fit, in this process")
    args = C.parse(p, argv)
    if args.case:
        print(json.dumps(one_case(int(args.case[0]), args.case[1])))
        return 0
    solvers = [s for s in args.solvers if s not in ("cholmod", "qdldl") or installed(s)]
    available = C.available_bytes() or 0
    info = C.machine_info(
        "benchmarks.spline_fit",
        dtype="float64",
        scipy=C.version_of("scipy"),
        qdldl=C.version_of("qdldl"),
        cvxopt=C.version_of("cvxopt"),
        memory_available_gb=available / 1e9,
    )
    start, rows = time.perf_counter(), []
    for n in map(int, args.sizes.split(",")):
        costs = []
        for solver in solvers:
            dense_gb = (6 * n) ** 2 * 8 / 1e9  # the dense normal matrix alone
            if solver == "dense" and dense_gb > available / 2e9:
                rows.append({"control_points": n, "solver": solver, "skipped_gb": dense_gb})
                continue
            cmd = [sys.executable, "-m", "benchmarks.spline_fit", "--case", str(n), solver]
            out = subprocess.run(cmd, cwd=C.REPO_ROOT, capture_output=True, text=True)
            if out.returncode != 0:
                raise RuntimeError(f"{n} control points, {solver}: {out.stderr.strip()[-2000:]}")
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
            costs.append(rows[-1]["final_cost"])
        if costs and max(costs) - min(costs) > 1e-9 * max(costs):
            raise SystemExit(f"{n} control points: the solvers disagree on the cost: {costs}")
    data = {"machine": info, "results": rows, "elapsed_s": time.perf_counter() - start}
    print("\n".join(spline_fit_table(data)))
    save("spline-fit", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
