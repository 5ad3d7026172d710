"""The size of each group's kernels after XLA's optimisation, and what they cost to compile.

For each group and operation

  exp            G.exp(x).parameters()
  log            G.exp(x).log() with the element given: G(p).log()
  jac_right      G.jac_right(x)
  jac_right_inv  G.jac_right_inv(x)
  jlog           G(p).jlog()
  grad           x ↦ ∇ Σ ‖log(exp(x))‖²
  from_matrix    G.from_matrix(M).parameters()

on a batch of 1,000 in float32 and float64, the program ``jax.jit`` compiles is counted in
optimised HLO instructions (the lines of ``compiled.as_text()`` that define a value, in
every computation, fused ones included) and timed from empty caches (trace, lower and
compile; the minimum of ``--repeats``). The count is what XLA emits code for: compile time
and the size of a user's program grow with it. It depends on the jax/XLA version, not on the
machine's speed.

``tests/kernel_sizes.json`` records the counts per jax minor release (``--record`` adds or
replaces the running release's); ``tests/test_kernel_sizes.py`` fails when a kernel grows
or shrinks more than 20% from its record for the jax it runs on.

Usage:
  python -m benchmarks.kernel_sizes                   # prints the table
  python -m benchmarks.kernel_sizes --save            # raw/<machine>/kernel-sizes.json, page
  python -m benchmarks.kernel_sizes --record          # rewrites tests/kernel_sizes.json
"""

from __future__ import annotations

import argparse
import sys
import time

from benchmarks import common as C
from jaxlie_geo._xla import x64

GROUPS = ("SO2", "SE2", "SO3", "SE3", "Sim3", "SE23")
OPS = C.KERNEL_OPS
DTYPES = ("float32", "float64")
N = 1000
RECORD = C.REPO_ROOT / "tests" / "kernel_sizes.json"


def program(group: str, op: str, dtype: str):
    """(function, example arguments) of ``op`` on ``group`` for a batch of N."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import jaxlie_geo

    G = getattr(jaxlie_geo, group)
    rng = np.random.default_rng([GROUPS.index(group), OPS.index(op)])
    x = jnp.asarray(0.8 * rng.normal(size=(N, G.tangent_dim)), dtype)
    if op == "exp":
        return (lambda x: G.exp(x).parameters()), (x,)
    if op in ("jac_right", "jac_right_inv"):
        return getattr(G, op), (x,)
    if op == "grad":
        return jax.grad(lambda x: jnp.sum(G.exp(x).log() ** 2)), (x,)
    T = G.exp(x)
    if op == "from_matrix":
        return (lambda m: G.from_matrix(m).parameters()), (T.as_matrix(),)
    method = {"log": lambda p: G(p).log(), "jlog": lambda p: G(p).jlog()}[op]
    return method, (T.parameters(),)


def release(version: str) -> str:
    """The record's key of a jax version: its major and minor numbers ("0.10.2" → "0.10");
    XLA's optimisations change between minor releases, rarely within one."""
    return ".".join(version.split(".")[:2])


def count_instructions(hlo_text: str) -> int:
    """Instructions of an optimised HLO module: the lines that define a value (``%x = ...``
    or ``x = ...``), in every computation."""
    n = 0
    for line in hlo_text.splitlines():
        s = line.strip()
        if " = " in s and not s.startswith(("HloModule", "//")) and "{" not in s.split(" = ")[0]:
            n += 1
    return n


def instructions(group: str, op: str, dtype: str) -> int:
    """The optimised instruction count of ``op`` (compiled without clearing any cache)."""
    import jax

    with x64(dtype == "float64"):
        fn, args = program(group, op, dtype)
        return count_instructions(jax.jit(fn).lower(*args).compile().as_text())


def measure(group: str, op: str, dtype: str, repeats: int = 1) -> dict:
    """Instructions and compile seconds (min over ``repeats``, caches cleared each time)."""
    import jax

    best, count = float("inf"), 0
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
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--groups", nargs="+", choices=GROUPS, default=list(GROUPS))
    p.add_argument("--ops", nargs="+", choices=OPS, default=list(OPS))
    p.add_argument("--dtypes", nargs="+", choices=DTYPES, default=list(DTYPES))
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--record", action="store_true", help=f"rewrite {RECORD.name}")
    C.add_save_arguments(p)
    args = p.parse_args(argv)
    import jax

    rows = []
    for dtype in args.dtypes:
        for group in args.groups:
            for op in args.ops:
                row = measure(group, op, dtype, args.repeats)
                rows.append(row)
                print(
                    f"{dtype:8s} {group:5s} {op:14s} {row['instructions']:7d} instructions"
                    f"  compile {row['compile_s'] * 1e3:8.0f} ms",
                    flush=True,
                )
    if args.record:
        sizes = {f"{r['group']}.{r['op']}.{r['dtype']}": r["instructions"] for r in rows}
        record = C.read_json(RECORD) if RECORD.exists() else {"batch": N, "instructions": {}}
        record["instructions"].setdefault(release(jax.__version__), {}).update(sizes)
        C.write_json(RECORD, record)
        print(f"wrote {RECORD} (jax {release(jax.__version__)})")
    from benchmarks.report import save

    info = C.machine_info("benchmarks.kernel_sizes", batch=N, repeats=args.repeats)
    save("kernel-sizes", {"machine": info, "results": rows}, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
