"""Speed of Sim3 and SE23 against the matrix computations that define them.

jaxlie has neither group, so each operation is timed (``common.compare``) against a
reference built from jax alone on the group's matrices (``make_reference``; none for log
and grad, which need a matrix logarithm: they are checked against log(exp ξ) = ξ and the
gradient 2ξ). The method is on the results page (``methods.md``: extended-groups).

Usage:
  python -m benchmarks.extended_groups [--save]      # float32, N = 10^3 and 10^6
  python -m benchmarks.extended_groups --quick       # smoke test: N = 100, 3 repeats
  python -m benchmarks.extended_groups --groups SE23 --ops exp,jac_right --sizes 1000
"""

from __future__ import annotations

import sys

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import expm

import jaxlie_geo
from benchmarks import common as C
from benchmarks.report import extended_groups_table, save

GROUPS = ("Sim3", "SE23")
OPS = ("exp", "log", "compose", "apply", "jac_right", "grad")
#: The homogeneous coordinates a point is completed with for the matrix reference of apply.
HOMOGENEOUS = {"Sim3": (1.0,), "SE23": (1.0, 0.0)}
#: The references as the raw file records them.
REFERENCES = {
    "exp": "vmap(jax.scipy.linalg.expm)(G.hat(xi))",
    "compose": "A @ B (as_matrix of both, precomputed)",
    "apply": "M @ homogeneous(x), first three rows",
    "jac_right": "vmap: columns vee(inv(E) @ jvp(expm∘hat, xi, e_k)), E = expm(hat xi)",
}


def make_ours(G, op: str):
    if op == "grad":
        return jax.grad(lambda xi: jnp.sum(G.exp(xi).log() ** 2))
    return {
        "exp": lambda xi: G.exp(xi).parameters(),
        "log": lambda p: G(p).log(),
        "compose": lambda pa, pb: (G(pa) @ G(pb)).parameters(),
        "apply": lambda p, pts: G(p) @ pts,
        "jac_right": G.jac_right,
    }[op]


def make_reference(G, group: str, op: str):
    """The matrix computation ``op`` stands for, or None where jax has none (log, grad)."""
    if op == "exp":
        return lambda xi: jax.vmap(expm)(G.hat(xi))
    if op == "compose":
        return jnp.matmul
    if op == "apply":
        hom = HOMOGENEOUS[group]

        def apply(m, pts):
            tail = jnp.broadcast_to(jnp.asarray(hom, pts.dtype), (*pts.shape[:-1], len(hom)))
            return jnp.einsum("...ij,...j->...i", m, jnp.concatenate([pts, tail], -1))[..., :3]

        return apply
    if op == "jac_right":

        def one(xi):
            # J_r(ξ) δ = vee(E⁻¹ d/dε expm(hat(ξ + ε δ))), E = expm(hat ξ): column k is a jvp
            # through expm in the direction e_k (E itself the shared primal).
            f = lambda y: expm(G.hat(y))
            eye = jnp.eye(G.tangent_dim, dtype=xi.dtype)
            E, dE = jax.vmap(lambda d: jax.jvp(f, (xi,), (d,)), out_axes=(None, 0))(eye)
            return G.vee(jnp.linalg.inv(E) @ dE).T

        return jax.vmap(one)
    return None


def make_inputs(G, group: str, op: str, n: int, dtype, seed: int):
    """(ours' inputs, the reference's or None, the tangents): rotation angles uniform in
    (0, 2.8) rad, Sim3's log-scale in (−1, 1); the reference of compose and apply gets the
    elements' matrices."""
    rng = np.random.default_rng([seed, GROUPS.index(group), OPS.index(op), n])

    def tangent():
        xi = rng.normal(size=(n, G.tangent_dim))
        norm = np.linalg.norm(xi[:, 3:6], axis=-1, keepdims=True)
        xi[:, 3:6] *= rng.uniform(0.0, 2.8, size=(n, 1)) / np.maximum(norm, 1e-12)
        if group == "Sim3":
            xi[:, 6] = rng.uniform(-1.0, 1.0, size=n)
        return jnp.asarray(xi, dtype)

    params = jax.jit(lambda x: G.exp(x).parameters())
    matrix = jax.jit(lambda p: G(p).as_matrix())
    xi = tangent()
    if op in ("exp", "jac_right"):
        ours, ref = (xi,), (xi,)
    elif op in ("log", "grad"):
        ours, ref = ((params(xi),) if op == "log" else (xi,)), None
    elif op == "compose":
        pa, pb = params(xi), params(tangent())
        ours, ref = (pa, pb), (matrix(pa), matrix(pb))
    else:
        p, pts = params(xi), jnp.asarray(rng.normal(size=(n, 3)), dtype)
        ours, ref = (p, pts), (matrix(p), pts)
    return jax.block_until_ready((ours, ref, xi))


def check(G, op: str, ours, ref, xi) -> float | None:
    """Ours against the reference (exp and compose through ``as_matrix``) or the identity."""
    if op in ("log", "grad"):
        return C.max_rel_diff(ours, xi if op == "log" else 2.0 * xi)
    if ref is None:
        return None
    if op in ("exp", "compose"):
        ours = jax.jit(lambda p: G(p).as_matrix())(ours)
    return C.max_rel_diff(ours, ref)


def main(argv=None) -> int:
    p = C.parser(__doc__, "1000,1000000", "100", groups=GROUPS, ops=OPS)
    args = C.parse(p, argv)
    info = C.machine_info("benchmarks.extended_groups", dtype=args.dtype)
    info.pop("jaxlie", None)
    results, index = [], 0
    for group in args.groups:
        G = getattr(jaxlie_geo, group)
        for op in args.ops:
            for n in args.sizes:
                ours_in, ref_in, xi = make_inputs(G, group, op, n, jnp.dtype(args.dtype), args.seed)
                ref = make_reference(G, group, op)
                r, outs = C.compare([(make_ours(G, op), ours_in), (ref, ref_in)], n, args, index)
                index += 1
                r.update(group=group, op=op, n=n, dtype=args.dtype, reference=REFERENCES.get(op))
                r["reference_note"] = r.pop("ref_note")
                r["max_rel_diff"] = check(G, op, *outs, xi)
                results.append(r)
                print(group, op, n, C.fmt_ns(r["ours_ns_per_elem"]), r["ratio"], flush=True)
    data = {"machine": info, "results": results}
    print("\n".join(extended_groups_table(data)))
    save(f"extended-groups-{args.dtype}", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
