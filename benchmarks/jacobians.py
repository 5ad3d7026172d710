"""Speed benchmark: jaxlie_geo's closed-form Jacobians against ``jax.jacfwd``.

For every group (SO2, SE2, SO3, SE3) and every analytical Jacobian that is not constant,
the closed form is timed against ``jax.vmap(jax.jacfwd(map))`` of the map it is the
Jacobian of, both under ``jax.jit`` on the same random inputs (batch 10^5 by default,
float32 by default). Conventions are those of ``jaxlie_geo/jacobians.py``: right
perturbations ``X ⊕ δ = X exp(δ)``, ``J = d log(f(X)⁻¹ f(X ⊕ δ)) / dδ`` at δ = 0 for
group-valued f, ``d f(X ⊕ δ) / dδ`` for vector-valued f (points and tangents are
perturbed additively). The maps differentiated (all at δ = 0):

  G.jac_right(x)            δ ↦ log(exp(x)⁻¹ exp(x + δ))
  G.jac_left(x)             δ ↦ log(exp(x + δ) exp(x)⁻¹)
  G.jac_right_inv(x)        δ ↦ log(exp(x) exp(δ))
  G.jac_left_inv(x)         δ ↦ log(exp(δ) exp(x))
  T.jlog()                  δ ↦ log(T exp(δ))
  jacobians.compose(a, b)   (δa, δb) ↦ log((a b)⁻¹ (a exp δa)(b exp δb))
  jacobians.inverse(a)      δ ↦ log(a (a exp δ)⁻¹)
  jacobians.between(a, b)   (δa, δb) ↦ log((a⁻¹ b)⁻¹ (a exp δa)⁻¹ (b exp δb))
  jacobians.rminus(a, b)    (δa, δb) ↦ log((a exp δa)⁻¹ (b exp δb))
  jacobians.rplus(a, x)     (δa, δx) ↦ log((a exp x)⁻¹ (a exp δa) exp(x + δx))
  jacobians.apply(T, p)     (δT, δp) ↦ (T exp δT)(p + δp)

(``jacobians.exp(G, x)`` and ``jacobians.log(T)`` are ``G.jac_right(x)`` and ``T.jlog()``.)
A case is skipped when our Jacobian does not depend on its inputs (e.g. everything of SO2
except apply, where Ad = 1 and J_r = 1); ``SEn.adjoint()`` is not the Jacobian of a map and
is not timed (it appears inside compose / inverse / between / rplus).

Inputs: tangents have normally distributed translations and rotation angles uniform in
(0, 3) rad about random axes; elements come from ``G.sample_uniform``; points are standard
normal. Before timing, every case is checked: the closed form and jacfwd are evaluated in
float64 on the same inputs and the max absolute difference is reported (column
``max |diff|``; > 1e-9 is flagged).

Timing is that of ``benchmarks/run.py`` (``common.interleaved``): the two jit-compiled
functions are run in interleaved repetitions (A B, B A, ...), the time per element is the
median over repetitions divided by N, and the ratio jacfwd / ours (> 1: the closed form is
faster) is the median of the paired per-repetition ratios, with their inter-quartile
range as a noise gauge. Compile time (trace + lower + compile) is measured separately.

With --save the results replace raw/<machine>/jacobians-<dtype>.json and the results page
(RESULTS.md) is regenerated (report.py).

Usage:
  python -m benchmarks.jacobians                    # float32, N = 10^5, all groups
  python -m benchmarks.jacobians --save             # ... saved to raw/<machine>/, page regenerated
  python -m benchmarks.jacobians --dtype float64    # float64 (enables jax x64)
  python -m benchmarks.jacobians --quick            # smoke test: N = 10^3, 3 repeats
  python -m benchmarks.jacobians --groups SE3 --cases jac_right_inv,rminus --sizes 1000,100000
  python -m benchmarks.jacobians --json out.json

JAX_PLATFORMS is respected (e.g. JAX_PLATFORMS=cuda to run on a GPU). On a 2-core CPU a
default run takes ~4-6 min and --quick ~2-5 min: most of it is XLA compilation (each case
compiles both sides in the timed dtype, and again in float64 for the check unless
--dtype float64), and jacfwd of the SE3 maps costs up to ~2 s per call at N = 10^5.
Repetitions: automatic within ~1 s per case, at least 5 (--quick: 3).
"""

from __future__ import annotations

import importlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import common as C
from benchmarks.common import GROUP_INFO, GROUPS, fmt_n, plain_ns
from benchmarks.report import jacobian_table, save

TOL = 1e-9  # float64 agreement threshold

# name -> (label of our function, map differentiated by jacfwd, input kinds)
CASES = {
    "jac_right": ("G.jac_right(x)", "δ ↦ log(exp(x)⁻¹ exp(x+δ))", ("tangent",)),
    "jac_left": ("G.jac_left(x)", "δ ↦ log(exp(x+δ) exp(x)⁻¹)", ("tangent",)),
    "jac_right_inv": ("G.jac_right_inv(x)", "δ ↦ log(exp(x) exp(δ))", ("tangent",)),
    "jac_left_inv": ("G.jac_left_inv(x)", "δ ↦ log(exp(δ) exp(x))", ("tangent",)),
    "jlog": ("T.jlog()", "δ ↦ log(T exp(δ))", ("element",)),
    "compose": (
        "jacobians.compose(a, b)",
        "(δa, δb) ↦ log((ab)⁻¹ (a exp δa)(b exp δb))",
        ("element", "element"),
    ),
    "inverse": ("jacobians.inverse(a)", "δ ↦ log(a (a exp δ)⁻¹)", ("element",)),
    "between": (
        "jacobians.between(a, b)",
        "(δa, δb) ↦ log((a⁻¹b)⁻¹ (a exp δa)⁻¹ (b exp δb))",
        ("element", "element"),
    ),
    "rminus": (
        "jacobians.rminus(a, b)",
        "(δa, δb) ↦ log((a exp δa)⁻¹ (b exp δb))",
        ("element", "element"),
    ),
    "rplus": (
        "jacobians.rplus(a, x)",
        "(δa, δx) ↦ log((a exp x)⁻¹ (a exp δa) exp(x+δx))",
        ("element", "tangent"),
    ),
    "apply": ("jacobians.apply(T, p)", "(δT, δp) ↦ (T exp δT)(p + δp)", ("element", "point")),
}


def parse_args(argv=None):
    p = C.parser(
        "Benchmark jaxlie_geo's closed-form Jacobians against jax.jacfwd (jit, interleaved; "
        "the agreement check is always float64).",
        {"groups": GROUPS, "cases": tuple(CASES)},
        sizes="100000",
        quick="1000",
        min_repeats=5,
    )
    return C.parse(p, argv)


# --------------------------------------------------------------------------------------
# The two sides of every case. Both map raw arrays -> a pytree of arrays; elements are
# rebuilt inside the trace. Fresh closures per call, so that compile times are not cached.
# --------------------------------------------------------------------------------------


def make_ours(lib, group: str, case: str):
    G = getattr(lib, group)
    J = lib.jacobians
    return {
        "jac_right": lambda x: G.jac_right(x),
        "jac_left": lambda x: G.jac_left(x),
        "jac_right_inv": lambda x: G.jac_right_inv(x),
        "jac_left_inv": lambda x: G.jac_left_inv(x),
        "jlog": lambda pt: G(pt).jlog(),
        "compose": lambda pa, pb: J.compose(G(pa), G(pb)),
        "inverse": lambda pa: J.inverse(G(pa)),
        "between": lambda pa, pb: J.between(G(pa), G(pb)),
        "rminus": lambda pa, pb: J.rminus(G(pa), G(pb)),
        "rplus": lambda pa, x: J.rplus(G(pa), x),
        "apply": lambda pt, p: J.apply(G(pt), p),
    }[case]


def make_autodiff(lib, group: str, case: str):
    """vmap over the batch of jacfwd (at 0) of the map the case's Jacobian differentiates."""

    G = getattr(lib, group)
    k = G.tangent_dim
    E = G.exp

    def at0(f, argnums=0):
        def jac(*inputs):
            zeros = lambda: jnp.zeros((k,), inputs[0].dtype)  # noqa: E731
            if argnums == 0:
                return jax.jacfwd(lambda d: f(d, *inputs))(zeros())
            return jax.jacfwd(lambda d1, d2: f(d1, d2, *inputs), argnums=(0, 1))(zeros(), zeros())

        return jax.vmap(jac)

    if case == "jac_right":
        return at0(lambda d, x: (E(x).inverse() @ E(x + d)).log())
    if case == "jac_left":
        return at0(lambda d, x: (E(x + d) @ E(x).inverse()).log())
    if case == "jac_right_inv":
        return at0(lambda d, x: (E(x) @ E(d)).log())
    if case == "jac_left_inv":
        return at0(lambda d, x: (E(d) @ E(x)).log())
    if case == "jlog":
        return at0(lambda d, pt: (G(pt) @ E(d)).log())
    if case == "compose":

        def f(da, db, pa, pb):
            a, b = G(pa), G(pb)
            return ((a @ b).inverse() @ ((a @ E(da)) @ (b @ E(db)))).log()

        return at0(f, argnums=(0, 1))
    if case == "inverse":

        def f(d, pa):
            a = G(pa)
            return (a @ (a @ E(d)).inverse()).log()

        return at0(f)
    if case == "between":

        def f(da, db, pa, pb):
            a, b = G(pa), G(pb)
            return ((a.inverse() @ b).inverse() @ ((a @ E(da)).inverse() @ (b @ E(db)))).log()

        return at0(f, argnums=(0, 1))
    if case == "rminus":

        def f(da, db, pa, pb):
            a, b = G(pa), G(pb)
            return ((a @ E(da)).inverse() @ (b @ E(db))).log()

        return at0(f, argnums=(0, 1))
    if case == "rplus":

        def f(da, dx, pa, x):
            a = G(pa)
            return ((a @ E(x)).inverse() @ ((a @ E(da)) @ E(x + dx))).log()

        return at0(f, argnums=(0, 1))
    if case == "apply":

        def jac(pt, p):
            T = G(pt)
            return jax.jacfwd(lambda dT, dp: (T @ E(dT)) @ (p + dp), argnums=(0, 1))(
                jnp.zeros((k,), pt.dtype), jnp.zeros_like(p)
            )

        return jax.vmap(jac)
    raise ValueError(case)


# --------------------------------------------------------------------------------------
# Inputs (float64 numpy; cast to the timed dtype later)
# --------------------------------------------------------------------------------------


def make_inputs(lib, group: str, case: str, n: int, seed: int):
    """float64 numpy inputs; needs jax_enable_x64 on (for sample_uniform in float64)."""

    G = getattr(lib, group)
    info = GROUP_INFO[group]
    ids = [seed, GROUPS.index(group), list(CASES).index(case), n]
    rng = np.random.default_rng(ids)
    key = jax.random.PRNGKey(int(rng.integers(0, 2**31 - 1)))
    out = []
    for kind in CASES[case][2]:
        if kind == "tangent":
            xi = rng.normal(size=(n, info["tangent_dim"]))
            rot = xi[:, info["rot"]]
            norm = np.linalg.norm(rot, axis=-1, keepdims=True)
            if rot.shape[-1] == 1:  # SO2 / SE2: signed angle
                ang = rng.uniform(-3.0, 3.0, size=(n, 1))
                xi[:, info["rot"]] = ang
            else:
                ang = rng.uniform(0.0, 3.0, size=(n, 1))
                xi[:, info["rot"]] = rot / np.maximum(norm, 1e-12) * ang
            out.append(xi)
        elif kind == "element":
            key, sub = jax.random.split(key)
            sample = G.sample_uniform(sub, (n,), dtype=jnp.float64)
            out.append(np.asarray(sample.parameters(), np.float64))
        elif kind == "point":
            out.append(rng.normal(size=(n, info["space_dim"])))
        else:
            raise ValueError(kind)
    return tuple(out)


# --------------------------------------------------------------------------------------
# Check / constant detection (float64)
# --------------------------------------------------------------------------------------


def leaves64(tree):

    return [np.asarray(x, dtype=np.float64) for x in jax.tree_util.tree_leaves(tree)]


def max_abs_diff(a, b) -> float:

    la, lb = leaves64(a), leaves64(b)
    if len(la) != len(lb):
        return float("inf")
    worst = 0.0
    for x, y in zip(la, lb):
        if x.shape != y.shape:
            return float("inf")
        if x.size:
            d = np.abs(x - y)
            worst = max(worst, float(np.max(np.where(np.isnan(d), np.inf, d))))
    return worst


def is_constant(lib, group: str, case: str, seed: int) -> bool:
    """True if our Jacobian is the same for all of a few random inputs (e.g. SO2's J_r = 1)."""

    inputs = [jnp.asarray(x) for x in make_inputs(lib, group, case, 16, seed + 12345)]
    out = leaves64(jax.jit(make_ours(lib, group, case))(*inputs))
    return all(np.array_equal(x, np.broadcast_to(x[:1], x.shape)) for x in out)


def check(lib, group: str, case: str, inputs64) -> float:
    """Max |ours - jacfwd| in float64 on the given inputs."""

    inputs = [jnp.asarray(x, dtype=jnp.float64) for x in inputs64]
    ours = jax.jit(make_ours(lib, group, case))(*inputs)
    ad = jax.jit(make_autodiff(lib, group, case))(*inputs)
    return max_abs_diff(ours, ad)


# --------------------------------------------------------------------------------------
# Main benchmark
# --------------------------------------------------------------------------------------


def set_x64(jax, on: bool):
    jax.config.update("jax_enable_x64", bool(on))


def bench_case(lib, group, case, n, args, index):

    # Inputs and the agreement check, in float64.
    set_x64(jax, True)
    inputs64 = make_inputs(lib, group, case, n, args.seed)

    # Timing, in the requested dtype (x64 only on for float64).
    set_x64(jax, args.dtype == "float64")
    dtype = jnp.float64 if args.dtype == "float64" else jnp.float32
    inputs = tuple(jnp.asarray(x.astype(dtype)) for x in inputs64)
    f_ours = make_ours(lib, group, case)
    f_ad = make_autodiff(lib, group, case)
    # Alternate compile order between cases so neither side systematically goes first.
    if index % 2 == 0:
        c_ours, comp_ours = C.compile_fn(f_ours, inputs)
        c_ad, comp_ad = C.compile_fn(f_ad, inputs)
    else:
        c_ad, comp_ad = C.compile_fn(f_ad, inputs)
        c_ours, comp_ours = C.compile_fn(f_ours, inputs)
    out_ours = jax.block_until_ready(c_ours(*inputs))  # warm-up execution
    out_ad = jax.block_until_ready(c_ad(*inputs))
    dtypes = {str(x.dtype) for x in jax.tree_util.tree_leaves(out_ours)}
    diff_timed = max_abs_diff(out_ours, out_ad)
    del out_ours, out_ad

    target_s = 0.002 if args.quick else 0.01
    budget_s = 0.1 if args.quick else 1.0
    repeats = 3 if (args.quick and args.repeats is None) else args.repeats
    t_ours, t_ad = C.interleaved(
        c_ours, c_ad, inputs, repeats, target_s, budget_s, min_repeats=3 if args.quick else 5
    )
    del c_ours, c_ad, inputs

    if args.dtype == "float64":
        diff = diff_timed  # the timed functions already ran in float64 on these inputs
    else:
        set_x64(jax, True)
        diff = check(lib, group, case, inputs64)
        set_x64(jax, False)

    st = C.paired_stats(t_ours, t_ad)
    label, mapping, _ = CASES[case]
    return {
        "group": group,
        "case": case,
        "jacobian": label,
        "map": mapping,
        "n": n,
        "dtype": args.dtype,
        "ours_ns_per_elem": st["median_a"] * 1e9 / n,
        "jacfwd_ns_per_elem": st["median_b"] * 1e9 / n,
        "ratio": st["ratio"],
        "ratio_q1": st["ratio_q1"],
        "ratio_q3": st["ratio_q3"],
        "compile_ours_ms": comp_ours * 1e3,
        "compile_jacfwd_ms": comp_ad * 1e3,
        "repeats": len(t_ours),
        "max_abs_diff_float64": diff,
        "max_abs_diff_timed_dtype": diff_timed,
        "output_dtypes": sorted(dtypes),
    }


def global_warmup(lib, dtype):
    """Pay one-time process costs (backend init, first compile) before measuring anything."""

    for g in GROUPS:
        G = getattr(lib, g)
        x = jnp.zeros((1, G.tangent_dim), dtype=dtype)
        jax.block_until_ready(jax.jit(lambda x, G=G: G.jac_right(x))(x))
        jax.block_until_ready(jax.jit(jax.vmap(jax.jacfwd(lambda x, G=G: G.exp(x).log())))(x))


# --------------------------------------------------------------------------------------
# Reporting
# --------------------------------------------------------------------------------------


def main(argv=None):
    args = parse_args(argv)
    set_x64(jax, args.dtype == "float64")

    lib = importlib.import_module("jaxlie_geo")
    info = C.machine_info("benchmarks.jacobians", dtype=args.dtype)
    info.pop("jaxlie", None)
    print("# jaxlie_geo closed-form Jacobians vs jax.jacfwd")
    for k, v in info.items():
        print(f"  {k:16s} {v}")
    print(flush=True)

    t_start = time.perf_counter()
    global_warmup(lib, jnp.float64 if args.dtype == "float64" else jnp.float32)

    results, skipped = [], []
    index = 0
    for group in args.groups:
        for case in args.cases:
            set_x64(jax, True)
            constant = is_constant(lib, group, case, args.seed)
            set_x64(jax, args.dtype == "float64")
            if constant:
                skipped.append((group, case))
                print(f"{group:4s} {case:14s} skipped (constant)", flush=True)
                continue
            for n in args.sizes:
                r = bench_case(lib, group, case, n, args, index)
                index += 1
                results.append(r)
                print(
                    f"{group:4s} {case:14s} N={fmt_n(n):>6s}  "
                    f"ours {plain_ns(r['ours_ns_per_elem']):>7s} ns/el  "
                    f"jacfwd {plain_ns(r['jacfwd_ns_per_elem']):>7s} ns/el  "
                    f"ratio {r['ratio']:5.2f} [{r['ratio_q1']:.2f}–{r['ratio_q3']:.2f}]  "
                    f"compile {r['compile_ours_ms']:5.0f}/{r['compile_jacfwd_ms']:5.0f} ms  "
                    f"x{r['repeats']}  diff64 {r['max_abs_diff_float64']:.1e}  "
                    f"diff{args.dtype[-2:]} {r['max_abs_diff_timed_dtype']:.1e}",
                    flush=True,
                )

    elapsed = time.perf_counter() - t_start
    data = {
        "machine": info,
        "results": results,
        "skipped_constant": [{"group": g, "case": c} for g, c in skipped],
        "elapsed_s": elapsed,
    }
    print("\n" + "\n".join(jacobian_table(data)))
    bad = [r for r in results if not (r["max_abs_diff_float64"] <= TOL)]
    for r in bad:
        print(f"DISAGREEMENT beyond {TOL:g} (float64): {r['group']} {r['jacobian']}")
    print(f"total benchmark time: {elapsed:.0f} s")
    save(f"jacobians-{args.dtype}", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
