"""Speed of Sim3 and SE23 against references built from their matrices.

jaxlie has neither group, so each closed form is timed against the matrix computation that
defines it, built from jax alone (``G.hat`` and ``as_matrix`` only assemble matrices):

  op         ours (jaxlie_geo)                 matrix reference
  exp        G.exp(xi)                         vmap(jax.scipy.linalg.expm)(G.hat(xi))
  log        T.log() (T precomputed)           none: jax has no matrix logarithm
  compose    a @ b                             A @ B, the 4×4 (Sim3) or 5×5 (SE23) matrices
  apply      T @ points                        M @ (x, 1) (Sim3), M @ (x, 1, 0) (SE23)
  jac_right  G.jac_right(xi)                   vee(E⁻¹ ∂E/∂ξ_k) per column k, E = expm(hat ξ),
                                               ∂E/∂ξ_k by jax.jvp through expm, E⁻¹ by
                                               jnp.linalg.inv, vmapped over the batch
  grad       jax.grad of Σ‖log(exp(ξ))‖²       none (it needs a matrix logarithm)

The reference side of compose and apply gets the matrices of the same elements, computed
before timing; its output is a matrix (exp, compose) where ours is the parameter vector.
Inputs: tangents standard normal, rotation angles uniform in (0, 2.8) rad about random axes;
Sim3's log-scale σ uniform in (−1, 1); elements are exp of such tangents; points standard
normal. Every output is checked outside the timing, in the timed dtype, against the
reference (exp and compose through ``as_matrix``) and, where there is none, against the
identities log(exp ξ) = ξ and ∇Σ‖log(exp ξ)‖² = 2ξ (angles stay below π); the column
``max rel diff`` is max |ours − reference| / (1 + |reference|).

Timing (``common.measure``): every function is jitted
and compiled ahead (trace + lower + XLA compile, reported per side), inputs are on the
device, every call blocks until its result is ready; repetitions of the two sides are
interleaved (ours then the reference, then the reference then ours, ...), each about 10 ms
(a tenth of the slower side's call, up to 1 s, where that is longer) or one call; the time
per element is the median over repetitions divided by N, the speed-up reference / ours the
median of the paired per-repetition ratios with their inter-quartile range. The references
are slow (expm ~10 µs per 4×4 matrix on a CPU core), so the number of repetitions is chosen
within a time budget per case, at least 3, or 2 where a call takes more than 5 s (the
references of exp and jac_right at 10^6). A reference whose compiled program (arguments,
output, temporaries, from XLA's buffer assignment) would take more than 80% of the available
memory is compiled but not run: jac_right's reference differentiates expm through all its
branches and needs ~13 GB at N = 10^6 for SE23 in float32. The raw file records both sides'
footprints (``memory_*_mb``).

With --save the results replace raw/<machine>/extended-groups-<dtype>.json and the results
page (RESULTS.md) is regenerated (report.py).

Usage:
  python -m benchmarks.extended_groups                    # float32, N = 10^3 and 10^6
  python -m benchmarks.extended_groups --save             # ... saved, page regenerated
  python -m benchmarks.extended_groups --dtype float64    # float64 (enables jax x64)
  python -m benchmarks.extended_groups --quick            # smoke test: N = 100, 3 repeats
  python -m benchmarks.extended_groups --groups SE23 --ops exp,jac_right --sizes 1000

On a 2-core CPU the default float32 run takes 5-6 minutes, most of it in the references at
N = 10^6 (jac_right's reference takes 20-35 s per call there, exp's ~10 s); float64 about
2.5 minutes (jac_right's references at 10^6 need 22 and 44 GB and are not run).
"""

from __future__ import annotations

import importlib
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import expm

from benchmarks import common as C
from benchmarks.common import fmt_n
from benchmarks.report import extended_table, save

GROUPS = ("Sim3", "SE23")
OPS = ("exp", "log", "compose", "apply", "jac_right", "grad")

# Tangent layout: rotation vector at 3:6 in both; Sim3's log-scale at 6; the homogeneous
# coordinates a point is completed with for the matrix reference of apply.
GROUP_INFO = {
    "Sim3": dict(tangent_dim=7, rot=slice(3, 6), scale=6, homogeneous=(1.0,)),
    "SE23": dict(tangent_dim=9, rot=slice(3, 6), scale=None, homogeneous=(1.0, 0.0)),
}

# The expressions, as the raw file records them (report.py prints its own method text).
REFERENCES = {
    "exp": "vmap(jax.scipy.linalg.expm)(G.hat(xi))",
    "log": None,
    "compose": "A @ B (as_matrix of both, precomputed)",
    "apply": "M @ homogeneous(x), first three rows",
    "jac_right": "vmap: columns vee(inv(E) @ jvp(expm∘hat, xi, e_k)), E = expm(hat xi)",
    "grad": None,
}
CHECKS = {
    "exp": "as_matrix(ours) against the reference",
    "log": "log(exp(xi)) against xi",
    "compose": "as_matrix(ours) against the reference",
    "apply": "against the reference",
    "jac_right": "against the reference",
    "grad": "against 2 xi",
}


def parse_args(argv=None):
    p = C.parser(
        "Benchmark Sim3 and SE23 against matrix references (jit, interleaved).",
        {"groups": GROUPS, "ops": OPS},
        sizes="1000,1000000",
        quick="100",
        min_repeats=3,
    )
    return C.parse(p, argv)


# --------------------------------------------------------------------------------------
# The two sides. Every function maps raw arrays -> arrays; elements are built inside the
# trace. Fresh closures per case, so that compile times are not cached.
# --------------------------------------------------------------------------------------


def make_ours(G, op: str):
    if op == "exp":
        return lambda xi: G.exp(xi).parameters()
    if op == "log":
        return lambda p: G(p).log()
    if op == "compose":
        return lambda pa, pb: (G(pa) @ G(pb)).parameters()
    if op == "apply":
        return lambda p, pts: G(p) @ pts
    if op == "jac_right":
        return lambda xi: G.jac_right(xi)
    if op == "grad":
        return jax.grad(lambda xi: jnp.sum(G.exp(xi).log() ** 2))
    raise ValueError(op)


def make_reference(G, group: str, op: str):
    """The matrix computation ``op`` stands for, or None where jax has none (log, grad)."""

    if op == "exp":
        return lambda xi: jax.vmap(expm)(G.hat(xi))
    if op == "compose":
        return lambda ma, mb: jnp.matmul(ma, mb)
    if op == "apply":
        hom = GROUP_INFO[group]["homogeneous"]

        def apply(m, pts):
            tail = jnp.broadcast_to(jnp.asarray(hom, pts.dtype), (*pts.shape[:-1], len(hom)))
            x = jnp.concatenate([pts, tail], axis=-1)
            return jnp.einsum("...ij,...j->...i", m, x)[..., :3]

        return apply
    if op == "jac_right":
        k = G.tangent_dim

        def one(xi):
            # J_r(ξ) δ = vee(E⁻¹ d/dε expm(hat(ξ + ε δ))), E = expm(hat ξ): every column k
            # is a jvp through expm in the direction e_k (E itself is the shared primal).
            f = lambda y: expm(G.hat(y))
            E, dE = jax.vmap(lambda d: jax.jvp(f, (xi,), (d,)), out_axes=(None, 0))(
                jnp.eye(k, dtype=xi.dtype)
            )
            return G.vee(jnp.linalg.inv(E) @ dE).T  # (k, k): column k is vee(E⁻¹ dE_k)

        return jax.vmap(one)
    if op in ("log", "grad"):
        return None
    raise ValueError(op)


# --------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------


def make_inputs(G, group: str, op: str, n: int, dtype, seed: int):
    """(ours' inputs, the reference's inputs or None, the tangents behind them): device
    arrays of the timed dtype. The reference of compose and apply gets the elements'
    matrices."""

    info = GROUP_INFO[group]
    rng = np.random.default_rng([seed, GROUPS.index(group), OPS.index(op), n])

    def tangent():
        xi = rng.normal(size=(n, info["tangent_dim"]))
        rot = xi[:, info["rot"]]
        norm = np.linalg.norm(rot, axis=-1, keepdims=True)
        ang = rng.uniform(0.0, 2.8, size=(n, 1))
        xi[:, info["rot"]] = rot / np.maximum(norm, 1e-12) * ang
        if info["scale"] is not None:
            xi[:, info["scale"]] = rng.uniform(-1.0, 1.0, size=n)
        return jnp.asarray(xi, dtype=dtype)

    to_params = jax.jit(lambda x: G.exp(x).parameters())
    to_matrix = jax.jit(lambda p: G(p).as_matrix())

    xi = tangent()
    if op in ("exp", "jac_right"):
        ours, ref = (xi,), (xi,)
    elif op == "grad":
        ours, ref = (xi,), None
    elif op == "log":
        ours, ref = (to_params(xi),), None
    elif op == "compose":
        pa, pb = to_params(xi), to_params(tangent())
        ours, ref = (pa, pb), (to_matrix(pa), to_matrix(pb))
    elif op == "apply":
        p = to_params(xi)
        pts = jnp.asarray(rng.normal(size=(n, 3)), dtype=dtype)
        ours, ref = (p, pts), (to_matrix(p), pts)
    else:
        raise ValueError(op)
    return jax.block_until_ready((ours, ref, xi))


# --------------------------------------------------------------------------------------
# Checks (outside the timing, in the timed dtype)
# --------------------------------------------------------------------------------------


def max_rel_diff(x, y) -> float:
    """max |x - y| / (1 + |y|), non-finite -> inf."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if x.shape != y.shape:
        return float("inf")
    d = np.abs(x - y) / (1.0 + np.abs(y))
    return float(np.max(np.where(np.isfinite(d), d, np.inf))) if d.size else 0.0


def check(G, op: str, out_ours, out_ref, xi) -> float:
    if op in ("exp", "compose"):
        return max_rel_diff(jax.jit(lambda p: G(p).as_matrix())(out_ours), out_ref)
    if op in ("apply", "jac_right"):
        return max_rel_diff(out_ours, out_ref)
    if op == "log":
        return max_rel_diff(out_ours, xi)
    if op == "grad":
        return max_rel_diff(out_ours, 2.0 * xi)
    raise ValueError(op)


# --------------------------------------------------------------------------------------
# Main benchmark
# --------------------------------------------------------------------------------------


def bench_case(geo, group, op, n, args, dtype, index):
    G = getattr(geo, group)
    ours_in, ref_in, xi = make_inputs(G, group, op, n, dtype, args.seed)
    f_ours = make_ours(G, op)
    f_ref = make_reference(G, group, op) if ref_in is not None else None

    # Alternate the compile order between cases so neither side systematically goes first.
    comp_ref = None
    if f_ref is not None and index % 2 == 1:
        c_ref, comp_ref = C.compile_fn(f_ref, ref_in)
    c_ours, comp_ours = C.compile_fn(f_ours, ours_in)
    if f_ref is not None and index % 2 == 0:
        c_ref, comp_ref = C.compile_fn(f_ref, ref_in)

    # A reference that would not fit in memory is not run (SE23 jac_right at 10^6 needs
    # ~13 GB of temporaries in float32); the case then reports ours alone.
    ref_note, mem_ref = None, None
    if f_ref is not None:
        mem_ref = C.footprint_bytes(c_ref)
        avail = C.available_bytes()
        if avail is not None and mem_ref > 0.8 * avail:
            ref_note = f"not run: needs {mem_ref / 1e9:.1f} GB, {avail / 1e9:.1f} GB available"
            f_ref = c_ref = None

    # Warm-up executions, timed only to size the measurements; their outputs are checked.
    out_ours, first_ours = C.timed_call(c_ours, ours_in)
    sides = [(c_ours, ours_in, first_ours)]
    out_ref = None
    if f_ref is not None:
        out_ref, first_ref = C.timed_call(c_ref, ref_in)
        sides.append((c_ref, ref_in, first_ref))
    diff = (
        check(G, op, out_ours, out_ref, xi)
        if op in ("log", "grad") or out_ref is not None
        else None
    )
    del out_ours, out_ref

    target_s = 0.002 if args.quick else 0.01
    budget_s = 0.1 if args.quick else 1.5
    repeats = 3 if (args.quick and args.repeats is None) else args.repeats
    times = C.measure(sides, repeats, target_s, budget_s, min_repeats=3)

    r = {
        "group": group,
        "op": op,
        "n": n,
        "dtype": args.dtype,
        "ours_ns_per_elem": statistics.median(times[0]) * 1e9 / n,
        "ref_ns_per_elem": None,
        "ratio": None,
        "ratio_q1": None,
        "ratio_q3": None,
        "compile_ours_ms": comp_ours * 1e3,
        "compile_ref_ms": None if comp_ref is None else comp_ref * 1e3,
        "repeats": len(times[0]),
        "reference": REFERENCES[op],
        "reference_note": ref_note,
        "check": CHECKS[op],
        "max_rel_diff": diff,
        "memory_ours_mb": C.footprint_bytes(c_ours) / 1e6,
        "memory_ref_mb": None if mem_ref is None else mem_ref / 1e6,
    }
    if f_ref is not None:
        st = C.paired_stats(times[0], times[1])
        r.update(
            ref_ns_per_elem=st["median_b"] * 1e9 / n,
            ratio=st["ratio"],
            ratio_q1=st["ratio_q1"],
            ratio_q3=st["ratio_q3"],
        )
    return r


def global_warmup(geo, dtype):
    """Pay one-time process costs (backend init, first compile) before measuring anything."""
    for g in GROUPS:
        G = getattr(geo, g)
        x = jnp.zeros((1, G.tangent_dim), dtype=dtype)
        jax.block_until_ready(jax.jit(lambda x, G=G: G.exp(x).parameters())(x))
        jax.block_until_ready(jax.jit(lambda x, G=G: jax.vmap(expm)(G.hat(x)))(x))


# --------------------------------------------------------------------------------------
# Reporting
# --------------------------------------------------------------------------------------


def main(argv=None):
    args = parse_args(argv)
    if args.dtype == "float64":
        jax.config.update("jax_enable_x64", True)
    dtype = jnp.float64 if args.dtype == "float64" else jnp.float32

    geo = importlib.import_module("jaxlie_geo")
    info = C.machine_info("benchmarks.extended_groups", dtype=args.dtype)
    info.pop("jaxlie", None)
    print("# Sim3 and SE23 against matrix references")
    for k, v in info.items():
        print(f"  {k:13s} {v}")
    print(flush=True)

    t_start = time.perf_counter()
    global_warmup(geo, dtype)

    results = []
    index = 0
    for group in args.groups:
        for op in args.ops:
            for n in args.sizes:
                r = bench_case(geo, group, op, n, args, dtype, index)
                index += 1
                results.append(r)
                print(f"{group} {op} N={fmt_n(n)}: {C.progress_text(r)}", flush=True)

    elapsed = time.perf_counter() - t_start
    finish(
        results,
        args,
        info,
        elapsed,
        f"extended-groups-{args.dtype}",
        lambda r: f"{r['group']} {r['op']} N={fmt_n(r['n'])}",
        "the reference",
    )
    return 0


def finish(results, args, info, elapsed, stem, label, reference, table=None):
    """Print the page's table of the run (``table``, the report's function for it), the cases
    slower than ``reference`` or disagreeing with it (beyond 1e-3 in float32, 1e-8 in
    float64), the total time; write --json and --save."""
    table = table or extended_table
    for r in results:
        if r["ratio"] is not None and r["ratio"] < 0.95:
            print(f"slower than {reference}: {label(r)}")
    tol = 1e-3 if args.dtype == "float32" else 1e-8
    for r in results:
        if r["max_rel_diff"] is not None and not r["max_rel_diff"] < tol:
            check = f" ({r['check']})" if "check" in r else ""
            print(f"disagreement beyond {tol:g}: {label(r)}: {r['max_rel_diff']:.3g}{check}")
    data = {"machine": info, "results": results, "elapsed_s": elapsed}
    print("\n" + "\n".join(table(data)))
    print(f"total benchmark time: {elapsed:.0f} s")
    save(stem, data, args)


if __name__ == "__main__":
    sys.exit(main())
