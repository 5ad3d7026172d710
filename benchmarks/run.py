"""Speed benchmark: jaxlie_geo against jaxlie 1.5, in the same process.

For every group (SO2, SE2, SO3, SE3), every op and every batch size, both
libraries get a jax.jit-compiled function built from the *same* expression
(or the native method where jaxlie_geo has one that jaxlie lacks) and the
*same* input arrays; the tables it prints are the results page's (report.py). Timing
repetitions are interleaved (A B, then B A, ...)
so machine noise hits both libraries alike; we report the median time per
call divided by the batch size (ns/element) and the ratio
jaxlie / jaxlie_geo (> 1 means jaxlie_geo is faster), together with the
inter-quartile range of the per-repetition (paired) ratios as a noise gauge.
JIT compile time (trace + lower + compile) is reported per op as well.

Ops (identical inputs for both libraries):
  exp          G.exp(tangent)
  log          T.log() with T = exp(tangent) precomputed (time of log alone)
  compose      a @ b
  apply        T @ points
  inverse      T.inverse()
  interpolate  jaxlie_geo: a.interpolate(b, t)
               jaxlie:     a @ G.exp(t * (a.inverse() @ b).log())
  grad         jax.grad of sum |log(exp(xi)^-1 @ b)|^2 w.r.t. xi

With --save the results replace raw/<machine>/speed-<dtype>.json and the results page
(RESULTS.md, results.png) is regenerated from the raw files (report.py).

Usage:
  python -m benchmarks.run                      # full default run (float32), printed
  python -m benchmarks.run --save               # ... saved to raw/<machine>/, page regenerated
  python -m benchmarks.run --dtype float64      # float64 (enables jax x64)
  python -m benchmarks.run --quick              # smoke test, small sizes
  python -m benchmarks.run --groups SE3 --ops exp,log --sizes 1,1000
"""

from __future__ import annotations

import importlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import common as C
from benchmarks.common import GROUP_INFO, GROUPS, OPS, fmt_n, fmt_ns
from benchmarks.report import save, speed_table


def parse_args(argv=None):
    p = C.parser(
        "Benchmark jaxlie_geo against jaxlie (same process, interleaved, jit).",
        {"groups": GROUPS, "ops": OPS},
        sizes="1,1000,1000000",
        quick="1,100",
        min_repeats=7,
    )
    p.add_argument(
        "--no-eager", action="store_true", help="skip the eager SE3.exp latency measurement"
    )
    p.add_argument(
        "--memory-n",
        type=float,
        default=2**22,
        help="batch size of the memory table (SE3 ops, compiled, not run; 0 skips it)",
    )
    p.add_argument(
        "--candidate",
        default="jaxlie_geo",
        help="module benchmarked against jaxlie (default jaxlie_geo; 'jaxlie' gives an "
        "A/A run that calibrates the harness: all ratios should be ~1)",
    )
    args = C.parse(p, argv)
    if args.save and args.candidate != "jaxlie_geo":
        p.error("--save records jaxlie_geo's results; an A/A run (--candidate) is not saved")
    return args


# --------------------------------------------------------------------------------------
# Op definitions. Every op maps raw arrays -> raw arrays (or a pytree of arrays), so both
# libraries see exactly the same jit inputs; group objects are built inside the trace.
# --------------------------------------------------------------------------------------


def make_op(lib, group: str, op: str, native: bool):
    """Return f(*arrays) for `op` of `lib.<group>`.

    `native` selects jaxlie_geo's own interpolate(); jaxlie has none and gets the
    defining expression a @ exp(t * log(a^-1 b)).
    """

    G = getattr(lib, group)

    if op == "exp":
        return lambda xi: G.exp(xi).parameters()
    if op == "log":
        return lambda pa: G(pa).log()
    if op == "compose":
        return lambda pa, pb: (G(pa) @ G(pb)).parameters()
    if op == "apply":
        return lambda pa, pts: G(pa) @ pts
    if op == "inverse":
        return lambda pa: G(pa).inverse().parameters()
    if op == "interpolate":
        if native:
            return lambda pa, pb, t: G(pa).interpolate(G(pb), t).parameters()

        def interp(pa, pb, t):
            a, b = G(pa), G(pb)
            return (a @ G.exp(t[..., None] * (a.inverse() @ b).log())).parameters()

        return interp
    if op == "grad":

        def loss(xi, pb):
            d = (G.exp(xi).inverse() @ G(pb)).log()
            return jnp.sum(d * d)

        return jax.grad(loss)
    raise ValueError(op)


def make_inputs(group: str, op: str, n: int, dtype, seed: int, ref_lib):
    """Identical inputs (numpy -> jax arrays) for both libraries."""

    info = GROUP_INFO[group]
    rng = np.random.default_rng([seed, GROUPS.index(group), OPS.index(op), n])

    # Rotation angles uniform in (0, max_angle), random axes, translations O(1). Ops that
    # combine two elements (compose, interpolate, grad) use max_angle 1.5 so that the relative
    # rotation stays below pi, away from the (ill-conditioned) cut locus of log.
    max_angle = 2.8 if op in ("exp", "log", "apply", "inverse") else 1.5

    def tangent():
        xi = rng.normal(size=(n, info["tangent_dim"]))
        rot = xi[:, info["rot"]]
        norm = np.linalg.norm(rot, axis=-1, keepdims=True)
        ang = rng.uniform(0.0, max_angle, size=(n, 1))
        xi[:, info["rot"]] = rot / np.maximum(norm, 1e-12) * ang
        return jnp.asarray(xi, dtype=dtype)

    G = getattr(ref_lib, group)
    exp_params = jax.jit(lambda x: G.exp(x).parameters())

    def params():
        p = exp_params(tangent())
        return jnp.asarray(p, dtype=dtype)

    if op == "exp":
        args = (tangent(),)
    elif op in ("log", "inverse"):
        args = (params(),)
    elif op == "compose":
        args = (params(), params())
    elif op == "apply":
        pts = jnp.asarray(rng.normal(size=(n, info["space_dim"])), dtype=dtype)
        args = (params(), pts)
    elif op == "interpolate":
        t = jnp.asarray(rng.uniform(0.0, 1.0, size=(n,)), dtype=dtype)
        args = (params(), params(), t)
    elif op == "grad":
        args = (tangent(), params())
    else:
        raise ValueError(op)
    return jax.block_until_ready(args)


# --------------------------------------------------------------------------------------
# Agreement check (guards against benchmarking two different computations)
# --------------------------------------------------------------------------------------


def max_disagreement(group, op, out_geo, out_ref) -> float:
    """Max over outputs of |geo - ref| / (1 + |ref|)."""

    a = [np.asarray(x, dtype=np.float64) for x in jax.tree_util.tree_leaves(out_geo)]
    b = [np.asarray(x, dtype=np.float64) for x in jax.tree_util.tree_leaves(out_ref)]
    worst = 0.0
    for x, y in zip(a, b):
        if x.shape != y.shape:
            return float("inf")
        quat = GROUP_INFO[group]["quat"]
        if quat is not None and op in ("exp", "compose", "inverse", "interpolate"):
            # q and -q are the same rotation; align the candidate's sign to the reference
            s = np.sign(np.sum(x[..., quat] * y[..., quat], axis=-1, keepdims=True))
            s[s == 0] = 1.0
            x = x.copy()
            x[..., quat] *= s
        if x.size:
            worst = max(worst, float(np.max(np.abs(x - y) / (1.0 + np.abs(y)))))
    return worst


# --------------------------------------------------------------------------------------
# Main benchmark
# --------------------------------------------------------------------------------------


def bench_case(geo, ref, native, group, op, n, args, dtype):

    inputs = make_inputs(group, op, n, dtype, args.seed, ref)
    f_geo = make_op(geo, group, op, native=native)
    f_ref = make_op(ref, group, op, native=False)

    # Alternate compile order between cases so neither side systematically goes first.
    if (GROUPS.index(group) + OPS.index(op) + args.sizes.index(n)) % 2 == 0:
        c_geo, comp_geo = C.compile_fn(f_geo, inputs)
        c_ref, comp_ref = C.compile_fn(f_ref, inputs)
    else:
        c_ref, comp_ref = C.compile_fn(f_ref, inputs)
        c_geo, comp_geo = C.compile_fn(f_geo, inputs)

    out_geo = jax.block_until_ready(c_geo(*inputs))  # warm-up execution
    out_ref = jax.block_until_ready(c_ref(*inputs))
    diff = max_disagreement(group, op, out_geo, out_ref)
    del out_geo, out_ref

    target_s = 0.002 if args.quick else 0.01
    budget_s = 0.1 if args.quick else 1.5
    repeats = 3 if (args.quick and args.repeats is None) else args.repeats
    t_geo, t_ref = C.interleaved(c_geo, c_ref, inputs, repeats, target_s, budget_s)

    st = C.paired_stats(t_geo, t_ref)
    return {
        "group": group,
        "op": op,
        "n": n,
        "dtype": args.dtype,
        "geo_ns_per_elem": st["median_a"] * 1e9 / n,
        "ref_ns_per_elem": st["median_b"] * 1e9 / n,
        "ratio": st["ratio"],
        "ratio_q1": st["ratio_q1"],
        "ratio_q3": st["ratio_q3"],
        "compile_geo_ms": comp_geo * 1e3,
        "compile_ref_ms": comp_ref * 1e3,
        "repeats": len(t_geo),
        "max_rel_diff": diff,
    }


def eager_latency(geo, ref, args, dtype):
    """Per-call latency of SE3.exp on one tangent (batch 1), no user jit."""

    xi = jnp.asarray(np.random.default_rng(args.seed).normal(size=(1, 6)) * 0.5, dtype=dtype)
    f_geo = lambda x: geo.SE3.exp(x).parameters()
    f_ref = lambda x: ref.SE3.exp(x).parameters()
    for _ in range(3):  # warm per-primitive dispatch caches
        jax.block_until_ready(f_geo(xi))
        jax.block_until_ready(f_ref(xi))
    repeats = 5 if args.quick else (args.repeats or 15)
    target_s = 0.005 if args.quick else 0.03
    t_geo, t_ref = C.interleaved(f_geo, f_ref, (xi,), repeats, target_s, 1.0)
    st = C.paired_stats(t_geo, t_ref)
    return {
        "geo_us": st["median_a"] * 1e6,
        "ref_us": st["median_b"] * 1e6,
        "ratio": st["ratio"],
        "ratio_q1": st["ratio_q1"],
        "ratio_q3": st["ratio_q3"],
        "repeats": len(t_geo),
    }


def global_warmup(geo, ref, dtype):
    """Pay one-time process costs (backend init, first compile) before measuring anything."""

    for lib in (ref, geo):
        for g in GROUPS:
            G = getattr(lib, g)
            x = jnp.zeros((1, G.tangent_dim), dtype=dtype)
            jax.block_until_ready(jax.jit(lambda x, G=G: G.exp(x).parameters())(x))


# --------------------------------------------------------------------------------------
# Reporting
# --------------------------------------------------------------------------------------


def memory_table(geo, ref, native, n: int, dtype, seed: int) -> list:
    """Per SE3 op at batch n: XLA's buffer assignment for the compiled program (compiled,
    not run), in MB: arguments, output, temporaries, for both libraries. Peak memory is at
    most their sum."""
    rows = []
    for op in OPS:
        small = make_inputs("SE3", op, 1, dtype, seed, ref)
        specs = [jax.ShapeDtypeStruct((n,) + a.shape[1:], a.dtype) for a in small]
        row = {"op": op, "n": n}
        for side, lib, nat in (("geo", geo, native), ("ref", ref, False)):
            m = jax.jit(make_op(lib, "SE3", op, nat)).lower(*specs).compile().memory_analysis()
            row[f"{side}_args_mb"] = m.argument_size_in_bytes / 1e6
            row[f"{side}_out_mb"] = m.output_size_in_bytes / 1e6
            row[f"{side}_temp_mb"] = m.temp_size_in_bytes / 1e6
        rows.append(row)
    return rows


def main(argv=None):
    args = parse_args(argv)

    if args.dtype == "float64":
        jax.config.update("jax_enable_x64", True)
    dtype = jnp.float64 if args.dtype == "float64" else jnp.float32

    ref = importlib.import_module("jaxlie")
    geo = importlib.import_module(args.candidate)
    native = hasattr(geo.SO2, "interpolate")

    info = C.machine_info("benchmarks.run", dtype=args.dtype, candidate=args.candidate)
    print("# jaxlie_geo vs jaxlie benchmark")
    for k, v in info.items():
        print(f"  {k:13s} {v}")
    if not native:
        print(
            f"  note: {args.candidate} has no interpolate(); both sides use the explicit expression"
        )
    print(flush=True)

    t_start = time.perf_counter()
    global_warmup(geo, ref, dtype)

    results = []
    for group in args.groups:
        for op in args.ops:
            for n in args.sizes:
                r = bench_case(geo, ref, native, group, op, n, args, dtype)
                results.append(r)
                print(
                    f"{group:4s} {op:12s} N={fmt_n(r['n']):>6s}  "
                    f"geo {fmt_ns(r['geo_ns_per_elem']):>10s}/el  "
                    f"jaxlie {fmt_ns(r['ref_ns_per_elem']):>10s}/el  ratio {r['ratio']:5.2f} "
                    f"[{r['ratio_q1']:.2f}–{r['ratio_q3']:.2f}]  "
                    f"compile {r['compile_geo_ms']:5.0f}/{r['compile_ref_ms']:5.0f} ms  "
                    f"x{r['repeats']}  reldiff {r['max_rel_diff']:.1e}",
                    flush=True,
                )

    eager = None
    if not args.no_eager:
        eager = eager_latency(geo, ref, args, dtype)
        print(
            f"eager SE3.exp (batch 1, no jit): geo {eager['geo_us']:.1f} µs  "
            f"jaxlie {eager['ref_us']:.1f} µs  ratio {eager['ratio']:.2f} "
            f"[{eager['ratio_q1']:.2f}–{eager['ratio_q3']:.2f}]",
            flush=True,
        )

    memory = None
    if args.memory_n:
        memory = memory_table(geo, ref, native, int(args.memory_n), dtype, args.seed)

    elapsed = time.perf_counter() - t_start
    data = {
        "machine": info,
        "results": results,
        "eager_se3_exp": eager,
        "memory": memory,
        "elapsed_s": elapsed,
    }
    print("\n" + "\n".join(speed_table(data)))
    print(f"total benchmark time: {elapsed:.0f} s")
    save(f"speed-{args.dtype}", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
