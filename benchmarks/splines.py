"""Speed of the cumulative B-splines' closed-form derivatives and Jacobians against autodiff.

One SE3 spline of 100 control points (``jaxlie_geo.splines.Spline``), degrees 3 and 5, is
evaluated at N times; both sides get the same times as a ``SplineTime`` (segment, fraction)
computed before timing:

  benchmark    ours (jaxlie_geo)                    autodiff reference
  derivatives  spline.evaluate(t, 2): the value,    the value T(u) = spline(SplineTime(s, u))
               the body velocity ω and dω/dt from   differentiated twice in the fraction u by
               the recursions of Sommer et al.      nested forward mode (jax.jvp of jax.jvp,
               (2020)                               on the whole batch: T is elementwise in
                                                    the times), then SE3's kinematics of the
                                                    parameters (q, p): ω = (Rᵀṗ, 2 vec(q̄ q̇))
                                                    and dω/dt = (Rᵀp̈ − ω_rot × Rᵀṗ,
                                                    2 vec(q̄ q̈)), with d/dt = (1/Δt) d/du
  jacobians    spline.jacobians(t): the blocks of   vmap over the times of jax.jacfwd, in the
               the value, ω and dω/dt with          right perturbations δ ((degree + 1, 6)) of
               respect to right perturbations of    the control points the time depends on, of
               the degree + 1 control points the    (log(T₀⁻¹ T(δ)), ω(δ), dω/dt(δ)), T₀ the
               time depends on                      unperturbed value; T(δ), ω(δ), dω/dt(δ)
                                                    by spline.evaluate(·, 2) on those control
                                                    points alone, T_m exp(δ_m)

The derivatives' reference is the fastest autodiff of the value measured here: through the
4×4 matrices, ω = vee(T⁻¹ dT/dt) and dω/dt = vee(T⁻¹ d²T/dt² − (T⁻¹ dT/dt)²), it is 2 to 5
times slower on a CPU (XLA's small batched matrix products), and a vmap of the same nested
jvp per time is 10-40% slower than the batched form. The Jacobians' reference differentiates
the library's own evaluation (the recursions), on the local control points only, so that it
does not copy the whole spline per time.

Spline: T₀ = exp(ξ₀), T_{i+1} = T_i exp(ξ_{i+1}), the ξ_i with standard normal translations
times 0.3 and rotation angles uniform in (0, 0.5) rad about random axes; Δt = 0.1, t0 = 0.
Times: segments uniform over the spline's 100 − degree segments, fractions uniform in
(0.001, 0.999) (at 0 or 1 exactly, the clip in ``Spline.locate`` would halve the autodiff
derivative). Every output is checked outside the timing, in the timed dtype, against the
reference; the column ``max rel diff`` is max |ours − reference| / (1 + |reference|) over all
outputs (the value's parameters, ω and dω/dt; or the three Jacobians).

Timing is ``extended_groups.py``'s (its helpers are imported): every function is jitted and
compiled ahead (trace + lower + XLA compile, reported per side), inputs are on the device,
every call blocks until its result is ready; repetitions of the two sides are interleaved,
each about 10 ms (a tenth of the slower side's call, up to 1 s, where that is longer) or one
call; the time per element is the median over repetitions divided by N, the speed-up
reference / ours the median of the paired per-repetition ratios with their inter-quartile
range. Repetitions: at least 3 (2 where a call takes more than 5 s) within a time budget per
case. A side whose compiled program (arguments, output, temporaries, from XLA's buffer
assignment) would take more than 80% of the available memory is compiled but not run: the
Jacobians' reference needs ~27 kB per time at degree 3 and ~66 kB at degree 5 in float32,
ours 11 and 22 kB, so at N = 10^6 neither fits a machine with a few GB free. The Jacobians
are therefore also measured at N = 10^4. The raw file records both sides' footprints.

With --save the results replace raw/<machine>/splines-<dtype>.json and the results page
(RESULTS.md) is regenerated (report.py).

Usage:
  python -m benchmarks.splines                    # float32, degrees 3 and 5
  python -m benchmarks.splines --save             # ... saved, page regenerated
  python -m benchmarks.splines --dtype float64    # float64 (enables jax x64)
  python -m benchmarks.splines --quick            # smoke test: N = 100, 3 repeats
  python -m benchmarks.splines --benchmarks derivatives --degrees 3 --sizes 1000

Sizes: derivatives at N = 10^3 and 10^6, Jacobians at 10^3, 10^4 and 10^6 (--sizes sets both).
On a 2-core CPU the default float32 run takes about 5 minutes, most of it in the Jacobians'
reference at N = 10^4 (~2 s per call at degree 5) and in compiling the programs at 10^6.
"""

from __future__ import annotations

import importlib
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import common as C
from benchmarks.common import fmt_n
from benchmarks.extended_groups import finish, max_rel_diff
from benchmarks.report import splines_table

BENCHMARKS = ("derivatives", "jacobians")
DEGREES = (3, 5)
SIZES = {"derivatives": (1000, 1000000), "jacobians": (1000, 10000, 1000000)}
GROUP = "SE3"
NUM_CONTROL_POINTS = 100
T0, DT = 0.0, 0.1

# The expressions, as the raw file records them (report.py prints its own method text).
OURS = {
    "derivatives": "spline.evaluate(SplineTime(s, u), 2): value, velocity, acceleration",
    "jacobians": "spline.jacobians(SplineTime(s, u)): value, velocity, acceleration blocks",
}
REFERENCES = {
    "derivatives": "jvp(jvp(u -> spline(SplineTime(s, u)).parameters())), batched; "
    "ω = (Rᵀṗ, 2 vec(q̄ q̇))/Δt, dω/dt = (Rᵀp̈ − ω_rot × Rᵀṗ, 2 vec(q̄ q̈))/Δt²",
    "jacobians": "vmap(jacfwd(δ -> (log(T₀⁻¹ T(δ)), ω(δ), dω/dt(δ)))), δ: (degree + 1, 6) "
    "right perturbations of the local control points, evaluate(·, 2) of those alone",
}


def parse_args(argv=None):
    p = C.parser(
        "Benchmark the splines' derivatives and Jacobians against autodiff.",
        {"benchmarks": BENCHMARKS},
        sizes=None,
        sizes_text="derivatives 1000,1000000; jacobians 1000,10000,1000000",
        quick="100",
        min_repeats=3,
    )
    p.add_argument("--degrees", default=",".join(map(str, DEGREES)), help="degrees, 1 to 5")
    args = C.parse(p, argv)
    args.sizes = {b: list(args.sizes or SIZES[b]) for b in BENCHMARKS}
    degrees = C.parse_choices(p, args.degrees, ("1", "2", "3", "4", "5"), "degree")
    args.degrees = [int(d) for d in degrees]
    return args


# --------------------------------------------------------------------------------------
# The spline and the times
# --------------------------------------------------------------------------------------


def make_spline(geo, degree: int, dtype, seed: int):
    """The benchmarked spline: a random walk of NUM_CONTROL_POINTS SE3 control points."""
    G = getattr(geo, GROUP)
    rng = np.random.default_rng([seed, degree])
    xi = rng.normal(size=(NUM_CONTROL_POINTS, 6)) * 0.3
    axis = rng.normal(size=(NUM_CONTROL_POINTS, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    xi[:, 3:] = axis * rng.uniform(0.0, 0.5, size=(NUM_CONTROL_POINTS, 1))

    @jax.jit
    def walk(xi):
        steps = G.exp(xi)

        def step(T, A):
            T = T @ A
            return T, T.parameters()

        _, params = jax.lax.scan(step, G.identity(dtype=xi.dtype), steps)
        return params

    cp = G(walk(jnp.asarray(xi, dtype)))
    return geo.splines.Spline(cp, degree=degree, t0=T0, dt=DT)


def make_times(spline, n: int, dtype, seed: int, index: int):
    """(segment, fraction) of n times, device arrays."""
    rng = np.random.default_rng([seed, index, n, spline.degree])
    seg = rng.integers(0, spline.num_segments, size=n)
    frac = rng.uniform(0.001, 0.999, size=n)
    return jax.block_until_ready((jnp.asarray(seg, jnp.int32), jnp.asarray(frac, dtype)))


# --------------------------------------------------------------------------------------
# The two sides. Every function maps (spline, segment, fraction) -> arrays. Fresh closures
# per case, so that compile times are not cached.
# --------------------------------------------------------------------------------------


def _qmul(a, b):
    """Quaternion product (w, x, y, z)."""
    w1, v1, w2, v2 = a[..., :1], a[..., 1:], b[..., :1], b[..., 1:]
    w = w1 * w2 - jnp.sum(v1 * v2, axis=-1, keepdims=True)
    return jnp.concatenate([w, w1 * v2 + w2 * v1 + jnp.cross(v1, v2)], axis=-1)


def make_ours(geo, benchmark: str):
    SplineTime = geo.splines.SplineTime
    if benchmark == "derivatives":

        def derivatives(spline, seg, frac):
            ev = spline.evaluate(SplineTime(seg, frac), 2)
            return ev.value.parameters(), ev.velocity, ev.acceleration

        return derivatives
    if benchmark == "jacobians":

        def jacobians(spline, seg, frac):
            jac = spline.jacobians(SplineTime(seg, frac))
            return jac.value, jac.velocity, jac.acceleration

        return jacobians
    raise ValueError(benchmark)


def make_reference(geo, benchmark: str):
    G = getattr(geo, GROUP)
    splines = geo.splines
    if benchmark == "derivatives":

        def derivatives(spline, seg, frac):
            # The value's parameters (q, p) and their first two derivatives in the fraction u,
            # by forward mode twice; every time is independent, so the batch is one call.
            f = lambda u: spline(splines.SplineTime(seg, u)).parameters()
            one = jnp.ones_like(frac)
            first = lambda u: jax.jvp(f, (u,), (one,))
            (x, dx), (_, ddx) = jax.jvp(first, (frac,), (one,))
            q, dq, ddq = x[..., :4], dx[..., :4], ddx[..., :4]
            Rt = G(x).rotation().inverse()
            conj = q * jnp.asarray([1, -1, -1, -1], q.dtype)
            w_rot = 2 * _qmul(conj, dq)[..., 1:]  # d/du q̄q = 0 for a unit q: no q̇̄ q̇ term
            dw_rot = 2 * _qmul(conj, ddq)[..., 1:]
            v = Rt @ dx[..., 4:]
            dv = Rt @ ddx[..., 4:] - jnp.cross(w_rot, v)
            h = jnp.asarray(spline.dt, frac.dtype)
            w = jnp.concatenate([v, w_rot], axis=-1) / h
            dw = jnp.concatenate([dv, dw_rot], axis=-1) / h**2
            return x, w, dw

        return derivatives
    if benchmark == "jacobians":

        def jacobians(spline, seg, frac):
            k = spline.order
            p = spline.control_points.parameters()

            def moved(delta, s, u):  # delta: (k, 6) on control points s … s + k − 1
                local = G(p[s + jnp.arange(k)]) @ G.exp(delta)
                alone = splines.Spline(local, degree=spline.degree, t0=spline.t0, dt=spline.dt)
                ev = alone.evaluate(splines.SplineTime(jnp.zeros((), jnp.int32), u), 2)
                T = ev.value
                # log(T₀⁻¹ T(δ)), T₀ the value at δ = 0: the primal of T itself
                r = (jax.lax.stop_gradient(T).inverse() @ T).log()
                return r, ev.velocity, ev.acceleration

            zero = jnp.zeros((k, G.tangent_dim), frac.dtype)
            jac = jax.vmap(jax.jacfwd(moved), in_axes=(None, 0, 0))(zero, seg, frac)
            # (N, dim, k, dim) -> (N, k, dim, dim), ours' layout
            return tuple(jnp.moveaxis(x, 2, 1) for x in jac)

        return jacobians
    raise ValueError(benchmark)


# --------------------------------------------------------------------------------------
# Main benchmark
# --------------------------------------------------------------------------------------


def fits(compiled):
    """(footprint in bytes, None) when the program fits 80% of the available memory, else
    (footprint, note)."""
    mem = C.footprint_bytes(compiled)
    avail = C.available_bytes()
    if avail is not None and mem > 0.8 * avail:
        return mem, f"not run: needs {mem / 1e9:.1f} GB, {avail / 1e9:.1f} GB available"
    return mem, None


def bench_case(geo, benchmark, degree, n, args, dtype, index):
    spline = make_spline(geo, degree, dtype, args.seed)
    seg, frac = make_times(spline, n, dtype, args.seed, index)
    inputs = (spline, seg, frac)
    f_ours, f_ref = make_ours(geo, benchmark), make_reference(geo, benchmark)

    # Alternate the compile order between cases so neither side systematically goes first.
    if index % 2 == 1:
        c_ref, comp_ref = C.compile_fn(f_ref, inputs)
    c_ours, comp_ours = C.compile_fn(f_ours, inputs)
    if index % 2 == 0:
        c_ref, comp_ref = C.compile_fn(f_ref, inputs)

    # A side that would not fit in memory is not run (the Jacobians at 10^6).
    mem_ours, ours_note = fits(c_ours)
    mem_ref, ref_note = fits(c_ref)

    # Warm-up executions, timed only to size the measurements; their outputs are checked.
    sides, outs = [], []
    for c, note in ((c_ours, ours_note), (c_ref, ref_note)):
        if note is None:
            out, first = C.timed_call(c, inputs)
            sides.append((c, inputs, first))
            outs.append(out)
    diff = None
    if len(outs) == 2:
        diff = max(max_rel_diff(a, b) for a, b in zip(outs[0], outs[1]))
    del outs

    times = []
    if sides:
        target_s = 0.002 if args.quick else 0.01
        budget_s = 0.1 if args.quick else 1.5
        repeats = 3 if (args.quick and args.repeats is None) else args.repeats
        times = C.measure(sides, repeats, target_s, budget_s, min_repeats=3)

    r = {
        "benchmark": benchmark,
        "group": GROUP,
        "degree": degree,
        "n": n,
        "dtype": args.dtype,
        "control_points": NUM_CONTROL_POINTS,
        "ours_ns_per_elem": None,
        "ref_ns_per_elem": None,
        "ratio": None,
        "ratio_q1": None,
        "ratio_q3": None,
        "compile_ours_ms": comp_ours * 1e3,
        "compile_ref_ms": comp_ref * 1e3,
        "repeats": len(times[0]) if times else 0,
        "ours": OURS[benchmark],
        "reference": REFERENCES[benchmark],
        "ours_note": ours_note,
        "reference_note": ref_note,
        "max_rel_diff": diff,
        "memory_ours_mb": mem_ours / 1e6,
        "memory_ref_mb": mem_ref / 1e6,
    }
    if ours_note is None:
        r["ours_ns_per_elem"] = statistics.median(times[0]) * 1e9 / n
    if ref_note is None:
        r["ref_ns_per_elem"] = statistics.median(times[-1]) * 1e9 / n
    if ours_note is None and ref_note is None:
        st = C.paired_stats(times[0], times[1])
        r.update(ratio=st["ratio"], ratio_q1=st["ratio_q1"], ratio_q3=st["ratio_q3"])
    return r


def global_warmup(geo, dtype):
    """Pay one-time process costs (backend init, first compile) before measuring anything."""
    G = getattr(geo, GROUP)
    x = jnp.zeros((1, G.tangent_dim), dtype=dtype)
    jax.block_until_ready(jax.jit(lambda x: G.exp(x).parameters())(x))


# --------------------------------------------------------------------------------------
# Reporting
# --------------------------------------------------------------------------------------


def main(argv=None):
    args = parse_args(argv)
    if args.dtype == "float64":
        jax.config.update("jax_enable_x64", True)
    dtype = jnp.float64 if args.dtype == "float64" else jnp.float32

    geo = importlib.import_module("jaxlie_geo")
    importlib.import_module("jaxlie_geo.splines")
    info = C.machine_info("benchmarks.splines", dtype=args.dtype)
    info.pop("jaxlie", None)
    print("# Cumulative B-splines: closed forms against autodiff")
    for k, v in info.items():
        print(f"  {k:13s} {v}")
    print(flush=True)

    t_start = time.perf_counter()
    global_warmup(geo, dtype)

    results = []
    index = 0
    for benchmark in args.benchmarks:
        for degree in args.degrees:
            for n in args.sizes[benchmark]:
                r = bench_case(geo, benchmark, degree, n, args, dtype, index)
                index += 1
                results.append(r)
                print(f"{benchmark} degree {degree} N={fmt_n(n)}: {C.progress_text(r)}", flush=True)

    elapsed = time.perf_counter() - t_start
    finish(
        results,
        args,
        info,
        elapsed,
        f"splines-{args.dtype}",
        lambda r: f"{r['benchmark']} degree {r['degree']} N={fmt_n(r['n'])}",
        "autodiff",
        splines_table,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
