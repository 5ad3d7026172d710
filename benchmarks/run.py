"""Speed of jaxlie_geo against jaxlie 1.5, in one process, on the same inputs.

Every group × operation × batch size, both libraries jitted (``common.compare``); then the
eager latency of ``SE3.exp`` and the memory of each compiled SE3 operation at N = 2²². The
method and the timed expressions are on the results page (``methods.md``: method).

Usage:
  python -m benchmarks.run [--save]             # float32; --dtype float64
  python -m benchmarks.run --quick              # smoke test: sizes 1 and 100, 3 repeats
  python -m benchmarks.run --groups SE3 --ops exp,log --sizes 1,1000
  python -m benchmarks.run --candidate jaxlie   # A/A run: the harness's noise, ratios ~1
"""

from __future__ import annotations

import importlib
import sys

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import common as C
from benchmarks.common import GROUPS, OPS
from benchmarks.report import save, speed_table

#: Tangent dimension, the tangent's rotation slice, the dimension acted on, quaternion slice.
LAYOUT = {
    "SO2": (1, slice(0, 1), 2, None),
    "SE2": (3, slice(2, 3), 2, None),
    "SO3": (3, slice(0, 3), 3, slice(0, 4)),
    "SE3": (6, slice(3, 6), 3, slice(0, 4)),
}


def make_op(lib, group: str, op: str, native: bool = True):
    """f(*arrays) of ``op`` on ``lib.<group>``; ``native=False`` gives interpolate by its
    defining expression a @ exp(t log(a⁻¹ b)) (jaxlie has no interpolate)."""
    G = getattr(lib, group)
    if op == "interpolate" and not native:
        return lambda pa, pb, t: (
            G(pa) @ G.exp(t[..., None] * (G(pa).inverse() @ G(pb)).log())
        ).parameters()
    if op == "grad":
        return jax.grad(lambda xi, pb: jnp.sum((G.exp(xi).inverse() @ G(pb)).log() ** 2))
    return {
        "exp": lambda xi: G.exp(xi).parameters(),
        "log": lambda pa: G(pa).log(),
        "compose": lambda pa, pb: (G(pa) @ G(pb)).parameters(),
        "apply": lambda pa, pts: G(pa) @ pts,
        "inverse": lambda pa: G(pa).inverse().parameters(),
        "interpolate": lambda pa, pb, t: G(pa).interpolate(G(pb), t).parameters(),
    }[op]


def make_inputs(group: str, op: str, n: int, dtype, seed: int, lib):
    """The same inputs for both libraries: rotation angles uniform in (0, 2.8) rad, or
    (0, 1.5) for the operations on two elements (relative rotations below π)."""
    dim, rot, space, _ = LAYOUT[group]
    rng = np.random.default_rng([seed, GROUPS.index(group), OPS.index(op), n])
    top = 2.8 if op in ("exp", "log", "apply", "inverse") else 1.5

    def tangent():
        xi = rng.normal(size=(n, dim))
        norm = np.linalg.norm(xi[:, rot], axis=-1, keepdims=True)
        xi[:, rot] *= rng.uniform(0.0, top, size=(n, 1)) / np.maximum(norm, 1e-12)
        return jnp.asarray(xi, dtype)

    G = getattr(lib, group)
    params = lambda: jax.jit(lambda x: G.exp(x).parameters())(tangent())
    args = {
        "exp": lambda: (tangent(),),
        "log": lambda: (params(),),
        "inverse": lambda: (params(),),
        "compose": lambda: (params(), params()),
        "apply": lambda: (params(), jnp.asarray(rng.normal(size=(n, space)), dtype)),
        "interpolate": lambda: (params(), params(), jnp.asarray(rng.uniform(size=n), dtype)),
        "grad": lambda: (tangent(), params()),
    }[op]()
    return jax.block_until_ready(args)


def disagreement(group: str, op: str, ours, theirs) -> float:
    """max |ours − jaxlie| / (1 + |jaxlie|), a quaternion's sign aligned to jaxlie's."""
    quat = LAYOUT[group][3]
    if quat is not None and op in ("exp", "compose", "inverse", "interpolate"):
        x, y = np.array(ours, np.float64), np.asarray(theirs, np.float64)
        s = np.sign(np.sum(x[..., quat] * y[..., quat], axis=-1, keepdims=True))
        x[..., quat] *= np.where(s == 0, 1.0, s)
        ours = x
    return C.max_rel_diff(ours, theirs)


def memory_table(geo, ref, native: bool, n: int, dtype, seed: int) -> list:
    """Per SE3 op at batch n, XLA's buffer assignment of the compiled program (not run), MB."""
    rows = []
    for op in OPS:
        small = make_inputs("SE3", op, 1, dtype, seed, ref)
        specs = [jax.ShapeDtypeStruct((n,) + a.shape[1:], a.dtype) for a in small]
        row = {"op": op, "n": n}
        for side, fn in (
            ("geo", make_op(geo, "SE3", op, native)),
            ("ref", make_op(ref, "SE3", op, False)),
        ):
            m = jax.jit(fn).lower(*specs).compile().memory_analysis()
            row[f"{side}_args_mb"] = m.argument_size_in_bytes / 1e6
            row[f"{side}_out_mb"] = m.output_size_in_bytes / 1e6
            row[f"{side}_temp_mb"] = m.temp_size_in_bytes / 1e6
        rows.append(row)
    return rows


def main(argv=None) -> int:
    p = C.parser(__doc__, "1,1000,1000000", "1,100", groups=GROUPS, ops=OPS)
    p.add_argument("--no-eager", action="store_true", help="skip the eager SE3.exp latency")
    p.add_argument("--memory-n", type=float, default=2**22, help="memory table's N (0 skips)")
    p.add_argument("--candidate", default="jaxlie_geo", help="module timed against jaxlie")
    args = C.parse(p, argv)
    if args.save and args.candidate != "jaxlie_geo":
        p.error("--save records jaxlie_geo's results; an A/A run (--candidate) is not saved")
    dtype = jnp.dtype(args.dtype)
    ref, geo = importlib.import_module("jaxlie"), importlib.import_module(args.candidate)
    native = hasattr(geo.SO2, "interpolate")
    info = C.machine_info("benchmarks.run", dtype=args.dtype, candidate=args.candidate)
    results, index = [], 0
    for group in args.groups:
        for op in args.ops:
            for n in args.sizes:
                x = make_inputs(group, op, n, dtype, args.seed, ref)
                sides = [(make_op(geo, group, op, native), x), (make_op(ref, group, op, False), x)]
                r, outs = C.compare(sides, n, args, index, min_repeats=7)
                index += 1
                r.update(group=group, op=op, n=n, dtype=args.dtype)
                r["max_rel_diff"] = disagreement(group, op, *outs)
                results.append(r)
                print(
                    group, op, n, C.fmt_ns(r["ours_ns_per_elem"]), f"{r['ratio']:.2f}", flush=True
                )
    eager = None
    if not args.no_eager:
        xi = jnp.asarray(np.random.default_rng(args.seed).normal(size=(1, 6)) * 0.5, dtype)
        sides = [(lambda x, lib=lib: lib.SE3.exp(x).parameters(), (xi,)) for lib in (geo, ref)]
        firsts = [C.timed_call(f, a)[1] for f, a in sides for _ in range(3)][2::3]
        times = C.measure(
            [(f, a, t) for (f, a), t in zip(sides, firsts)],
            5 if args.quick else args.repeats or 15,
            0.03,
            1.0,
        )
        eager = {"geo_us": np.median(times[0]) * 1e6, "ref_us": np.median(times[1]) * 1e6}
        eager.update(C.paired_stats(*times), repeats=len(times[0]))
    memory = None
    if args.memory_n:
        memory = memory_table(geo, ref, native, int(args.memory_n), dtype, args.seed)
    data = {"machine": info, "results": results, "eager_se3_exp": eager, "memory": memory}
    print("\n".join(speed_table(data)))
    save(f"speed-{args.dtype}", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
