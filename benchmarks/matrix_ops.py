"""Every group's matrix-valued operations and derivatives, beside jaxlie 1.5 and beside the
cost of writing their output.

For each group and operation of ``common.MATRIX_OPS`` at N = 10³ and 10⁶, in float32 and
float64: jaxlie_geo's function, jaxlie's where it has the operation, and the *write floor*
(an array of the output's shape and dtype filled from one input entry per element), timed
in 5 rounds in which they run in turn (``common.measure``). Tangents are standard normal
times 0.8; elements their exp; a matrix input is an element's with 10⁻³ Gaussian noise on
its rotation block. The method is on the results page (``methods.md``: matrix-ops).

Usage:
  python -m benchmarks.matrix_ops [--save]
  python -m benchmarks.matrix_ops --groups SE3,Sim3 --ops jlog --sizes 1000
"""

from __future__ import annotations

import statistics
import sys

import jax
import jax.numpy as jnp
import jaxlie
import numpy as np

import jaxlie_geo
from benchmarks import common as C
from benchmarks import run
from benchmarks.report import matrix_ops_table, save
from jaxlie_geo._xla import x64

JAXLIE_OPS = ("jlog", "adjoint", "grad", "from_matrix")


def make_op(lib, group: str, op: str):
    """f(*inputs) of ``op`` on ``lib.<group>``."""
    G = getattr(lib, group)
    if op == "grad":
        return run.make_op(lib, group, "grad")
    return {
        "jac_right": lambda x: G.jac_right(x),
        "jac_right_inv": lambda x: G.jac_right_inv(x),
        "jlog": lambda p: G(p).jlog(),
        "adjoint": lambda p: G(p).adjoint(),
        "from_matrix": lambda m: G.from_matrix(m).parameters(),
        "from_matrix_project": lambda m: G.from_matrix(m, project=True).parameters(),
    }[op]


def make_inputs(group: str, op: str, n: int, dtype, seed: int) -> tuple:
    G = getattr(jaxlie_geo, group)
    rng = np.random.default_rng([seed, C.ALL_GROUPS.index(group), C.MATRIX_OPS.index(op), n])
    tangent = lambda: jnp.asarray(0.8 * rng.normal(size=(n, G.tangent_dim)), dtype)
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
    """An array like ``out`` written from one entry of the first input per element."""

    def floor(first, *rest):
        one = first.reshape(first.shape[0], -1)[:, :1]
        return jnp.zeros(out.shape, out.dtype) + one.reshape(one.shape + (1,) * (out.ndim - 2))

    return floor


def bench_case(group: str, op: str, n: int, dtype, seed: int) -> dict:
    args = make_inputs(group, op, n, dtype, seed)
    ours = make_op(jaxlie_geo, group, op)
    out = jax.eval_shape(ours, *args)
    fns = {"ours": ours, "floor": write_floor(out)}
    if group in C.GROUPS and op in JAXLIE_OPS:
        fns["jaxlie"] = make_op(jaxlie, group, op)
    compiled = {k: C.compile_fn(f, args) for k, f in fns.items()}
    sides = [(c, args, C.timed_call(c, args)[1]) for c, _ in compiled.values()]
    times = C.measure(sides, 5, 0.2)
    ns = {k: statistics.median(t) / n * 1e9 for k, t in zip(fns, times)}
    return {
        "group": group,
        "op": op,
        "n": n,
        "dtype": np.dtype(dtype).name,
        "output_shape": list(out.shape[1:]),
        "ours_ns_per_elem": ns["ours"],
        "floor_ns_per_elem": ns["floor"],
        "jaxlie_ns_per_elem": ns.get("jaxlie"),
        "compile_ours_ms": compiled["ours"][1] * 1e3,
        "compile_jaxlie_ms": compiled["jaxlie"][1] * 1e3 if "jaxlie" in compiled else None,
    }


def main(argv=None) -> int:
    p = C.parser(__doc__, groups=C.ALL_GROUPS, ops=C.MATRIX_OPS, dtypes=("float32", "float64"))
    p.add_argument("--sizes", default="1000,1000000", help="batch sizes (default %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    args = C.parse(p, argv)
    rows = []
    for dtype in args.dtypes:
        with x64(dtype == "float64"):
            for group in args.groups:
                for op in args.ops:
                    for n in map(int, args.sizes.split(",")):
                        rows.append(bench_case(group, op, n, jnp.dtype(dtype), args.seed))
                        print(
                            dtype, group, op, n, C.fmt_ns(rows[-1]["ours_ns_per_elem"]), flush=True
                        )
    info = C.machine_info("benchmarks.matrix_ops", dtype="float32, float64")
    data = {"machine": info, "results": rows}
    print("\n".join(matrix_ops_table(data)))
    save("matrix-ops", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
