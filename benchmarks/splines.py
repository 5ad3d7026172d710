"""Speed of the cumulative B-splines' closed-form derivatives and Jacobians against autodiff.

One SE3 spline of 100 control points, degrees 3 and 5, evaluated at N times given to both
sides as the same ``SplineTime``; each benchmark is timed by ``common.compare`` against its
autodiff reference (``make_reference``). The method is on the results page (``methods.md``:
splines). Derivatives at N = 10³ and 10⁶, Jacobians at 10³, 10⁴ and 10⁶ (``--sizes`` sets
both); a side that would not fit in memory is compiled but not run.

Usage:
  python -m benchmarks.splines [--save]           # float32, degrees 3 and 5
  python -m benchmarks.splines --quick            # smoke test: N = 100, 3 repeats
  python -m benchmarks.splines --benchmarks derivatives --degrees 3 --sizes 1000
"""

from __future__ import annotations

import sys

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import common as C
from benchmarks.report import save, splines_table
from jaxlie_geo import SE3, splines

BENCHMARKS = ("derivatives", "jacobians")
SIZES = {"derivatives": (1000, 1000000), "jacobians": (1000, 10000, 1000000)}
CONTROL_POINTS, DT = 100, 0.1


def make_spline(degree: int, dtype, seed: int):
    """A random walk of SE3 control points: steps with standard normal translations times
    0.3 and rotation angles uniform in (0, 0.5) rad."""
    rng = np.random.default_rng([seed, degree])
    xi = rng.normal(size=(CONTROL_POINTS, 6)) * 0.3
    axis = rng.normal(size=(CONTROL_POINTS, 3))
    xi[:, 3:] = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    xi[:, 3:] *= rng.uniform(0.0, 0.5, size=(CONTROL_POINTS, 1))
    walk = lambda T, A: (T @ A, (T @ A).parameters())
    steps = SE3.exp(jnp.asarray(xi, dtype))
    _, params = jax.jit(lambda s: jax.lax.scan(walk, SE3.identity(dtype=dtype), s))(steps)
    return splines.Spline(SE3(params), degree=degree, t0=0.0, dt=DT)


def _qmul(a, b):
    """Quaternion product (w, x, y, z)."""
    w1, v1, w2, v2 = a[..., :1], a[..., 1:], b[..., :1], b[..., 1:]
    w = w1 * w2 - jnp.sum(v1 * v2, axis=-1, keepdims=True)
    return jnp.concatenate([w, w1 * v2 + w2 * v1 + jnp.cross(v1, v2)], axis=-1)


def make_ours(benchmark: str):
    if benchmark == "derivatives":

        def derivatives(spline, seg, frac):
            ev = spline.evaluate(splines.SplineTime(seg, frac), 2)
            return ev.value.parameters(), ev.velocity, ev.acceleration

        return derivatives

    def jacobians(spline, seg, frac):
        jac = spline.jacobians(splines.SplineTime(seg, frac))
        return jac.value, jac.velocity, jac.acceleration

    return jacobians


def make_reference(benchmark: str):
    if benchmark == "derivatives":

        def derivatives(spline, seg, frac):
            # (q, p) and two derivatives in the fraction u by forward mode twice, then SE3's
            # kinematics ω = (Rᵀṗ, 2 vec(q̄ q̇)), dω/dt = (Rᵀp̈ − ω_rot × Rᵀṗ, 2 vec(q̄ q̈)).
            f = lambda u: spline(splines.SplineTime(seg, u)).parameters()
            one = jnp.ones_like(frac)
            (x, dx), (_, ddx) = jax.jvp(lambda u: jax.jvp(f, (u,), (one,)), (frac,), (one,))
            Rt = SE3(x).rotation().inverse()
            conj = x[..., :4] * jnp.asarray([1, -1, -1, -1], x.dtype)
            w_rot = 2 * _qmul(conj, dx[..., :4])[..., 1:]  # q̄q = 1: no q̇̄ q̇ term
            dw_rot = 2 * _qmul(conj, ddx[..., :4])[..., 1:]
            v = Rt @ dx[..., 4:]
            dv = Rt @ ddx[..., 4:] - jnp.cross(w_rot, v)
            h = jnp.asarray(spline.dt, frac.dtype)
            return x, jnp.concatenate([v, w_rot], -1) / h, jnp.concatenate([dv, dw_rot], -1) / h**2

        return derivatives

    def jacobians(spline, seg, frac):
        k, p = spline.order, spline.control_points.parameters()

        def moved(delta, s, u):  # delta (k, 6) on the control points s … s + k − 1
            local = SE3(p[s + jnp.arange(k)]) @ SE3.exp(delta)
            alone = splines.Spline(local, degree=spline.degree, t0=spline.t0, dt=spline.dt)
            ev = alone.evaluate(splines.SplineTime(jnp.zeros((), jnp.int32), u), 2)
            r = (jax.lax.stop_gradient(ev.value).inverse() @ ev.value).log()  # log(T₀⁻¹ T(δ))
            return r, ev.velocity, ev.acceleration

        zero = jnp.zeros((k, 6), frac.dtype)
        jac = jax.vmap(jax.jacfwd(moved), in_axes=(None, 0, 0))(zero, seg, frac)
        return tuple(jnp.moveaxis(x, 2, 1) for x in jac)  # (N, dim, k, dim) -> (N, k, dim, dim)

    return jacobians


def main(argv=None) -> int:
    p = C.parser(__doc__, "", "100", benchmarks=BENCHMARKS, degrees=(1, 2, 3, 4, 5))
    p.set_defaults(degrees="3,5")
    args = C.parse(p, argv)
    info = C.machine_info("benchmarks.splines", dtype=args.dtype)
    info.pop("jaxlie", None)
    dtype, results, index = jnp.dtype(args.dtype), [], 0
    for benchmark in args.benchmarks:
        sizes = args.sizes or SIZES[benchmark]
        for degree in args.degrees:
            for n in sizes:
                spline = make_spline(degree, dtype, args.seed)
                rng = np.random.default_rng([args.seed, index, n, degree])
                seg = jnp.asarray(rng.integers(0, spline.num_segments, size=n), jnp.int32)
                frac = jnp.asarray(rng.uniform(0.001, 0.999, size=n), dtype)
                x = (spline, seg, frac)
                r, outs = C.compare(
                    [(make_ours(benchmark), x), (make_reference(benchmark), x)], n, args, index
                )
                index += 1
                r["reference_note"] = r.pop("ref_note")
                r.update(benchmark=benchmark, group="SE3", degree=degree, n=n, dtype=args.dtype)
                r.update(control_points=CONTROL_POINTS, max_rel_diff=None)
                if None not in outs:
                    r["max_rel_diff"] = C.max_rel_diff(*outs)
                results.append(r)
                print(benchmark, degree, n, r["ours_ns_per_elem"], r["ratio"], flush=True)
    data = {"machine": info, "results": results}
    print("\n".join(splines_table(data)))
    save(f"splines-{args.dtype}", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
