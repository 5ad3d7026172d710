"""exp, log and the derivatives of log∘exp of every group against mpmath, in ulp.

Grid: rotation angle regimes {exactly 0, 1e-30…1e-6, 1e-5…0.1, 0.1…3, π−1e-2…π−1e-7
(float32: …π−2e-6), and for exp only π…10π and 10π…1e4} × translation norms {0, 1e-6, 1, 1e3}
(SE2, SE3, Sim3, SE23; SE23's velocity norm cycles through the same four within each cell)
× {float32, float64} × {SO2, SE2, SO3, SE3, Sim3, SE23}, N_PER random samples per cell
(fixed seed; the band end points are always included). Sim3's log-scale σ is 0 at θ = 0
and 1e-3 ≤ |σ| ≤ 3 elsewhere, and Sim3 has six regimes of its own, joint in θ and σ: θ = 0
with 1e-8 ≤ |σ| ≤ 20; σ = 0 or 1e-30 ≤ |σ| ≤ 1e-4 at 0.1 ≤ θ ≤ 3.1; θ = r√ρ, |σ| = r/√ρ
for r ∈ {1e-3, 1e-5, 1e-8} and θ/|σ| = ρ from 1e-3 to 1e3 with both signs of σ; and
3 ≤ |σ| ≤ 20 at 1e-8 ≤ θ ≤ π − 1e-3 (``M._angles_sigmas``).

Measure (benchmarks/mpref.py has the details and the references): per output block,
ulp_err = ‖got − ref‖_∞ / (eps · max(1, ‖ref‖_∞)), the reference computed in mpmath at 60
digits from the float the function actually received (subnormals flushed, as XLA on CPU
does); log's input is a stored group element (the exact exp rounded to the dtype) and its
reference is the principal log of exactly that element. Bounds (``M.bound``): exp and
log ≤ 4 ulp, exp beyond π ≤ 4 + |θ|/2 ulp (the conditioning of its input);
d log(exp(x))/dx within 8 ulp of I and d² log(exp(x))/dx² within 64 ulp of 0, with the
entries of an output vector differentiated by ω (Sim3: also by σ) scaled by max(1, ‖v‖) of
that vector; derivatives only where the angle is below π, second derivatives in float64
only (``OPS_OF``: the checks that differentiate twice run in float64, as jaxlie's suite
does). Any non-finite value fails.
float32 runs with jax_enable_x64 off (no silent promotion can hide float32 rounding) and,
for exp and log, also with it on.

`python -m benchmarks.accuracy` prints the same measurement as a table, next to jaxlie.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from _diskcache import disk_cached
from conftest import SE_GROUPS

import jaxlie_geo
from benchmarks import mpref as M

N_PER = 64

OPS_OF = {"float32": tuple(op for op in M.OPS if op != "hess"), "float64": M.OPS}
"""The operations checked in each dtype: float32 values and first derivatives."""


@disk_cached
def _cases(group: str, dtype: str) -> M.Cases:
    return M.make_cases(group, dtype, n_per=N_PER, seed=0)


@functools.lru_cache(maxsize=None)
def _errors(group: str, dtype: str, op: str):
    """The errors of one operation over the grid (each compiled only by the cells that
    read it, so that a run without the slow cells compiles no second derivative)."""
    return M.evaluate(jaxlie_geo, _cases(group, dtype), (op,))


def _report(cases: M.Cases, result, op: str, regime: str, top: int = 5) -> str:
    errors, bound = result[op], cases.bound(op)
    idx = np.nonzero((cases.regime == regime) & ~np.isnan(errors))[0]
    order = idx[np.argsort(-(errors[idx] / bound[idx]), kind="stable")][:top]
    lines = [
        f"{cases.group}.{op} {cases.dtype} regime {regime} ({M.REGIME_TEXT[regime]}): worst cases:"
    ]
    for k in order:
        blocks = M.block_errors(cases, k, op, result)
        case = M.describe_case(cases, k, op)
        lines.append(f"  {M.fmt_ulp(float(errors[k]))} ulp (bound {bound[k]:.3g}) {blocks} {case}")
    return "\n".join(lines)


def test_references_are_exact():
    """The mpmath references agree with mpmath.expm of the hat matrix, the series with
    the closed forms at high precision, and log inverts exp (to < 1e-40)."""
    M.check_references()


def test_measure_is_exact():
    """Rounding the reference to the dtype scores ≤ 0.5 ulp; a reference moved by one
    eps·scale scores 1."""
    for dtype in M.DTYPES:
        c = _cases("SE3", dtype)
        got = c.exp_hi.astype(dtype)
        e = M.ulp_errors(got, c.exp_hi, c.exp_lo, M.EXP_BLOCKS["SE3"], dtype)
        assert np.all(e <= 0.5 + 1e-6), e.max()
        eps = float(np.finfo(dtype).eps)
        lo = np.zeros_like(c.exp_lo)  # reference hi + lo, got = hi: error |lo| / (eps·scale)
        lo[:, 0] = -eps * np.maximum(1.0, np.max(np.abs(c.exp_hi[:, :4]), axis=-1))
        e = M.ulp_errors(c.exp_hi, c.exp_hi, lo, M.EXP_BLOCKS["SE3"], dtype)
        assert np.allclose(e, 1.0, rtol=1e-6), (e.min(), e.max())


def test_sim3_grid_covers_the_joint_regimes():
    """Sim3's grid holds what its regimes promise: θ = |σ| = r and θ/|σ| from 1e-3 to 1e3 at
    r = 1e-3, 1e-5, 1e-8 with both signs of σ, σ = 0 and |σ| = 20 of both signs, θ = 0
    with σ ≠ 0, and θ within 1e-5 of π."""
    for dtype in M.DTYPES:
        c = _cases("Sim3", dtype)
        th, sg = c.theta, c.sigma
        for name, r in M.JOINT_SCALE.items():
            m = c.regime == name
            ratio = th[m] / np.abs(sg[m])
            assert np.isclose(ratio.min(), 1e-3, rtol=1e-5) and np.isclose(
                ratio.max(), 1e3, rtol=1e-5
            )
            both = np.isclose(th[m], r, rtol=1e-6) & np.isclose(np.abs(sg[m]), r, rtol=1e-6)
            assert set(np.sign(sg[m][both])) == {-1.0, 1.0}
        assert set(np.sign(sg[np.abs(sg) == 20.0])) == {-1.0, 1.0}
        small = sg[c.regime == "sigma_small"]
        assert np.count_nonzero(small == 0.0) >= 2 * len(M.SIZES)
        assert np.any((th == 0.0) & (np.abs(sg) > 0.0))
        assert np.pi - th[c.regime == "near_pi"].max() < 1e-5


CELLS = [
    (g, op, dt, r)
    for g in M.GROUPS
    for op in M.OPS
    for dt in M.DTYPES
    for r in M.regimes(g)
    if op in M.OPS_IN_REGIME[r] and op in OPS_OF[dt]
]


@pytest.mark.parametrize("group,op,dtype,regime", CELLS)
def test_accuracy(group, op, dtype, regime):
    """One cell of the grid: every case's error is within its bound (``M.bound``) of the
    mpmath reference, every value finite, the output in the input dtype."""
    cases = _cases(group, dtype)
    errors = _errors(group, dtype, op)
    assert errors[op + "_dtype"] == dtype
    m = cases.regime == regime
    e, bound = errors[op][m], cases.bound(op)[m]
    assert not np.any(np.isnan(e)) and len(e) > 0
    if not (np.all(np.isfinite(e)) and np.all(e <= bound)):
        pytest.fail(_report(cases, errors, op, regime), pytrace=False)


@pytest.mark.parametrize("group", M.GROUPS)
def test_float32_under_x64(group):
    """float32 inputs with jax_enable_x64 on (as in this test run) stay float32 and
    meet the same exp/log bounds."""
    import jax.numpy as jnp

    c = _cases(group, "float32")
    G = getattr(jaxlie_geo, group)
    with M.x64_for("float64"):  # x64 on, float32 data
        got_exp = G.exp(jnp.asarray(c.tangent)).parameters()
        m = c.mask("log")
        got_log = G(jnp.asarray(c.params[m])).log()
    assert got_exp.dtype == jnp.float32 and got_log.dtype == jnp.float32
    e_exp = M.ulp_errors(
        np.asarray(got_exp), c.exp_hi, c.exp_lo, M.EXP_BLOCKS[group], "float32", floor=c.exp_floor()
    )
    e_log = M.ulp_errors(
        np.asarray(got_log), c.log_hi[m], c.log_lo[m], M.LOG_BLOCKS[group], "float32"
    )
    for op, e, idx in (("exp", e_exp, np.arange(len(m))), ("log", e_log, np.nonzero(m)[0])):
        r = e / c.bound(op)[idx]
        k = int(idx[np.argmax(r)])
        if not float(r.max()) <= 1.0:
            pytest.fail(
                f"{group}.{op} float32 (x64 on), regime {c.regime[k]}: "
                f"{M.fmt_ulp(float(e.max()))} ulp at {M.describe_case(c, k, op)}",
                pytrace=False,
            )


def test_measure_catches_jaxlie_defects():
    """The harness is sensitive: jaxlie 1.5's known defects show up at their known size
    (SE3.exp at θ ≈ 1e-7, |v| = 1: ~1e8 ulp; d log(exp)/dx at a pure translation: 0.5)."""
    import jaxlie  # in the test extra: a missing jaxlie fails here, it is not skipped

    c = M.make_cases("SE3", "float64", n_per=4, seed=1)
    errors = M.evaluate(jaxlie, c, ops=("exp", "jac"))
    tiny = (c.regime == "tiny") & (c.size == 1.0)
    assert np.nanmax(errors["exp"][tiny]) > 1e6
    # jaxlie's ∂v/∂ω at ω = 0 is I + ½ v̂ instead of I: 0.5·‖v‖_∞/max(1, ‖v‖) after scaling.
    zero = (c.regime == "zero") & (c.size >= 1.0)
    off = errors["jac"][zero] * np.finfo(np.float64).eps
    assert np.all((off > 0.5 / np.sqrt(3) - 1e-9) & (off < 0.5 + 1e-9)), off


@pytest.mark.parametrize("dtype", M.DTYPES)
@pytest.mark.parametrize("group", [G.__name__ for G in SE_GROUPS])
def test_relative_pose_far_from_the_origin(group, dtype):
    """log(a⁻¹ b) of two poses ~10⁴ from the origin and ~1 apart, as ``manifold.rminus``,
    ``geodesic(a, b).tangent`` and ``motion.velocity_between(a, b, 1)`` form it, and
    ``between(a, b)``'s parameters, within 4 ulp
    (of max(1, |log|)) of mpmath at 60 digits, and ``interpolate(b, 1)`` returns b to within
    4 ulp of |t_b|. Forming a⁻¹b as a.inverse() @ b cancelled ε·|t_a|: 10⁴ ulp in float32."""
    import jax.numpy as jnp

    from jaxlie_geo import manifold, motion

    G = getattr(jaxlie_geo, group)
    rng = np.random.default_rng(11)
    n, d = 24, G.space_dim
    pa, pb = [], []
    for _ in range(n):
        xa = M._random_tangent(group, rng.uniform(0.0, 3.0), 1e4 * rng.uniform(0.5, 2.0), rng)
        xd = M._random_tangent(group, rng.uniform(0.0, 1.0), rng.uniform(0.1, 1.0), rng)
        a = [float(c) for c in np.asarray(M.exp_ref(group, xa), dtype=np.float64).astype(dtype)]
        delta = M.exp_ref(group, xd)
        b = np.asarray([float(c) for c in M.compose_ref(group, a, delta)]).astype(dtype)
        pa.append(a)
        pb.append([float(c) for c in b])
    pa, pb = np.asarray(pa, dtype), np.asarray(pb, dtype)
    assert np.all(np.linalg.norm(pa[:, -d:], axis=-1) > 4e3)
    ref = [M.log_ref(group, M.compose_ref(group, a, b, invert_a=True)) for a, b in zip(pa, pb)]
    hi, lo = M._dd(ref)
    with M.x64_for(dtype):
        A, B = G(jnp.asarray(pa)), G(jnp.asarray(pb))
        got = {
            "rminus": manifold.rminus(A, B),
            "geodesic": jaxlie_geo.geodesic(A, B).tangent,
            "velocity_between": motion.velocity_between(A, B, 1.0),
        }
        end = np.asarray(A.interpolate(B, 1.0).parameters(), np.float64)
        rel = np.asarray(jaxlie_geo.between(A, B).parameters(), np.float64)
    for name, g in got.items():
        e = M.ulp_errors(np.asarray(g), hi, lo, M.LOG_BLOCKS[group], dtype)
        assert float(e.max()) <= 4.0, f"{group}.{name} {dtype}: {float(e.max()):.1f} ulp"
    # the relative element itself, against its exact parameters
    rel_ref = [M.compose_ref(group, a, b, invert_a=True) for a, b in zip(pa, pb)]
    rhi, rlo = M._dd(rel_ref)
    e = M.ulp_errors(rel, rhi, rlo, M.EXP_BLOCKS[group], dtype)
    assert float(e.max()) <= 4.0, f"{group}.between {dtype}: {float(e.max()):.1f} ulp"
    eps = float(np.finfo(dtype).eps)
    err = np.abs(end - pb.astype(np.float64)) / np.linalg.norm(
        pb.astype(np.float64), axis=-1, keepdims=True
    )
    assert float(err.max()) <= 4 * eps, float(err.max()) / eps


@pytest.mark.parametrize("dtype", M.DTYPES)
def test_se3_exp_near_full_turns_with_v_perpendicular(dtype):
    """θ within 1e-3 of 2πk (k = 1..4) with v ⟂ ω, ‖v‖ ∈ {1, 10³}: there the translation
    F0 v + F1 ω×v + F2 (ω·v) ω is ~1e-4 ‖v‖ long and ω·v cancels. Its error stays within
    the conditioning bound of exp beyond π, 4 + |θ|/2 ulp of max(1, ‖v‖_∞) (one ulp of ω
    moves t by about ε‖v‖ here; ``benchmarks.mpref.Cases.exp_floor``). The grid's beyond-π draws
    near 2πk have v in a random direction, where ω·v does not cancel."""
    import jax.numpy as jnp
    from mpmath import mp

    rng = np.random.default_rng(12)
    xs = []
    for size in (1.0, 1e3):
        for k in rng.integers(1, 5, 32):
            w = M._unit(rng, 3) * (2 * np.pi * k + rng.uniform(-1e-3, 1e-3))
            v = np.cross(w, M._unit(rng, 3))
            xs.append(np.concatenate([size * v / np.linalg.norm(v), w]))
    x = M.flush(np.array(xs).astype(dtype))
    x[:, :3] -= (
        np.sum(x[:, :3] * x[:, 3:], -1, keepdims=True)
        * x[:, 3:]
        / np.sum(x[:, 3:] ** 2, -1, keepdims=True)
    )  # ⟂ again after rounding, to the dtype's precision
    with mp.workdps(M.DPS):
        hi, lo = M._dd([M.exp_ref("SE3", xi) for xi in x])
    with M.x64_for(dtype):
        got = np.asarray(jaxlie_geo.SE3.exp(jnp.asarray(x)).parameters())
    floor = np.ones((len(x), 2))
    floor[:, 1] = np.maximum(1.0, np.max(np.abs(x[:, :3].astype(np.float64)), axis=-1))
    e = M.ulp_errors(got, hi, lo, M.EXP_BLOCKS["SE3"], dtype, floor=floor)
    r = e / M.bound("exp", np.linalg.norm(x[:, 3:].astype(np.float64), axis=-1))
    assert r.max() <= 1.0, (e[np.argmax(r)], x[np.argmax(r)])


@pytest.mark.parametrize("dtype", M.DTYPES)
def test_se3_log_near_pi_with_long_translations(dtype):
    """θ ∈ [3.1, π], ‖t‖ = 10³: v = h t − ½ ω×t + G (ω·t) ω takes G θ² = 1 − h from h
    (``_se3.log_translation``'s ``far`` branch) where the series G·s² loses accuracy.
    Here it is ≤ 1.7 ulp; with the series throughout, 3.3. The grid's bound (4) cannot
    tell them apart, so this cell is held to 2.5."""
    import jax.numpy as jnp
    from mpmath import mp

    rng = np.random.default_rng(13)
    th = 3.1 + (np.pi - 3.1) * rng.random(256)
    x = np.stack([M._random_tangent("SE3", t, 1e3, rng) for t in th])
    with mp.workdps(M.DPS):
        exps = [M.exp_ref("SE3", xi) for xi in M.flush(x.astype(dtype))]
        params = M.flush(np.array([[float(c) for c in e] for e in exps]).astype(dtype))
        hi, lo = M._dd([M.log_ref("SE3", p) for p in params])
    with M.x64_for(dtype):
        got = np.asarray(jaxlie_geo.SE3(jnp.asarray(params)).log())
    e = M.ulp_errors(got, hi, lo, M.LOG_BLOCKS["SE3"], dtype)
    assert e.max() <= 2.5, (e.max(), params[np.argmax(e)])
