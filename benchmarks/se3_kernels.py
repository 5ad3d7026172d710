"""SE3 exp/log: the textbook V-matrix forms against the axis-split forms.

The translation part of SE3's exp is t = V(ω) v. The textbook form, v + F1 ω×v + F2 ω×(ω×v)
(Barfoot, *State Estimation for Robotics* (2017), eq. 7.82), cancels beyond π; the axis-split
form splits v along and across the rotation axis, F0 v + F1 ω×v + F2 (ω·v) ω (Zhang, *A
Geometric Introduction to Lie Theory* (2022), §8.4, with ω = θ·axis), and so does the log's
inverse (§9). Both are in jaxlie_geo/_se3.py (``exp_translation``/``log_translation``,
``form=``); this script times full SE3 exp and log built on each, interleaved in one process,
and measures their worst error beyond π (exp) and near π (log) against a float64 reference, in
float32. The results and the choice: docs/design/se3-kernel-forms.md.

    python -m benchmarks.se3_kernels [--n 1048576] [--repeats 21]
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxlie_geo import _se3, _so3


def se3_exp(xi, form):
    v, w = xi[..., :3], xi[..., 3:]
    half = _so3.exp_half_angle(w)
    t = _se3.exp_translation(v, w, form, half)
    return jnp.concatenate([_so3.exp_quaternion(w, half), t], axis=-1)


def se3_log(p, form):
    u, s, h = _so3.log_quaternion_parts(p[..., :4])
    v = _se3.log_translation(p[..., 4:], u, s, h, form)
    return jnp.concatenate([v, s[..., None] * u], axis=-1)


def median_ns(fns, n, repeats):
    times = [[] for _ in fns]
    for f in fns:
        jax.block_until_ready(f())
    for _ in range(repeats):
        for i, f in enumerate(fns):
            t0 = time.perf_counter()
            jax.block_until_ready(f())
            times[i].append(time.perf_counter() - t0)
    return [float(np.median(t)) / n * 1e9 for t in times]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=21)
    args = ap.parse_args()
    key = jax.random.key(0)
    xi = jax.random.normal(key, (args.n, 6), jnp.float32)
    params = se3_exp(xi, "textbook")
    forms = ("textbook", "axis_split")
    exps = [jax.jit(lambda x, f=f: se3_exp(x, f)) for f in forms]
    logs = [jax.jit(lambda p, f=f: se3_log(p, f)) for f in forms]
    t_exp = median_ns([lambda f=f: f(xi) for f in exps], args.n, args.repeats)
    t_log = median_ns([lambda f=f: f(params) for f in logs], args.n, args.repeats)

    # Accuracy in float32 against the same formulas in float64 (x64 on for the reference).
    jax.config.update("jax_enable_x64", True)
    rng = np.random.default_rng(0)
    w = rng.normal(size=(4096, 3))
    w *= (rng.uniform(np.pi, 10 * np.pi, 4096) / np.linalg.norm(w, axis=1))[:, None]
    v = rng.normal(size=(4096, 3)) * 1e3
    x32 = np.concatenate([v, w], 1).astype(np.float32)
    ref = np.asarray(se3_exp(jnp.asarray(x32, jnp.float64), "textbook"))
    wl = rng.normal(size=(4096, 3))
    wl *= ((np.pi - 10 ** rng.uniform(-6, -2, 4096)) / np.linalg.norm(wl, axis=1))[:, None]
    p64 = se3_exp(jnp.asarray(np.concatenate([v, wl], 1)), "axis_split")
    p32 = np.asarray(p64).astype(np.float32)
    ref_log = np.asarray(se3_log(jnp.asarray(p32, jnp.float64), "axis_split"))
    eps = np.finfo(np.float32).eps

    def ulp(got, ref):
        return float(np.max(np.abs(got - ref).max(1) / (eps * np.maximum(1, np.abs(ref).max(1)))))

    err_exp = [ulp(np.asarray(se3_exp(jnp.asarray(x32), f))[:, 4:], ref[:, 4:]) for f in forms]
    err_log = [ulp(np.asarray(se3_log(jnp.asarray(p32), f))[:, :3], ref_log[:, :3]) for f in forms]
    print(
        f"SE3 kernels, float32, N = {args.n}, {jax.devices()[0].platform}, median of {args.repeats}"
    )
    print(
        "| form | exp ns/elem | log ns/elem | exp translation, θ in [π, 10π], |v| = 1e3 (ulp) "
        "| log v, θ in π − [1e-6, 1e-2] (ulp) |"
    )
    print("|---|--:|--:|--:|--:|")
    for i, f in enumerate(forms):
        print(f"| {f} | {t_exp[i]:.1f} | {t_log[i]:.1f} | {err_exp[i]:.1f} | {err_log[i]:.1f} |")


if __name__ == "__main__":
    main()
