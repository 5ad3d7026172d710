#!/usr/bin/env python
"""Speed benchmark: jaxlie_geo against jaxlie 1.5, in the same process.

For every group (SO2, SE2, SO3, SE3), every op and every batch size, both
libraries get a jax.jit-compiled function built from the *same* expression
(or the native method where jaxlie_geo has one that jaxlie lacks) and the
*same* input arrays. Timing repetitions are interleaved (A B, then B A, ...)
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
  python benchmarks/run.py                      # full default run (float32), printed
  python benchmarks/run.py --save               # ... saved to raw/<machine>/, page regenerated
  python benchmarks/run.py --dtype float64      # float64 (enables jax x64)
  python benchmarks/run.py --quick              # smoke test, small sizes
  python benchmarks/run.py --groups SE3 --ops exp,log --sizes 1,1000 --markdown
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import importlib.metadata
import json
import os
import platform
import statistics
import subprocess
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from report import add_save_arguments, fmt_n, fmt_ns, geomean, memory_rows, save

# Benchmark the checkout's jaxlie_geo (works with or without an install, and with a stale
# editable install that predates jaxlie_geo/__init__.py).
_REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if (
    os.path.exists(os.path.join(_REPO_ROOT, "jaxlie_geo", "__init__.py"))
    and _REPO_ROOT not in sys.path
):
    sys.path.insert(0, _REPO_ROOT)

GROUPS = ("SO2", "SE2", "SO3", "SE3")
OPS = ("exp", "log", "compose", "apply", "inverse", "interpolate", "grad")

# Tangent layout per group: (tangent_dim, indices of rotation part, space_dim)
GROUP_INFO = {
    "SO2": dict(tangent_dim=1, rot=slice(0, 1), space_dim=2, quat=None),
    "SE2": dict(tangent_dim=3, rot=slice(2, 3), space_dim=2, quat=None),
    "SO3": dict(tangent_dim=3, rot=slice(0, 3), space_dim=3, quat=slice(0, 4)),
    "SE3": dict(tangent_dim=6, rot=slice(3, 6), space_dim=3, quat=slice(0, 4)),
}


def parse_args(argv=None):
    p = argparse.ArgumentParser(
        description="Benchmark jaxlie_geo against jaxlie (same process, interleaved, jit).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--sizes",
        default=None,
        help="comma-separated batch sizes (default 1,1000,1000000; --quick: 1,100)",
    )
    p.add_argument(
        "--groups", default=",".join(GROUPS), help="comma-separated subset of SO2,SE2,SO3,SE3"
    )
    p.add_argument(
        "--ops", default=",".join(OPS), help="comma-separated subset of " + ",".join(OPS)
    )
    p.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="interleaved repetitions per (group, op, size); default: automatic, "
        "5..25 within a time budget per case",
    )
    p.add_argument("--dtype", choices=("float32", "float64"), default="float32")
    p.add_argument("--quick", action="store_true", help="small sizes and few repeats (smoke test)")
    p.add_argument("--markdown", action="store_true", help="print the result tables as markdown")
    p.add_argument(
        "--json",
        default=None,
        metavar="PATH",
        help="also write the raw results (the --save format) to PATH",
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
    p.add_argument("--seed", type=int, default=0)
    add_save_arguments(p)
    args = p.parse_args(argv)

    if args.sizes is None:
        args.sizes = "1,100" if args.quick else "1,1000,1000000"
    args.sizes = parse_sizes(p, args.sizes)
    args.groups = parse_choices(p, args.groups, GROUPS, "group", str.upper)
    args.ops = parse_choices(p, args.ops, OPS, "op", str.lower)
    if args.save and args.candidate != "jaxlie_geo":
        p.error("--save records jaxlie_geo's results; an A/A run (--candidate) is not saved")
    return args


def parse_sizes(p, text: str) -> list:
    """Comma-separated batch sizes ("1,1e3") -> ints >= 1 (argparse error otherwise)."""
    sizes = [int(float(s)) for s in text.split(",") if s.strip()]
    if any(n < 1 for n in sizes):
        p.error("sizes must be >= 1")
    return sizes


def parse_choices(p, text: str, choices, what: str, norm=lambda x: x) -> list:
    """Comma-separated names, normalised by ``norm``, each one of ``choices``."""
    items = [norm(x.strip()) for x in text.split(",") if x.strip()]
    for x in items:
        if x not in choices:
            p.error(f"unknown {what} {x!r}; choose from {tuple(choices)}")
    return items


# --------------------------------------------------------------------------------------
# Machine / version info
# --------------------------------------------------------------------------------------


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def version_of(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


#: What the scripts themselves write: a tree that differs from its commit only there is clean.
RESULT_FILES = ("benchmarks/raw/", "benchmarks/RESULTS.md", "benchmarks/results.png",
                "benchmarks/pose_graphs.png")  # fmt: skip


def git_commit() -> str:
    """The checkout's commit, with ``-dirty`` when ``dirty_files`` names any file."""
    try:
        out = subprocess.run(
            ["git", "-C", _REPO_ROOT, "rev-parse", "--short=7", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        )
        commit = out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return commit + "-dirty" if dirty_files() else commit


def dirty_files() -> list:
    """The tracked files that differ from the commit (``git status``), so that a page
    rendered from a run of a modified tree says which files differed. The benchmark results
    (``RESULT_FILES``) are not counted: one script's run may follow another's ``--save``."""
    try:
        out = subprocess.run(
            ["git", "-C", _REPO_ROOT, "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        )
        files = (line[3:].strip() for line in out.stdout.splitlines() if line.strip())
        return sorted(f for f in files if not f.startswith(RESULT_FILES))
    except (OSError, subprocess.SubprocessError):
        return []


def machine_info(command: str, **run) -> dict:
    """The machine and the versions a run used (the ``machine`` entry of a raw file), then
    the run's own fields (dtype, ...) and its command line."""
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = os.cpu_count()
    geo = importlib.import_module("jaxlie_geo")
    return {
        "date": datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "cores_usable": affinity,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "jax": version_of("jax"),
        "jaxlib": version_of("jaxlib"),
        "jaxlie": version_of("jaxlie"),
        "jaxlie_geo": getattr(geo, "__version__", version_of("jaxlie_geo")),
        "commit": git_commit(),
        "dirty_files": dirty_files(),
        "numpy": version_of("numpy"),
        "backend": jax.default_backend(),
        "devices": ", ".join(str(d) for d in jax.devices()),
        "device_kind": jax.devices()[0].device_kind,
        **run,
        "command": " ".join(["python", command, *sys.argv[1:]]),
    }


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
# Timing
# --------------------------------------------------------------------------------------


def compile_fn(fn, args):
    """Trace + lower + compile; returns (compiled, seconds)."""

    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    return compiled, time.perf_counter() - t0


def run_n(fn, args, n: int) -> float:
    """Mean seconds per call over n blocking calls."""

    bur = jax.block_until_ready
    t0 = time.perf_counter()
    for _ in range(n):
        bur(fn(*args))
    return (time.perf_counter() - t0) / n


def calibrate(fn, args, target_s: float) -> int:
    """Number of calls so that one measurement lasts about target_s."""
    t = run_n(fn, args, 1)
    if t < target_s / 10:
        t = run_n(fn, args, max(1, min(1000, int(target_s / 10 / max(t, 1e-9)))))
    return max(1, int(round(target_s / max(t, 1e-9))))


def interleaved(fn_a, fn_b, args, repeats, target_s, budget_s, min_repeats=7):
    """Interleaved A/B timing; returns (per-call seconds lists for A and B).

    Repetition i runs A then B for even i and B then A for odd i.
    If repeats is None it is chosen within [min_repeats, 25] to fit roughly budget_s.
    """
    n_a = calibrate(fn_a, args, target_s)
    n_b = calibrate(fn_b, args, target_s)
    if repeats is None:
        one = run_n(fn_a, args, n_a) * n_a + run_n(fn_b, args, n_b) * n_b
        repeats = int(min(25, max(min_repeats, budget_s / max(one, 1e-9))))
    ta, tb = [], []
    for i in range(repeats):
        if i % 2 == 0:
            ta.append(run_n(fn_a, args, n_a))
            tb.append(run_n(fn_b, args, n_b))
        else:
            tb.append(run_n(fn_b, args, n_b))
            ta.append(run_n(fn_a, args, n_a))
    return ta, tb


def paired_stats(t_a, t_b) -> dict:
    """Medians of two interleaved timing series and the ratio b/a as the median of the paired
    (same-repetition) ratios, robust to slow drift of the machine, with its quartiles."""
    paired = [b / a for a, b in zip(t_a, t_b)]
    q1, q3 = quantiles(paired)
    med_a, med_b = statistics.median(t_a), statistics.median(t_b)
    return {
        "median_a": med_a,
        "median_b": med_b,
        "ratio": statistics.median(paired),
        "ratio_q1": q1,
        "ratio_q3": q3,
    }


def quantiles(xs):
    xs = sorted(xs)
    if len(xs) == 1:
        return xs[0], xs[0]
    q = statistics.quantiles(xs, n=4, method="inclusive")
    return q[0], q[2]


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
        c_geo, comp_geo = compile_fn(f_geo, inputs)
        c_ref, comp_ref = compile_fn(f_ref, inputs)
    else:
        c_ref, comp_ref = compile_fn(f_ref, inputs)
        c_geo, comp_geo = compile_fn(f_geo, inputs)

    out_geo = jax.block_until_ready(c_geo(*inputs))  # warm-up execution
    out_ref = jax.block_until_ready(c_ref(*inputs))
    diff = max_disagreement(group, op, out_geo, out_ref)
    del out_geo, out_ref

    target_s = 0.002 if args.quick else 0.01
    budget_s = 0.1 if args.quick else 1.5
    repeats = 3 if (args.quick and args.repeats is None) else args.repeats
    t_geo, t_ref = interleaved(c_geo, c_ref, inputs, repeats, target_s, budget_s)

    st = paired_stats(t_geo, t_ref)
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
    t_geo, t_ref = interleaved(f_geo, f_ref, (xi,), repeats, target_s, 1.0)
    med_geo, med_ref = statistics.median(t_geo), statistics.median(t_ref)
    paired = [r / g for g, r in zip(t_geo, t_ref)]
    q1, q3 = quantiles(paired)
    return {
        "geo_us": med_geo * 1e6,
        "ref_us": med_ref * 1e6,
        "ratio": statistics.median(paired),
        "ratio_q1": q1,
        "ratio_q3": q3,
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


def table_rows(results):
    rows = []
    for r in results:
        rows.append(
            [
                r["group"],
                r["op"],
                fmt_n(r["n"]),
                fmt_ns(r["geo_ns_per_elem"]),
                fmt_ns(r["ref_ns_per_elem"]),
                f"{r['ratio']:.2f}",
                f"{r['ratio_q1']:.2f}–{r['ratio_q3']:.2f}",
                f"{r['compile_geo_ms']:.0f}",
                f"{r['compile_ref_ms']:.0f}",
            ]
        )
    return rows


HEADER = [
    "group",
    "op",
    "N",
    "jaxlie_geo /elem",
    "jaxlie /elem",
    "ratio",
    "ratio IQR",
    "compile geo ms",
    "compile jaxlie ms",
]


def render(header, rows, markdown: bool) -> str:
    if markdown:
        out = [
            "| " + " | ".join(header) + " |",
            "|" + "|".join("---" if i < 3 else "--:" for i in range(len(header))) + "|",
        ]
        out += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(out)
    widths = [
        max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)
    ]
    line = lambda cells: "  ".join(
        c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths))
    )
    return "\n".join([line(header), line(["-" * w for w in widths])] + [line(r) for r in rows])


def summary(results, markdown: bool, eager=None) -> str:
    lines = []
    ops = [o for o in OPS if any(r["op"] == o for r in results)]
    groups = [g for g in GROUPS if any(r["group"] == g for r in results)]
    sizes = sorted({r["n"] for r in results})

    def row(name, keep):
        cells = [
            f"{geomean([r['ratio'] for r in results if keep(r) and r['n'] == n]):.2f}"
            for n in sizes
        ]
        return [name, *cells, f"{geomean([r['ratio'] for r in results if keep(r)]):.2f}"]

    rows = [row(o, lambda r, o=o: r["op"] == o) for o in ops]
    rows += [row(g, lambda r, g=g: r["group"] == g) for g in groups]
    rows.append(row("overall", lambda r: True))
    header = ["op"] + [fmt_n(n) for n in sizes] + ["all"]
    lines.append(
        "Geometric-mean ratio jaxlie/jaxlie_geo (>1: jaxlie_geo faster), by op and by group:"
    )
    lines.append("")
    lines.append(render_simple(header, rows, markdown))
    # "slower" = median ratio below 0.95 and the whole paired-ratio IQR below 1 (A/A runs with
    # --candidate jaxlie show ~5% noise on this kind of machine for small batches).
    slower = [r for r in results if r["ratio"] < 0.95 and r["ratio_q3"] < 1.0]
    lines.append("")
    if eager is not None and eager["ratio"] < 0.95 and eager["ratio_q3"] < 1.0:
        lines.append(
            f"Eager (no jit) SE3.exp, batch 1: jaxlie_geo is slower, "
            f"{eager['geo_us']:.1f} µs vs {eager['ref_us']:.1f} µs per call "
            f"(ratio {eager['ratio']:.3f})."
        )
    if slower:
        lines.append(
            "Cases where jaxlie_geo is slower (ratio < 0.95 and whole paired-ratio IQR below 1):"
        )
        for r in sorted(slower, key=lambda r: r["ratio"]):
            lines.append(
                f"  {'- ' if markdown else ''}{r['group']} {r['op']} N={fmt_n(r['n'])}: "
                f"ratio {r['ratio']:.2f} ({fmt_ns(r['geo_ns_per_elem'])} vs "
                f"{fmt_ns(r['ref_ns_per_elem'])} per element)"
            )
    else:
        lines.append(
            "No case where jaxlie_geo is clearly slower "
            "(ratio < 0.95 with paired-ratio IQR below 1)."
        )
    tol = 1e-3 if results and results[0].get("dtype") == "float32" else 1e-8
    bad = [r for r in results if not (r["max_rel_diff"] < (10 * tol if r["op"] == "grad" else tol))]
    if bad:
        lines.append("")
        lines.append(
            "Note: outputs disagree between the libraries beyond the dtype's tolerance "
            "in these cases. Either a library is inaccurate there (see "
            "benchmarks/accuracy.py) or the two sides compute different things; check "
            "before trusting the ratio:"
        )
        for r in bad:
            lines.append(
                f"  {r['group']} {r['op']} N={fmt_n(r['n'])}: "
                f"max |diff|/(1+|jaxlie|) = {r['max_rel_diff']:.3g}"
            )
    return "\n".join(lines)


def render_simple(header, rows, markdown):
    if markdown:
        out = [
            "| " + " | ".join(header) + " |",
            "|---|" + "|".join("--:" for _ in header[1:]) + "|",
        ]
        return "\n".join(out + ["| " + " | ".join(r) + " |" for r in rows])
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    line = lambda cells: "  ".join(
        c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths))
    )
    return "\n".join([line(header)] + [line(r) for r in rows])


def main(argv=None):
    args = parse_args(argv)

    if args.dtype == "float64":
        jax.config.update("jax_enable_x64", True)
    dtype = jnp.float64 if args.dtype == "float64" else jnp.float32

    ref = importlib.import_module("jaxlie")
    geo = importlib.import_module(args.candidate)
    native = hasattr(geo.SO2, "interpolate")

    info = machine_info("benchmarks/run.py", dtype=args.dtype, candidate=args.candidate)
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
    print()
    print(
        f"## Results ({args.dtype}; per element = median time per call / N; ratio = median "
        "over repetitions of jaxlie time / jaxlie_geo time, >1 means jaxlie_geo is faster; "
        "IQR of those ratios)"
    )
    print()
    print(render(HEADER, table_rows(results), args.markdown))
    print()
    if eager is not None:
        eager_rows = [
            [
                "SE3.exp eager, batch 1",
                f"{eager['geo_us']:.1f}",
                f"{eager['ref_us']:.1f}",
                f"{eager['ratio']:.2f}",
                f"{eager['ratio_q1']:.2f}–{eager['ratio_q3']:.2f}",
            ]
        ]
        print(
            render_simple(
                ["case", "jaxlie_geo µs/call", "jaxlie µs/call", "ratio", "ratio IQR"],
                eager_rows,
                args.markdown,
            )
        )
        print()
    print(summary(results, args.markdown, eager))
    print()
    if memory is not None:
        print(
            f"## Memory, SE3 at N = {fmt_n(int(args.memory_n))} ({args.dtype}; MB from XLA's "
            "buffer assignment: arguments, output, temporaries)"
        )
        print()
        print(
            render_simple(
                ["op", "args", "out", "jaxlie_geo temp", "jaxlie temp"],
                memory_rows(memory),
                args.markdown,
            )
        )
        print()
    print(f"total benchmark time: {elapsed:.0f} s")

    data = {
        "machine": info,
        "results": results,
        "eager_se3_exp": eager,
        "memory": memory,
        "elapsed_s": elapsed,
    }
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=1, ensure_ascii=False)
    if args.save:
        save(f"speed-{args.dtype}", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
