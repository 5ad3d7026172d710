"""The size of each group's kernels after XLA's optimisation, and what they cost to compile.

Each operation of ``common.KERNEL_OPS`` (``program``) on a batch of 1,000 in float32 and
float64, compiled by ``jax.jit``: the instructions of the optimised HLO (the lines of
``compiled.as_text()`` that define a value, in every computation) and the compile seconds
from empty caches (the minimum of ``--repeats``). The counts depend on the jax version, not
on the machine; ``--record`` writes the running release's into ``tests/kernel_sizes.json``,
against which ``tests/test_kernel_sizes.py`` checks them.

Usage:
  python -m benchmarks.kernel_sizes [--save]
  python -m benchmarks.kernel_sizes --record          # rewrites tests/kernel_sizes.json
"""

from __future__ import annotations

import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxlie_geo
from benchmarks import common as C
from benchmarks.report import kernel_sizes_table, save
from jaxlie_geo._xla import x64

GROUPS, OPS, DTYPES, N = C.ALL_GROUPS, C.KERNEL_OPS, ("float32", "float64"), 1000
RECORD = C.REPO_ROOT / "tests" / "kernel_sizes.json"


def program(group: str, op: str, dtype: str):
    """(function, example arguments) of ``op`` on ``group`` for a batch of N."""
    G = getattr(jaxlie_geo, group)
    rng = np.random.default_rng([GROUPS.index(group), OPS.index(op)])
    x = jnp.asarray(0.8 * rng.normal(size=(N, G.tangent_dim)), dtype)
    if op == "grad":
        return jax.grad(lambda x: jnp.sum(G.exp(x).log() ** 2)), (x,)
    if op in ("jac_right", "jac_right_inv"):
        return getattr(G, op), (x,)
    if op == "exp":
        return (lambda x: G.exp(x).parameters()), (x,)
    if op == "from_matrix":
        return (lambda m: G.from_matrix(m).parameters()), (G.exp(x).as_matrix(),)
    return (lambda p: getattr(G(p), op)()), (G.exp(x).parameters(),)


def release(version: str) -> str:
    """The record's key of a jax version: its major and minor numbers ("0.10.2" → "0.10")."""
    return ".".join(version.split(".")[:2])


def count_instructions(hlo_text: str) -> int:
    """Instructions of an optimised HLO module: the lines that define a value."""
    lines = (line.strip() for line in hlo_text.splitlines())
    return sum(
        " = " in s and not s.startswith(("HloModule", "//")) and "{" not in s.split(" = ")[0]
        for s in lines
    )


def instructions(group: str, op: str, dtype: str) -> int:
    """The optimised instruction count of ``op`` (compiled without clearing any cache)."""
    with x64(dtype == "float64"):
        fn, args = program(group, op, dtype)
        return count_instructions(jax.jit(fn).lower(*args).compile().as_text())


def measure(group: str, op: str, dtype: str, repeats: int = 1) -> dict:
    """Instructions and compile seconds (min over ``repeats``, caches cleared each time)."""
    best = float("inf")
    with x64(dtype == "float64"):
        fn, args = program(group, op, dtype)
        for _ in range(repeats):
            jax.clear_caches()
            t0 = time.perf_counter()
            compiled = jax.jit(fn).lower(*args).compile()
            best = min(best, time.perf_counter() - t0)
    count = count_instructions(compiled.as_text())
    return {"group": group, "op": op, "dtype": dtype, "instructions": count, "compile_s": best}


def main(argv=None) -> int:
    p = C.parser(__doc__, groups=GROUPS, ops=OPS, dtypes=DTYPES)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--record", action="store_true", help=f"rewrite {RECORD.name}")
    args = C.parse(p, argv)
    rows = [
        measure(g, o, dt, args.repeats) for dt in args.dtypes for g in args.groups for o in args.ops
    ]
    if args.record:
        record = C.read_json(RECORD) if RECORD.exists() else {"batch": N, "instructions": {}}
        sizes = {f"{r['group']}.{r['op']}.{r['dtype']}": r["instructions"] for r in rows}
        record["instructions"].setdefault(release(jax.__version__), {}).update(sizes)
        C.write_json(RECORD, record)
        print(f"wrote {RECORD} (jax {release(jax.__version__)})")
    info = C.machine_info("benchmarks.kernel_sizes", batch=N, repeats=args.repeats)
    data = {"machine": info, "results": rows}
    print("\n".join(kernel_sizes_table(data)))
    save("kernel-sizes", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
