"""Compile time of whole programs: jaxlie_geo against jaxlie 1.5, in the same process.

``run.py`` times the compilation of one operation at a time. A user's jitted function
usually chains many, and there both libraries benefit from ``jax.jit``'s trace cache:
every public method is itself a ``jax.jit``, so each repeated call with the same shapes
adds one call to an already traced function. This script compiles the same program
for both libraries:

    chain_K(x) = log(exp(x) @ exp(x·1/K) @ exp(x·2/K) @ ... @ exp(x·K/K))
    value:     jax.jit(chain_K)
    gradient:  jax.jit(jax.grad(lambda x: sum(chain_K(x)²)))

with x an (N, tangent_dim) float32 batch. It reports trace time and lower + XLA
compile time in ms, the minimum over ``--repeats`` interleaved repetitions, with every
JAX cache cleared before each compilation.

Usage:
  python -m benchmarks.compile_time                       # SO3 and SE3, K = 1, 4, 16
  python -m benchmarks.compile_time --groups SE3 --chain 1,10,50 --markdown
"""

from __future__ import annotations

import argparse
import sys
import time


def program(lib, group: str, K: int, grad: bool):
    import jax
    import jax.numpy as jnp

    G = getattr(lib, group)

    def chain(x):
        T = G.exp(x)
        for j in range(1, K + 1):
            T = T @ G.exp(x * (j / K))
        return T.log()

    if grad:
        return jax.grad(lambda x: jnp.sum(chain(x) ** 2))
    return chain


def measure(fn, x):
    """(trace seconds, lower + compile seconds) of ``jax.jit(fn)`` from empty caches."""
    import jax

    jax.clear_caches()
    t0 = time.perf_counter()
    traced = jax.jit(fn).trace(x)
    t1 = time.perf_counter()
    traced.lower().compile()
    return t1 - t0, time.perf_counter() - t1


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--groups", default="SO3,SE3")
    p.add_argument("--chain", default="1,4,16", help="chain lengths K, comma-separated")
    p.add_argument("--n", type=int, default=1000, help="batch size N")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--markdown", action="store_true")
    args = p.parse_args(argv)

    import jax
    import jax.numpy as jnp
    import numpy as np

    import jaxlie_geo

    try:
        import jaxlie
    except ImportError:
        sys.exit("compile_time.py compares against jaxlie: pip install 'jaxlie==1.5.*'")

    libs = [("jaxlie_geo", jaxlie_geo), ("jaxlie", jaxlie)]
    print(
        f"jax {jax.__version__}, {jax.devices()[0].platform}, N = {args.n}, float32, "
        f"min of {args.repeats}, ms"
    )
    head = [
        "group",
        "program",
        "K",
        "ours: trace",
        "ours: lower+compile",
        "jaxlie: trace",
        "jaxlie: lower+compile",
        "total jaxlie / ours",
    ]
    if args.markdown:
        print("| " + " | ".join(head) + " |\n|" + "---|" * 3 + "--:|" * 5)
    else:
        print("  ".join(head))
    rng = np.random.default_rng(0)
    for group in args.groups.split(","):
        k = getattr(jaxlie_geo, group).tangent_dim
        x = jnp.asarray(0.3 * rng.normal(size=(args.n, k)), jnp.float32)
        for grad in (False, True):
            for K in (int(s) for s in args.chain.split(",")):
                best = {name: [float("inf")] * 2 for name, _ in libs}
                for r in range(args.repeats):
                    for name, lib in libs if r % 2 == 0 else libs[::-1]:
                        t = measure(program(lib, group, K, grad), x)
                        best[name] = [min(a, b) for a, b in zip(best[name], t)]
                ours, theirs = best["jaxlie_geo"], best["jaxlie"]
                row = [
                    group,
                    "gradient" if grad else "value",
                    str(K),
                    *(f"{1e3 * t:.0f}" for t in (*ours, *theirs)),
                    f"{sum(theirs) / sum(ours):.2f}",
                ]
                print(
                    ("| " + " | ".join(row) + " |") if args.markdown else "  ".join(row), flush=True
                )


if __name__ == "__main__":
    main()
