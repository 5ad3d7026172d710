"""Matrix-valued operations and derivatives of every group, against jaxlie and against the
cost of writing their output.

For each group (SO2, SE2, SO3, SE3, Sim3, SE23) and operation

  jac_right      G.jac_right(x)                      (N, k, k)
  jac_right_inv  G.jac_right_inv(x)                  (N, k, k)
  jlog           G(p).jlog()                         (N, k, k)
  adjoint        G(p).adjoint()                      (N, k, k)
  grad           x ↦ ∇ ‖log(exp(x)⁻¹ b)‖²            (N, k)
  from_matrix    G.from_matrix(M).parameters()       (N, P)
  from_matrix_project  G.from_matrix(M, project=True).parameters()   (N, P)

at N = 10³ and 10⁶, in float32 and float64, three jit-compiled functions are timed on the
same inputs: jaxlie_geo's, jaxlie 1.5's where it has the operation (SO2, SE2, SO3, SE3; it
has no ``jac_right``, ``jac_right_inv`` or projection), and the *write floor*: an array of the
output's shape and dtype filled from one entry of the input per element, the least any
implementation can cost. Tangents x are standard normal times 0.8 (rotation angles up to
about π); elements p = exp(x); b = exp of another such tangent; M is the matrix of an
element with Gaussian noise of 10⁻³ added to its rotation (or scaled rotation) block.

Time per element: the median of 5 rounds, each function calibrated to about 0.2 s per
measurement, the three run in turn within a round. Compile time: trace, lower and compile.

Usage:
  python -m benchmarks.matrix_ops                       # prints the table
  python -m benchmarks.matrix_ops --save                # raw/<machine>/matrix-ops.json, page
  python -m benchmarks.matrix_ops --groups SE3 Sim3 --ops jlog --sizes 1000
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxlie_geo
from benchmarks import common as C
from benchmarks import run as speed
from benchmarks.common import fmt_n, fmt_ns
from benchmarks.report import save
from jaxlie_geo._xla import x64

GROUPS = ("SO2", "SE2", "SO3", "SE3", "Sim3", "SE23")
OPS = C.MATRIX_OPS
JAXLIE_GROUPS = ("SO2", "SE2", "SO3", "SE3")
JAXLIE_OPS = ("jlog", "adjoint", "grad", "from_matrix")
ROUNDS = 5
TARGET_S = 0.2


def make_op(lib, group: str, op: str):
    """f(*inputs) for ``op`` of ``lib.<group>``."""
    G = getattr(lib, group)
    if op == "jac_right":
        return G.jac_right
    if op == "jac_right_inv":
        return G.jac_right_inv
    if op == "jlog":
        return lambda p: G(p).jlog()
    if op == "adjoint":
        return lambda p: G(p).adjoint()
    if op == "from_matrix":
        return lambda m: G.from_matrix(m).parameters()
    if op == "from_matrix_project":
        return lambda m: G.from_matrix(m, project=True).parameters()
    return speed.make_op(lib, group, "grad", native=True)


def make_inputs(group: str, op: str, n: int, dtype, seed: int) -> tuple:
    """The inputs of ``op``, identical for both libraries."""
    G = getattr(jaxlie_geo, group)
    rng = np.random.default_rng([seed, GROUPS.index(group), OPS.index(op), n])
    tangent = lambda: jnp.asarray(0.8 * rng.normal(size=(n, G.tangent_dim)), dtype)  # noqa: E731
    params = jax.jit(lambda x: G.exp(x).parameters())
    if op in ("jac_right", "jac_right_inv"):
        return (tangent(),)
    if op in ("jlog", "adjoint"):
        return (params(tangent()),)
    if op == "grad":
        return (tangent(), params(tangent()))
    m = np.array(jax.jit(lambda x: G.exp(x).as_matrix())(tangent()))
    d = 2 if group in ("SO2", "SE2") else 3
    m[:, :d, :d] += 1e-3 * rng.normal(size=(n, d, d))
    return (jnp.asarray(m, dtype),)


def write_floor(out: jax.ShapeDtypeStruct):
    """A function of the op's inputs that writes an array like its output from one entry
    of the first input per element."""

    def floor(first, *rest):
        one = first.reshape(first.shape[0], -1)[:, :1]
        one = one.reshape(one.shape + (1,) * (len(out.shape) - 2))
        return jnp.zeros(out.shape, out.dtype) + one.astype(out.dtype)

    return floor


def time_round_robin(fns: dict, args: tuple) -> dict:
    """Median seconds per call of each compiled function, measured in turn each round."""
    calls = {k: C.calibrate(f, args, TARGET_S) for k, f in fns.items()}
    times: dict = {k: [] for k in fns}
    for _ in range(ROUNDS):
        for k, f in fns.items():
            times[k].append(C.run_n(f, args, calls[k]))
    return {k: statistics.median(v) for k, v in times.items()}


def bench_case(group: str, op: str, n: int, dtype, seed: int) -> dict:
    args = make_inputs(group, op, n, dtype, seed)
    ours = make_op(jaxlie_geo, group, op)
    fns, compile_s = {}, {}
    fns["ours"], compile_s["ours"] = C.compile_fn(ours, args)
    out = jax.eval_shape(ours, *args)
    fns["floor"], _ = C.compile_fn(write_floor(out), args)
    if group in JAXLIE_GROUPS and op in JAXLIE_OPS:
        import jaxlie

        fns["jaxlie"], compile_s["jaxlie"] = C.compile_fn(make_op(jaxlie, group, op), args)
    seconds = time_round_robin(fns, args)
    ns = {k: v / n * 1e9 for k, v in seconds.items()}
    row = {
        "group": group,
        "op": op,
        "n": n,
        "dtype": np.dtype(dtype).name,
        "output_shape": list(out.shape[1:]),
        "ours_ns_per_elem": ns["ours"],
        "floor_ns_per_elem": ns["floor"],
        "jaxlie_ns_per_elem": ns.get("jaxlie"),
        "compile_ours_ms": compile_s["ours"] * 1e3,
        "compile_jaxlie_ms": compile_s["jaxlie"] * 1e3 if "jaxlie" in compile_s else None,
    }
    jl = row["jaxlie_ns_per_elem"]
    print(
        f"{row['dtype']:8s} {group:5s} {op:14s} N={fmt_n(n):>5s}  ours {fmt_ns(ns['ours']):>9s}  "
        f"jaxlie {fmt_ns(jl) if jl else '–':>9s}  floor {fmt_ns(ns['floor']):>9s}  "
        f"×floor {ns['ours'] / ns['floor']:6.1f}  compile {row['compile_ours_ms']:.0f} ms",
        flush=True,
    )
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--groups", nargs="+", choices=GROUPS, default=list(GROUPS))
    parser.add_argument("--ops", nargs="+", choices=OPS, default=list(OPS))
    parser.add_argument("--sizes", nargs="+", type=int, default=[1000, 1_000_000])
    parser.add_argument("--dtypes", nargs="+", default=["float32", "float64"])
    parser.add_argument("--seed", type=int, default=0)
    C.add_save_arguments(parser)
    args = parser.parse_args(argv)
    start = time.perf_counter()
    rows = []
    for dtype in args.dtypes:
        with x64(dtype == "float64"):
            for group in args.groups:
                for op in args.ops:
                    for n in args.sizes:
                        rows.append(bench_case(group, op, n, jnp.dtype(dtype), args.seed))
    info = C.machine_info(
        "benchmarks.matrix_ops", dtype="float32, float64", jaxlie=C.version_of("jaxlie")
    )
    elapsed = time.perf_counter() - start
    print(f"total benchmark time: {elapsed:.0f} s")
    save("matrix-ops", {"machine": info, "results": rows, "elapsed_s": elapsed}, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
