"""Speed of jaxlie_geo's closed-form Jacobians against ``jax.jacfwd``.

Every Jacobian that depends on its input, against ``jax.vmap(jax.jacfwd(f))`` of the map f
it is the Jacobian of (``CASES``, in ``jaxlie_geo/jacobians.py``'s conventions: right
perturbations X exp(δ), J = d log(f(X)⁻¹ f(X exp δ))/dδ at δ = 0 for group-valued f), both
jitted on the same inputs (``common.compare``); every case is also checked against jacfwd in
float64. Tangents: normal translations, rotation angles uniform in (0, 3) rad; elements from
``G.sample_uniform``; points standard normal.

Usage:
  python -m benchmarks.jacobians [--save]            # float32, N = 10^5
  python -m benchmarks.jacobians --quick             # smoke test: N = 10^3, 3 repeats
  python -m benchmarks.jacobians --groups SE3 --cases jac_right_inv,rminus --sizes 1000
"""

from __future__ import annotations

import sys

import jax
import jax.numpy as jnp
import numpy as np

import jaxlie_geo
from benchmarks import common as C
from benchmarks.common import GROUPS
from benchmarks.report import jacobians_table, save
from benchmarks.run import LAYOUT

#: case -> (our function, the map jacfwd differentiates at 0, the inputs' kinds)
CASES = {
    "jac_right": ("G.jac_right(x)", "δ ↦ log(exp(x)⁻¹ exp(x+δ))", "t"),
    "jac_left": ("G.jac_left(x)", "δ ↦ log(exp(x+δ) exp(x)⁻¹)", "t"),
    "jac_right_inv": ("G.jac_right_inv(x)", "δ ↦ log(exp(x) exp(δ))", "t"),
    "jac_left_inv": ("G.jac_left_inv(x)", "δ ↦ log(exp(δ) exp(x))", "t"),
    "jlog": ("T.jlog()", "δ ↦ log(T exp(δ))", "e"),
    "compose": ("jacobians.compose(a, b)", "(δa, δb) ↦ log((ab)⁻¹ (a exp δa)(b exp δb))", "ee"),
    "inverse": ("jacobians.inverse(a)", "δ ↦ log(a (a exp δ)⁻¹)", "e"),
    "between": (
        "jacobians.between(a, b)",
        "(δa, δb) ↦ log((a⁻¹b)⁻¹ (a exp δa)⁻¹ (b exp δb))",
        "ee",
    ),
    "rminus": ("jacobians.rminus(a, b)", "(δa, δb) ↦ log((a exp δa)⁻¹ (b exp δb))", "ee"),
    "rplus": ("jacobians.rplus(a, x)", "(δa, δx) ↦ log((a exp x)⁻¹ (a exp δa) exp(x+δx))", "et"),
    "apply": ("jacobians.apply(T, p)", "(δT, δp) ↦ (T exp δT)(p + δp)", "ep"),
}


def make_ours(group: str, case: str):
    G, J = getattr(jaxlie_geo, group), jaxlie_geo.jacobians
    if case.startswith("jac_"):
        return getattr(G, case)
    if case == "jlog":
        return lambda p: G(p).jlog()
    if case == "rplus":
        return lambda pa, x: J.rplus(G(pa), x)
    if case == "apply":
        return lambda p, x: J.apply(G(p), x)
    return lambda *ps: getattr(J, case)(*map(G, ps))


def make_autodiff(group: str, case: str):
    """vmap over the batch of jacfwd, at δ = 0, of the map the case's Jacobian is of."""
    G = getattr(jaxlie_geo, group)
    E = G.exp
    maps = {
        "jac_right": lambda d, x: (E(x).inverse() @ E(x + d)).log(),
        "jac_left": lambda d, x: (E(x + d) @ E(x).inverse()).log(),
        "jac_right_inv": lambda d, x: (E(x) @ E(d)).log(),
        "jac_left_inv": lambda d, x: (E(d) @ E(x)).log(),
        "jlog": lambda d, p: (G(p) @ E(d)).log(),
        "inverse": lambda d, p: (G(p) @ (G(p) @ E(d)).inverse()).log(),
        "compose": lambda da, db, a, b: (
            (G(a) @ G(b)).inverse() @ (G(a) @ E(da)) @ (G(b) @ E(db))
        ).log(),
        "between": lambda da, db, a, b: (
            (G(a).inverse() @ G(b)).inverse() @ (G(a) @ E(da)).inverse() @ (G(b) @ E(db))
        ).log(),
        "rminus": lambda da, db, a, b: ((G(a) @ E(da)).inverse() @ (G(b) @ E(db))).log(),
        "rplus": lambda da, dx, a, x: ((G(a) @ E(x)).inverse() @ (G(a) @ E(da)) @ E(x + dx)).log(),
        "apply": lambda dT, dp, T, p: (G(T) @ E(dT)) @ (p + dp),
    }
    f, two = maps[case], len(CASES[case][2]) == 2

    def jac(*x):
        zero = jnp.zeros((G.tangent_dim,), x[0].dtype)
        zeros = [zero, jnp.zeros_like(x[-1]) if case == "apply" else zero]
        if two:
            return jax.jacfwd(lambda d1, d2: f(d1, d2, *x), argnums=(0, 1))(*zeros)
        return jax.jacfwd(lambda d: f(d, *x))(zeros[0])

    return jax.vmap(jac)


def make_inputs(group: str, case: str, n: int, seed: int) -> tuple:
    """float64 numpy inputs (x64 on, for ``sample_uniform`` in float64)."""
    G, (dim, rot, space, _) = getattr(jaxlie_geo, group), LAYOUT[group]
    rng = np.random.default_rng([seed, GROUPS.index(group), list(CASES).index(case), n])
    key = jax.random.PRNGKey(int(rng.integers(0, 2**31 - 1)))
    out = []
    for kind in CASES[case][2]:
        if kind == "t":
            xi = rng.normal(size=(n, dim))
            if rot.stop - rot.start == 1:  # SO2 / SE2: a signed angle
                xi[:, rot] = rng.uniform(-3.0, 3.0, size=(n, 1))
            else:
                norm = np.linalg.norm(xi[:, rot], axis=-1, keepdims=True)
                xi[:, rot] *= rng.uniform(0.0, 3.0, size=(n, 1)) / np.maximum(norm, 1e-12)
            out.append(xi)
        elif kind == "e":
            key, sub = jax.random.split(key)
            out.append(np.asarray(G.sample_uniform(sub, (n,), dtype=jnp.float64).parameters()))
        else:
            out.append(rng.normal(size=(n, space)))
    return tuple(out)


def max_abs_diff(a, b) -> float:
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    if len(la) != len(lb) or any(np.shape(x) != np.shape(y) for x, y in zip(la, lb)):
        return float("inf")
    d = [np.abs(np.asarray(x, np.float64) - np.asarray(y, np.float64)) for x, y in zip(la, lb)]
    return max((float(np.max(np.nan_to_num(x, nan=np.inf))) for x in d if x.size), default=0.0)


def main(argv=None) -> int:
    p = C.parser(__doc__, "100000", "1000", groups=GROUPS, cases=tuple(CASES))
    args = C.parse(p, argv)
    timed64, dtype = args.dtype == "float64", jnp.dtype(args.dtype)
    info = C.machine_info("benchmarks.jacobians", dtype=args.dtype)
    info.pop("jaxlie", None)
    results, skipped, index = [], [], 0
    for group in args.groups:
        for case in args.cases:
            jax.config.update("jax_enable_x64", True)
            probe = [jnp.asarray(x) for x in make_inputs(group, case, 16, args.seed + 12345)]
            leaves = jax.tree_util.tree_leaves(jax.jit(make_ours(group, case))(*probe))
            if all(np.array_equal(x, np.broadcast_to(x[:1], x.shape)) for x in leaves):
                skipped.append({"group": group, "case": case})  # a constant Jacobian
                continue
            for n in args.sizes:
                jax.config.update("jax_enable_x64", True)
                x64 = make_inputs(group, case, n, args.seed)
                jax.config.update("jax_enable_x64", timed64)
                x = tuple(jnp.asarray(a.astype(dtype)) for a in x64)
                sides = [(make_ours(group, case), x), (make_autodiff(group, case), x)]
                r, outs = C.compare(sides, n, args, index, 3 if args.quick else 5, 1.0)
                index += 1
                r["max_abs_diff_timed_dtype"] = diff = max_abs_diff(*outs)
                if not timed64:
                    jax.config.update("jax_enable_x64", True)
                    x = [jnp.asarray(a) for a in x64]
                    diff = max_abs_diff(*(jax.jit(f)(*x) for f, _ in sides))
                    jax.config.update("jax_enable_x64", False)
                jacobian, mapping, _ = CASES[case]
                r.update(group=group, case=case, jacobian=jacobian, map=mapping, n=n)
                r.update(dtype=args.dtype, max_abs_diff_float64=diff)
                results.append(r)
                print(group, case, n, f"{r['ratio']:.2f}", f"{diff:.1e}", flush=True)
    data = {"machine": info, "results": results, "skipped_constant": skipped}
    print("\n".join(jacobians_table(data)))
    save(f"jacobians-{args.dtype}", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
