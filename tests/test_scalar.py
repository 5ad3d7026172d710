"""The scalar kernels of jaxlie_geo._scalar and _scalar_sim3 against mpmath at 50 digits.

For each kernel f(x), x = θ², over its whole domain (exactly 0, subnormal and tiny x, both
sides of every series/closed-form switch, and large angles), we measure the error of the
value and of the first two autodiff derivatives in ulp:

    err = |got − ref| / (eps · scale),   scale = max(|ref|, envelope(x), |x · f⁽ᵒ⁺¹⁾(x)|)

where the envelope is the size of the function's terms (so a kernel crossing zero, such as
sin θ/θ at θ = π, is judged by the absolute error its formula can reach) and the last term
is the change caused by one ulp of x: every caller forms x = θ² in floating point, and at
large angles (cos √x at θ = 10π) that rounding, not the kernel, dominates. The reference is
the exact power series (rational coefficients) below x = 4 and the closed form above, both at
50 digits, evaluated at the float the kernel actually received. Run as a script to print
the tables that the docstrings of _scalar and _scalar_sim3 quote.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from _diskcache import disk_cached

from jaxlie_geo import _scalar, _scalar_sim3

mp.mp.dps = 50
jax.config.update("jax_enable_x64", True)


# --- references ------------------------------------------------------------------


def _series(coef, x, n=60):
    return mp.fsum(coef(k) * x**k for k in range(n))


def _ref(name):
    fact = mp.factorial

    def bern_coef(k):  # |B_{2k+2}| / (2k+2)!
        return abs(mp.bernoulli(2 * k + 2)) / fact(2 * k + 2)

    table = {
        "cos_": (lambda k: (-1) ** k / fact(2 * k), lambda t: mp.cos(t)),
        "sinc": (lambda k: (-1) ** k / fact(2 * k + 1), lambda t: mp.sin(t) / t),
        "F1": (lambda k: (-1) ** k / fact(2 * k + 2), lambda t: (1 - mp.cos(t)) / t**2),
        "F2": (lambda k: (-1) ** k / fact(2 * k + 3), lambda t: (t - mp.sin(t)) / t**3),
        "C2": (
            lambda k: (-1) ** k / fact(2 * k + 4),
            lambda t: (t**2 + 2 * mp.cos(t) - 2) / (2 * t**4),
        ),
        "D": (
            lambda k: (-1) ** k * (k + 1) / fact(2 * k + 5),
            lambda t: (2 * t - 3 * mp.sin(t) + t * mp.cos(t)) / (2 * t**5),
        ),
        "G": (bern_coef, lambda t: (1 - (t / 2) * mp.cot(t / 2)) / t**2),
    }
    table["G_principal"] = table["G"]
    coef, closed = table[name]

    def f(x):
        x = mp.mpf(x)
        if x < 4:
            return _series(coef, x)
        return closed(mp.sqrt(x))

    return f


# Size of the terms of each kernel at x (see module docstring).
ENVELOPE = {
    "cos_": lambda x: 1.0,
    "sinc": lambda x: min(1.0, 1.0 / math.sqrt(x)) if x > 0 else 1.0,
    "F1": lambda x: min(0.5, 2.0 / x) if x > 0 else 0.5,
    "F2": lambda x: 0.0,
    "C2": lambda x: 0.0,
    "D": lambda x: 0.0,
    "G": lambda x: 0.0,
    "G_principal": lambda x: 0.0,
}

# Domain of each kernel: exp-side kernels up to θ = 10π; the Jacobian coefficients C2, D
# up to θ = 3π; G on θ < 2π (pole), mostly used on the principal range θ ≤ π.
X_MAX = {
    "cos_": 100 * math.pi**2,
    "sinc": 100 * math.pi**2,
    "F1": 100 * math.pi**2,
    "F2": 100 * math.pi**2,
    "C2": 9 * math.pi**2,
    "D": 9 * math.pi**2,
    "G": (2 * math.pi - 0.3) ** 2,
    "G_principal": math.pi**2,
}
SWITCHES = [1.0, 10.0, 12.0, math.pi**2, 16.0, 30.0]


def sample_x(name, dtype, n=160):
    """Fixed tiny points, log-uniform x over the domain, both sides of every switch, and a
    grid of step 0.1 on 0.3 ≤ x ≤ 40, where the switches and the cancelling closed forms
    are: log-uniform samples alone missed D″ at 63 ulp (x = 13.4) and G′ at 8.5 (x ≈ 10)."""
    rng = np.random.default_rng(0)
    xs = [0.0, 1e-300, 1e-40, 1e-30, 1e-20, 1e-12, 1e-8, 1e-4]
    xs += list(np.exp(rng.uniform(np.log(1e-6), np.log(X_MAX[name]), n)))
    xs += list(np.arange(0.3, 40.0, 0.1))
    for s in SWITCHES:
        xs += [s * (1 - 1e-6), s, s * (1 + 1e-6)]
    xs = np.array([x for x in xs if x <= X_MAX[name]], dtype=dtype)
    # XLA flushes subnormals to zero on CPU: the kernel receives the flushed value.
    tiny = np.finfo(dtype).tiny
    return np.where(np.abs(xs) < tiny, 0.0, xs).astype(dtype)


@functools.partial(jax.jit, static_argnums=0)
def _kernel_and_derivatives(name, xs):
    """The kernel ``name`` and its first two derivatives at ``xs``, in one program (as the
    library runs it: inside a jitted function)."""
    f = getattr(_scalar, name)
    return f(xs), jax.vmap(jax.grad(f))(xs), jax.vmap(jax.grad(jax.grad(f)))(xs)


def kernel_errors(name, dtype):
    """Worst (value, d/dx, d²/dx²) errors in ulp over the kernel's sample."""
    xs = sample_x(name, dtype)
    got = [np.asarray(g) for g in _kernel_and_derivatives(name, jnp.asarray(xs))]
    ref_f = _ref(name)
    eps = float(np.finfo(dtype).eps)
    worst = [0.0, 0.0, 0.0]
    for i, x in enumerate(xs.astype(np.float64)):
        refs = [c * math.factorial(k) for k, c in enumerate(mp.taylor(ref_f, x, 3))]
        env = ENVELOPE[name](x)
        for order in range(3):
            r = float(refs[order])
            scale = max(abs(r), env * (math.sqrt(x) ** -order if x > 1 and env else 1.0))
            scale = max(scale, abs(x * float(refs[order + 1])))
            scale = max(scale, np.finfo(dtype).tiny)
            g = float(got[order][i])
            err = abs(g - r) / (eps * scale) if np.isfinite(g) else math.inf
            worst[order] = max(worst[order], err)
    return worst


@jax.jit
def _atan2_over_and_gradient(n2, w):
    """atan2_over and its two partial derivatives, in one program."""
    f = _scalar.atan2_over
    return f(n2, w), jax.vmap(jax.grad(f, 0))(n2, w), jax.vmap(jax.grad(f, 1))(n2, w)


def atan2_over_errors(dtype):
    """atan2(n, w)/n on the unit circle, w ≥ 0 (the SO(3) log's case), value and both
    partial derivatives."""
    alphas = np.concatenate([[0.0, 1e-30, 1e-12, 1e-6], np.linspace(1e-3, np.pi / 2, 120)])
    n = np.sin(alphas).astype(dtype)
    w = np.cos(alphas).astype(dtype)
    w[-1] = 0.0
    n2 = (n * n).astype(dtype)
    got, gn, gw = (np.asarray(g) for g in _atan2_over_and_gradient(n2, w))
    eps = float(np.finfo(dtype).eps)

    def ref(a, b):
        a, b = mp.mpf(a), mp.mpf(b)
        if b > 0 and abs(a) < b * b / 2:  # analytic series of atan(√t)/√t, t = a/b²
            t = a / (b * b)
            return mp.fsum((-1) ** k * t**k / (2 * k + 1) for k in range(200)) / b
        return mp.atan2(mp.sqrt(a), b) / mp.sqrt(a)

    worst = [0.0, 0.0, 0.0]
    for i in range(len(n2)):
        a, b = float(n2[i]), float(w[i])
        r = ref(a, b)
        rn = mp.diff(lambda s, b=b: ref(s, b), a)
        rw = mp.diff(lambda s, a=a: ref(a, s), b)
        for k, (g, rr) in enumerate([(got[i], r), (gn[i], rn), (gw[i], rw)]):
            err = abs(float(g) - float(rr)) / (eps * max(abs(float(rr)), 1e-300))
            worst[k] = max(worst[k], err if np.isfinite(g) else math.inf)
    return worst


KERNELS = ["cos_", "sinc", "F1", "F2", "C2", "D", "G", "G_principal"]
# Bounds asserted (ulp): value, first derivative, second derivative.
BOUNDS = (4.0, 8.0, 64.0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("name", KERNELS)
def test_kernel_accuracy(name, dtype):
    """The kernel and its first two derivatives are within ``BOUNDS`` ulp of mpmath over the
    kernel's test points, and finite."""
    worst = kernel_errors(name, dtype)
    assert all(np.isfinite(worst)), worst
    for order, (w, bound) in enumerate(zip(worst, BOUNDS)):
        assert w <= bound, f"{name} {dtype.__name__} derivative order {order}: {w:.1f} ulp"


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_atan2_over_accuracy(dtype):
    """``atan2_over`` and its two partial derivatives are within ``BOUNDS`` ulp of mpmath."""
    worst = atan2_over_errors(dtype)
    assert worst[0] <= BOUNDS[0] and worst[1] <= BOUNDS[1] and worst[2] <= BOUNDS[1], worst


# (series, its switch) as _scalar uses them; coefficients written out here, independently.
_FACT = mp.factorial
_SERIES = {
    "cos": lambda k: (-1) ** k / _FACT(2 * k),
    "sinc": lambda k: (-1) ** k / _FACT(2 * k + 1),
    "F2": lambda k: (-1) ** k / _FACT(2 * k + 3),
    "C2": lambda k: (-1) ** k / _FACT(2 * k + 4),
    "D": lambda k: (-1) ** k * (k + 1) / _FACT(2 * k + 5),
    "G": lambda k: abs(mp.bernoulli(2 * k + 2)) / _FACT(2 * k + 2),
    "half_m": lambda k: (-1) ** k * (k + 1) / (4 * _FACT(2 * k + 3)),
    "atan": lambda k: mp.mpf((-1) ** k) / (2 * k + 1),
}
_SWITCHES = [
    ("cos", 1.0),
    ("sinc", 1.0),
    ("half_m", 1.0),
    ("F2", 10.0),
    ("C2", 12.0),
    ("D", 30.0),
    ("G", 16.0),
    ("G", math.pi**2 * (1 + 1e-6)),
    ("atan", _scalar._ATAN_X_MAX),
]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(("name", "x_max"), _SWITCHES, ids=[f"{n}@{x:.3g}" for n, x in _SWITCHES])
def test_series_truncation_below_eps_over_8(name, x_max, dtype):
    """The module docstring's rule: each series keeps enough terms that, at its switch, the
    dropped tail of the value and of its first two derivatives is below eps/8 of the
    function (resp. derivative) there. Checked with exact coefficients at 50 digits, summed
    to 400 terms (all these series converge at their switch with ratio ≤ 0.41)."""
    n = _scalar._n_terms(name, x_max, float(np.finfo(dtype).eps))
    coef, x = _SERIES[name], mp.mpf(x_max)
    for order in range(3):
        terms = [coef(j) * mp.ff(j, order) * x ** (j - order) for j in range(order, 400)]
        value = mp.fsum(terms)
        tail = mp.fsum(terms[max(n - order, 0) :])
        assert abs(tail) <= np.finfo(dtype).eps / 8 * abs(value), (name, order, n)


# --- Sim(3)'s joint kernels ----------------------------------------------------------
#
# (D0, B, C)(σ, x) = ∫₀¹ e^{στ} g(τ) dτ for g = cos τθ, sin τθ / θ, (1 − cos τθ)/θ², and
# their derivatives, from the power series of g in x integrated against the moments
# Iₖ(σ) = ∫ τᵏ e^{στ} dτ = Σ σⁿ/(n!(n+k+1)) (summed at 90 digits: the alternating terms of
# σ = −20 lose 9 of them):  ∂ⁿσ ∂ᵐx of kernel q is Σ_{j≥m} (−1)ʲ j!/(j−m)! x^{j−m}/(2j+q)! ·
# I_{2j+q+n}(σ).


@functools.lru_cache(maxsize=None)
def _moment(s, k):
    with mp.workdps(90):
        s = mp.mpf(s)
        return mp.fsum(s**n / (mp.factorial(n) * (n + k + 1)) for n in range(220))


def sim3_ref(q, s, x, n=0, m=0):
    """∂ⁿ/∂σⁿ ∂ᵐ/∂xᵐ of D0 (q = 0), B (1) or C (2) at (σ, x), to 50 digits."""
    with mp.workdps(90):
        x = mp.mpf(x)
        return mp.fsum(
            (-1) ** j
            * mp.factorial(j)
            / mp.factorial(j - m)
            * x ** (j - m)
            / mp.factorial(2 * j + q)
            * _moment(s, 2 * j + q + n)
            for j in range(m, 70)
        )


SIM3_SIGMAS = [
    0.0,
    1e-8,
    -1e-8,
    1e-3,
    -1e-3,
    0.5,
    -0.5,
    0.7,
    -0.7,
    2.4,
    2.6,
    -3.9,
    4.1,
    20.0,
    -20.0,
]
SIM3_THETAS = [0.0, 1e-5, 1e-3, 0.1, 0.7, 2.0, math.pi - 1e-3, math.pi]
_SIM3_ORDERS = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]


@jax.jit
def _sim3_derivatives(sig, xs):
    """(D0, B, C) and their partial derivatives up to order 2 in (σ, x), keyed by (n, m) =
    (order in σ, order in x), in one program."""
    f = lambda s, x: jnp.stack(_scalar_sim3.sim3_coefficients(s, x)[1:])
    H = jax.vmap(jax.hessian(f, (0, 1)))(sig, xs)
    return {
        (0, 0): jax.vmap(f)(sig, xs),
        (1, 0): jax.vmap(jax.jacfwd(f, 0))(sig, xs),
        (0, 1): jax.vmap(jax.jacfwd(f, 1))(sig, xs),
        (2, 0): H[0][0],
        (1, 1): H[0][1],
        (0, 2): H[1][1],
    }


def sim3_errors(dtype, sigmas=SIM3_SIGMAS, thetas=SIM3_THETAS):
    """Worst errors in ulp of (D0, B, C) (rows) for the value, the first and the second
    derivatives (columns, the worst over the partial derivatives of that order).

    Scale: |ref|, and for D0, which crosses zero, the modulus |φ| = √(D0² + x B²) of the
    complex number D0 + iθB it is the real part of (the same derivative of both); plus
    x |∂ref/∂x|, the change one ulp of x = θ² causes."""
    sig, xs = np.meshgrid(np.asarray(sigmas, dtype), np.asarray(thetas, dtype) ** 2)
    sig, xs = sig.ravel(), xs.ravel()
    got = _sim3_derivatives(sig, xs)
    eps = float(np.finfo(dtype).eps)
    worst = np.zeros((3, 3))
    for i, (s, x) in enumerate(zip(sig.astype(float), xs.astype(float))):
        for n, m in _SIM3_ORDERS:
            refs = [sim3_ref(q, s, x, n, m) for q in range(3)]
            for q in range(3):
                scale = abs(refs[q])
                if q == 0:
                    scale = max(scale, mp.sqrt(refs[0] ** 2 + x * sim3_ref(1, s, x, n, m) ** 2))
                scale = max(float(scale), abs(x * float(sim3_ref(q, s, x, n, m + 1))))
                g = float(np.asarray(got[(n, m)])[i, q])
                err = abs(g - float(refs[q])) / (eps * scale) if np.isfinite(g) else math.inf
                worst[q, n + m] = max(worst[q, n + m], err)
    return worst


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sim3_coefficients_accuracy(dtype):
    """Sim(3)'s D0, B, C and their first and second partial derivatives in (σ, x) are within
    ``BOUNDS`` ulp of mpmath over a grid that crosses every switch (|z|² = 1/2, σ = 2.5,
    |σ| = 4), includes θ and σ → 0 jointly and separately, θ = π, and |σ| = 20."""
    worst = sim3_errors(dtype)
    assert np.all(np.isfinite(worst)), worst
    for order, bound in enumerate(BOUNDS):
        assert np.all(worst[:, order] <= bound), (order, worst)


# The derivative family T_{p,m}(σ, x) = Σⱼ (−x)ʲ I_{p+m+2j}(σ)/(2j+m)! (``sim3_family``), on a
# grid that crosses each of its switches (|σ| = 8, x = 4, x = 10) and reaches θ = π, |σ| = 20.
FAMILY_SIGMAS = [-20.0, -8.0001, -7.9999, -3.0, -0.5, 0.0, 1e-8, 0.7, 4.1, 7.9999, 8.0001, 20.0]
FAMILY_THETAS = [0.0, 1e-3, 0.5, 1.9999, 2.0001, 3.0, 3.1622, 3.1623, math.pi]
FAMILY_INDEX = tuple((p, m) for p in range(4) for m in range(-1, 7))


def family_ref(p, m, s, x):
    """T_{p,m}(σ, x) at 90 digits (m = −1: the moment I_p(σ))."""
    if m < 0:
        return _moment(s, p)
    with mp.workdps(90):
        x = mp.mpf(x)
        return mp.fsum(
            (-x) ** j / mp.factorial(2 * j + m) * _moment(s, p + m + 2 * j) for j in range(70)
        )


@disk_cached
def _family_refs(dtype_name):
    """(value, scale) of every family member at every grid point, as the floats ``dtype``
    rounds the grid to: the scale is |T|, for m = 0 the modulus √(T_{p,0}² + x T_{p,1}²) of
    φ_p(σ + iθ) (T_{p,0} crosses zero), and x |∂T/∂x|, the change one ulp of x causes."""
    dtype = np.dtype(dtype_name)
    sig, xs = np.meshgrid(np.asarray(FAMILY_SIGMAS), np.asarray(FAMILY_THETAS) ** 2)
    sig, xs = sig.ravel().astype(dtype), xs.ravel().astype(dtype)
    out = np.zeros((2, len(FAMILY_INDEX), len(sig)))
    for i, (s, x) in enumerate(zip(sig.astype(float), xs.astype(float))):
        for k, (p, m) in enumerate(FAMILY_INDEX):
            ref = family_ref(p, m, s, x)
            scale = abs(ref)
            if m == 0:
                scale = max(scale, mp.sqrt(ref**2 + x * family_ref(p, 1, s, x) ** 2))
            if m >= 0:
                dx = (family_ref(p + 1, m + 1, s, x) - m * family_ref(p, m + 2, s, x)) / 2
                scale = max(scale, abs(x * dx))
            out[:, k, i] = float(ref), float(scale)
    return sig, xs, out


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sim3_family_accuracy(dtype):
    """Every member of Sim(3)'s derivative family with p ≤ 3, −1 ≤ m ≤ 6 is within 4 ulp of
    mpmath where the first derivatives of D0, B, C read it (p ≤ 1, m ≤ 4) and within 12
    elsewhere (second and third derivatives), for θ ≤ π and |σ| ≤ 20."""
    sig, xs, refs = _family_refs(np.dtype(dtype).name)
    got = jax.jit(lambda s, x: _scalar_sim3.sim3_family(s, x, FAMILY_INDEX))(sig, xs)
    eps = float(np.finfo(dtype).eps)
    for k, (p, m) in enumerate(FAMILY_INDEX):
        err = np.abs(np.asarray(got[k], np.float64) - refs[0, k]) / (eps * refs[1, k])
        bound = 4.0 if p <= 1 and m <= 4 else 12.0
        assert np.all(err <= bound), ((p, m), float(np.max(err)), int(np.argmax(err)))


def test_sim3_family_derivatives_are_members():
    """The custom JVP of ``sim3_family`` against central differences of the family itself,
    in float64 at points of every region: ∂T_{p,m}/∂σ = T_{p+1,m} and
    ∂T_{p,m}/∂x = −(T_{p+1,m+1} − m T_{p,m+2})/2 hold to the differences' own accuracy."""
    s = np.array([-12.0, -3.0, 0.3, 5.0, 12.0, -1.0, 2.0])
    x = np.array([0.7, 2.0, 1.0, 9.0, 3.0, 6.0, 12.0])
    index = ((0, -1), (0, 0), (0, 1), (0, 2), (1, 3), (0, 4))
    family = _scalar_sim3.sim3_family
    f = jax.jit(lambda s, x: jnp.stack(family(s, x, index)))
    ds, dx = jax.jit(
        lambda s, x: (
            jnp.stack(jax.jvp(lambda s: family(s, x, index), (s,), (jnp.ones_like(s),))[1]),
            jnp.stack(jax.jvp(lambda x: family(s, x, index), (x,), (jnp.ones_like(x),))[1]),
        )
    )(s, x)
    h = 1e-5
    fd_s = (f(s + h, x) - f(s - h, x)) / (2 * h)
    fd_x = (f(s, x + h) - f(s, x - h)) / (2 * h)
    np.testing.assert_allclose(ds, fd_s, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(dx, fd_x, rtol=1e-7, atol=1e-9)


def test_sim3_moments_are_the_integrals():
    """``sim3_moments`` Iₖ(σ), k ≤ 4, on both sides of its switch and of σ = 0, within 4 ulp
    of the series at 90 digits in float64 (its derivative is Iₖ₊₁ by construction)."""
    s = np.array(
        [-30.0, -20.0, -4.0001, -3.9999, -1.0, -1e-9, 0.0, 1e-9, 1.0, 3.9999, 4.0001, 20.0]
    )
    got = np.asarray(_scalar_sim3.sim3_moments(jnp.asarray(s), 4))
    eps = float(np.finfo(np.float64).eps)
    for i, si in enumerate(s):
        for k in range(5):
            ref = float(_moment(float(si), k))
            assert abs(got[i, k] - ref) <= 4 * eps * abs(ref), (si, k, got[i, k], ref)


if __name__ == "__main__":
    print("| kernel | float32 f, f', f'' | float64 f, f', f'' |")
    print("|---|---|---|")
    for name in KERNELS:
        cells = [
            ", ".join(f"{e:.1f}" for e in kernel_errors(name, dt))
            for dt in (np.float32, np.float64)
        ]
        print(f"| {name} | {cells[0]} | {cells[1]} |")
    cells = [
        ", ".join(f"{e:.1f}" for e in atan2_over_errors(dt)) for dt in (np.float32, np.float64)
    ]
    print(f"| atan2_over (f, ∂n², ∂w) | {cells[0]} | {cells[1]} |")
    both = [sim3_errors(dt) for dt in (np.float32, np.float64)]
    for q, name in enumerate(["sim3 D0", "sim3 B", "sim3 C"]):
        cells = [", ".join(f"{e:.1f}" for e in w[q]) for w in both]
        print(f"| {name} | {cells[0]} | {cells[1]} |")
