"""What each piece of scheduling machinery earns: every op with and without it, in one
process, interleaved.

Two mechanisms decide only how XLA schedules a kernel, never its values:

  barriers  ``_xla.materialize`` (an ``optimization_barrier``): computes a kernel's inputs
            once into memory instead of letting XLA recompute them per read.
  chunks    ``_batch.in_chunks``: evaluates a large CPU batch a slice at a time.

For each group, op and dtype at one batch size (default 10⁶), the op is compiled twice,
as shipped and with the mechanism switched off (barriers: ``optimization_barrier``
replaced by the identity while tracing; chunks: the chunking threshold set beyond any
batch), and both are timed interleaved (``run.py``'s harness). The gain is the time
without divided by the time with: a mechanism is worth keeping in an op where it earns
at least 1.3x. ``docs/design/memory-and-chunks.md`` records the decision.

Usage:
  python -m benchmarks.scheduling                       # barriers, float32 and float64
  python -m benchmarks.scheduling --without chunks --groups SE3 --ops exp,interpolate
"""

from __future__ import annotations

import argparse
import contextlib

import jax
import numpy as np

import jaxlie_geo
from benchmarks import common as C
from benchmarks import run as R
from jaxlie_geo import _batch


@contextlib.contextmanager
def without(mechanism: str):
    """Trace with ``mechanism`` ("barriers", "chunks", both comma-separated, or "nothing")
    switched off."""
    if "," in mechanism:
        first, rest = mechanism.split(",", 1)
        with without(first), without(rest):
            yield
    elif mechanism == "barriers":
        saved = jax.lax.optimization_barrier
        jax.lax.optimization_barrier = lambda x: x
        try:
            yield
        finally:
            jax.lax.optimization_barrier = saved
    elif mechanism == "chunks":
        saved = _batch.CHUNKED_FROM
        _batch.CHUNKED_FROM = 2**62
        try:
            yield
        finally:
            _batch.CHUNKED_FROM = saved
    else:
        yield


CHAINS = {
    # A computed element composed on: compose's kernel reads exp's output several times.
    "exp_compose": ("grad", lambda G: lambda xi, pb: (G.exp(xi) @ G(pb)).parameters()),
    "jac_right_inv": ("exp", lambda G: G.jac_right_inv),
}
"""Ops beyond ``run.py``'s: name -> (``run.py`` op whose inputs it takes, f of the group)."""


def compiled(f, inputs, mechanism: str):
    """``f`` compiled afresh (the methods' own jit caches cleared), with ``mechanism``
    switched off while tracing."""
    jax.clear_caches()
    with without(mechanism):
        return jax.jit(f).lower(*inputs).compile()


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--without", choices=("barriers", "chunks", "barriers,chunks"), default="barriers"
    )
    p.add_argument("--groups", default=",".join(C.GROUPS))
    p.add_argument("--ops", default=",".join(C.OPS + tuple(CHAINS)))
    p.add_argument("--dtypes", default="float32,float64")
    p.add_argument("--n", type=float, default=1e6)
    p.add_argument("--repeats", type=int, default=9)
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    n = int(args.n)
    print(f"jax {jax.__version__}, {C.cpu_model()}, {jax.devices()[0].device_kind}")
    print(f"\n| group | op | dtype | shipped (ns) | without {args.without} (ns) | gain |")
    print("|---|---|---|--:|--:|--:|")
    for dtype in args.dtypes.split(","):
        for group in args.groups.split(","):
            for op in args.ops.split(","):
                if op in CHAINS:
                    like, make = CHAINS[op]
                    f = make(getattr(jaxlie_geo, group))
                else:
                    like, f = op, R.make_op(jaxlie_geo, group, op, native=True)
                inputs = R.make_inputs(group, like, n, np.dtype(dtype), 0, jaxlie_geo)
                a = compiled(f, inputs, "nothing")
                b = compiled(f, inputs, args.without)
                ta, tb = C.interleaved(a, b, inputs, args.repeats, 0.2, 5.0)
                s = C.paired_stats(ta, tb)
                print(
                    f"| {group} | {op} | {dtype} | {s['median_a'] / n * 1e9:.1f} "
                    f"| {s['median_b'] / n * 1e9:.1f} | {s['ratio']:.2f} "
                    f"({s['ratio_q1']:.2f}–{s['ratio_q3']:.2f}) |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
