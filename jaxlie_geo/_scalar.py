"""The numerically delicate scalar functions, in one place.

Every exponential, logarithm and Jacobian in the package is a closed-form vector
expression whose only delicate parts are the functions below. Each one is an even,
analytic function of the rotation angle θ and is therefore written as a function of
``x = θ²``: never of ``θ = ‖ω‖``, whose derivative is infinite at 0 whatever the
kernel does.

Each kernel is evaluated as

* its Taylor series in ``x`` (Horner's scheme) for ``x < switch``, with as many terms
  as the dtype needs for the truncation error to stay below ``eps / 8`` at the switch
  (the number of terms is chosen at trace time, per dtype), and
* a closed form without catastrophic cancellation above the switch.

(``half_angle``, the pair cos(θ/2), sin(θ/2)/(θ/2) behind every SO(3)/SE(3) exp, is the
exception: its values are closed forms, which need no series, and its derivatives an
exact custom JVP whose one cancelling term is summed from a series.)

Both branches are evaluated on clamped arguments (the ``jnp.where``-safe pattern), so
no NaN or inf from the unused branch reaches a gradient; each clamp is the switch itself or
lies far from it, so that a branch selected by a copy of the test that XLA computed from a
differently rounded x still sees (nearly) the true argument (the Sim(3) section below has
the measured case). The switch sits where the
closed form's value *and its first two autodiff derivatives* are accurate, which for
cancellation-prone kernels is far from zero (``x = 10`` for F2, 12 for C2, 30 for D, 16 for
G). A trig formula above a small cutoff, as in Eberly 2024, §11.4 (constants below
θ = 0.0625), does not meet the library's accuracy requirement: values within 4 ulp, first
derivatives within 8 ulp and second derivatives within 64 (the bounds
``tests/test_scalar.py`` asserts). Lower switches do not either: with D switched at x = 12
and G at π², D″ reaches 63 ulp (x = 13.4) and G′ 8.5 ulp (x ≈ 10).

Notation (F0, F1, F2 as in Eberly 2024, §11, eq. 42; all written as functions of x = θ²):

========  ================================  =======================  =========
name      function                          series Σ aₖ xᵏ           value at 0
========  ================================  =======================  =========
cos_      cos θ                             (−1)ᵏ/(2k)!              1
sinc      F0 = sin θ / θ                    (−1)ᵏ/(2k+1)!            1
F1        (1 − cos θ)/θ²                    (−1)ᵏ/(2k+2)!            1/2
F2        (θ − sin θ)/θ³                    (−1)ᵏ/(2k+3)!            1/6
C2        (θ² + 2cos θ − 2)/(2θ⁴)           (−1)ᵏ/(2k+4)!            1/24
D         (2θ − 3 sin θ + θ cos θ)/(2θ⁵)    (−1)ᵏ(k+1)/(2k+5)!       1/120
G         (1 − (θ/2)cot(θ/2))/θ²            |B₂ₖ₊₂|/(2k+2)!          1/12
========  ================================  =======================  =========

F1 is evaluated as ½·sinc(θ/2)², from 1 − cos θ = 2 sin²(θ/2), which has no
cancellation anywhere. G's series (Bernoulli numbers) has only positive terms and
converges for θ < 2π; on the principal range θ ≤ π it is summed directly.

Measured worst errors, in ulp, against mpmath at 50 digits (``python tests/test_scalar.py``
reproduces this table; ``tests/test_scalar.py`` asserts value ≤ 4, f′ ≤ 8, f″ ≤ 64). Inputs:
x = 0, subnormal (flushed to 0 by XLA on CPU), 1e-40 … 1e-4, both sides of every switch, a
grid of step 0.1 on 0.3 ≤ x ≤ 40, and log-uniform x up to θ = 10π (C2, D: 3π; G: 2π − 0.3).
Error scale: max(|f|, the size of the formula's terms, the change from one ulp of x — every
caller forms x = θ² in floating point).

==============  =====================  =====================
kernel          float32 (f, f′, f″)    float64 (f, f′, f″)
==============  =====================  =====================
cos_            0.9, 0.9, 0.7          1.0, 0.9, 0.8
sinc            1.2, 1.0, 0.9          1.1, 1.1, 0.7
F1              1.4, 1.1, 0.7          1.7, 1.0, 0.7
F2              1.0, 3.2, 21.0         1.0, 5.1, 22.6
C2              1.0, 5.2, 34.3         1.1, 4.3, 29.7
D               3.1, 3.3, 6.2          1.9, 3.9, 6.5
G               2.3, 2.3, 2.9          2.1, 3.5, 4.0
G_principal     0.6, 2.1, 2.2          0.7, 3.5, 4.0
atan2_over      1.3, 2.7, 2.6          1.5, 4.1, 3.0   (f, ∂/∂n2, ∂/∂w)
==============  =====================  =====================

The second derivatives peak on the closed-form side of a switch, where autodiff of the
closed form still cancels a little; every value and first derivative is within 5.2 ulp.

Sim(3)'s coefficients are functions of two variables, the log-scale σ and x = θ²; their
section below (``sim3_coefficients``) has their series, switches and error table.
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction
from typing import Callable, Optional, Tuple

import jax
import jax.numpy as jnp

__all__ = [
    "cos_",
    "sinc",
    "F1",
    "F2",
    "C2",
    "D",
    "G",
    "G_principal",
    "atan2_over",
    "sim3_moments",
    "sim3_coefficients",
]


# ---------------------------------------------------------------------------------
# Series machinery.


def _bernoulli_even(count: int) -> list[Fraction]:
    """B_0, B_2, ..., B_{2(count-1)} as exact fractions (Akiyama–Tanigawa)."""
    n_max = 2 * count
    a = [Fraction(0)] * (n_max + 1)
    out = []
    for m in range(n_max + 1):
        a[m] = Fraction(1, m + 1)
        for j in range(m, 0, -1):
            a[j - 1] = j * (a[j - 1] - a[j])
        if m % 2 == 0:
            out.append(a[0])
    return out[:count]


_N_MAX = 60  # longest series any kernel may need (G in float64, switched at x = 16: 53 terms)
_ATAN_X_MAX = (math.sqrt(2.0) - 1.0) ** 2 * (1 + 1e-6)  # tan²(π/8)

_COEFFS: dict[str, tuple[float, ...]] = {
    "cos": tuple(float(Fraction((-1) ** k, math.factorial(2 * k))) for k in range(_N_MAX)),
    "sinc": tuple(float(Fraction((-1) ** k, math.factorial(2 * k + 1))) for k in range(_N_MAX)),
    "F2": tuple(float(Fraction((-1) ** k, math.factorial(2 * k + 3))) for k in range(_N_MAX)),
    "C2": tuple(float(Fraction((-1) ** k, math.factorial(2 * k + 4))) for k in range(_N_MAX)),
    "D": tuple(
        float(Fraction((-1) ** k * (k + 1), math.factorial(2 * k + 5))) for k in range(_N_MAX)
    ),
    # m = (sinc(θ/2) − cos(θ/2))/(2θ²) as a series in y = θ²/4: −d sinc(θ/2)/dθ².
    "half_m": tuple(
        float(Fraction((-1) ** k * (k + 1), 4 * math.factorial(2 * k + 3))) for k in range(_N_MAX)
    ),
    "atan": tuple(float(Fraction((-1) ** k, 2 * k + 1)) for k in range(_N_MAX)),
    "G": tuple(
        float(abs(b) / math.factorial(2 * k + 2))
        for k, b in enumerate(_bernoulli_even(_N_MAX + 1)[1:])
    ),
}


@functools.lru_cache(maxsize=None)
def _n_terms(name: str, x_max: float, eps: float) -> int:
    """Fewest terms for which, at ``x_max``, the truncated tail of the series and of its
    first two derivatives is below ``eps / 8`` of the smallest partial sum (a proxy for
    the size of the function and of those derivatives there)."""
    coeffs = _COEFFS[name]

    def falling(j: int, order: int) -> float:
        return float(math.prod(range(j - order + 1, j + 1))) if j >= order else 0.0

    for k in range(len(coeffs)):
        ok = True
        for order in range(3):
            terms = [
                c * falling(j, order) * x_max ** max(j - order, 0) for j, c in enumerate(coeffs)
            ]
            partials = [sum(terms[: i + 1]) for i in range(order, k + 1)]
            smallest = min((abs(p) for p in partials), default=0.0)
            tail = sum(abs(t) for t in terms[k + 1 :])
            ok &= smallest > 0 and tail <= eps / 8 * smallest
        if ok:
            return k + 1
    raise AssertionError(f"series {name} too short for x_max={x_max}")  # pragma: no cover


def _horner(name: str, x: jax.Array, x_max: float) -> jax.Array:
    coeffs = _COEFFS[name][: _n_terms(name, x_max, float(jnp.finfo(x.dtype).eps))]
    acc = jnp.full_like(x, coeffs[-1])
    for c in reversed(coeffs[:-1]):
        acc = acc * x + c
    return acc


def _switched(
    name: str, x: jax.Array, switch: float, closed_form: Callable[[jax.Array], jax.Array]
) -> jax.Array:
    """Series below ``switch``, ``closed_form(x)`` above; both on clamped arguments."""
    small = x < switch
    series = _horner(name, jnp.where(small, x, switch), switch)
    direct = closed_form(jnp.where(small, switch, x))
    return jnp.where(small, series, direct)


# ---------------------------------------------------------------------------------
# Vector helpers.


def components(x: jax.Array) -> Tuple[jax.Array, ...]:
    """The entries of ``x`` along its last axis, each ``(*batch,)``, in one ``unstack``:
    the same values as ``x[..., i]``, but reverse-mode differentiation transposes them into
    one concatenation, where per-index slices transpose into a pad and an addition each
    (``docs/design/compile-time.md``)."""
    return tuple(jnp.unstack(x, axis=-1))


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """Dot product over the last axis, ``(*batch, n) -> batch``, written out as products and
    sums rather than a reduction, so that it stays in its neighbours' fused loop."""
    A = components(a)
    B = A if b is a else components(b)
    out = A[0] * B[0]
    for i in range(1, len(A)):
        out = out + A[i] * B[i]
    return out


def sq_norm(w: jax.Array) -> jax.Array:
    """Σ wᵢ² over the last axis (``dot(w, w)``)."""
    return dot(w, w)


_INT = {2: jnp.int16, 4: jnp.int32, 8: jnp.int64}


def pow2_inverse(v: jax.Array) -> jax.Array:
    """2^k with |v| · 2^k in [1, 2), elementwise: the power of two nearest 1/|v|, for exact
    rescaling. k is clipped so that 2^k is a normal float (for v = 0 any factor would do).
    Built from the exponent bits: exact, and cheaper than ``frexp``/``ldexp`` (XLA:CPU's
    ``ldexp`` miscomputes in some fused, vectorised programs with jax 0.10.2: 1e-2
    relative error at batch sizes of 32 and more)."""
    fi = jnp.finfo(v.dtype)
    int_t = _INT[v.dtype.itemsize]
    bias = fi.maxexp - 1
    bits = jax.lax.bitcast_convert_type(jnp.abs(v), int_t)
    k = jnp.clip(int_t(bias) - jax.lax.shift_right_logical(bits, int_t(fi.nmant)), 1 - bias, bias)
    return jax.lax.bitcast_convert_type(
        jax.lax.shift_left(k + int_t(bias), int_t(fi.nmant)), v.dtype
    )


# ---------------------------------------------------------------------------------
# Kernels. All take x = θ² >= 0 (any shape, floating dtype) and return x's dtype.
# θ = √x carries the rounding of x: about |θ|·ε/2 absolute, so an angle far beyond π
# is only as accurate as its square (the conditioning bound in ``half_angle``).


def cos_(x: jax.Array) -> jax.Array:
    """cos θ as a function of x = θ². Series below x = 1."""
    return _switched("cos", x, 1.0, lambda x: jnp.cos(jnp.sqrt(x)))


def sinc(x: jax.Array) -> jax.Array:
    """F0 = sin θ / θ as a function of x = θ² (Eberly 2024, §11.1). Series below x = 1."""

    def closed(x: jax.Array) -> jax.Array:
        theta = jnp.sqrt(x)
        return jnp.sin(theta) / theta

    return _switched("sinc", x, 1.0, closed)


@jax.custom_jvp
def half_angle(x: jax.Array) -> Tuple[jax.Array, jax.Array]:
    """c = cos(θ/2) and k = sin(θ/2)/(θ/2) for x = θ², from one sincos.

    Everything an SO(3)/SE(3) exponential needs follows: the quaternion (c, k ω/2), and
    F0 = c k, F1 = k²/2, F2 = (1 − c k)/θ² above its switch.

    Values: the closed forms, which need no series for accuracy (cos is well conditioned,
    and sin(θ/2)/(θ/2) does not cancel), except x/4 < eps where c = 1 − x/8, k = 1 − x/24
    are exact and no 0/0 arises. θ/2 = √(x/4) carries the rounding of x = θ², at most
    about ¾·|θ|·ε/2 in the half angle: within 4 ulp up to θ = π and, beyond, within
    (4 + |θ|/2) ulp, the error a one-ulp change of the input ω itself causes (5 ulp
    measured at θ ≈ 16, 1.2e3 at θ = 1e4 in float32).

    Derivatives (custom JVP, exact in terms of the outputs): dc/dx = −k/8 and
    dk/dx = −m with m = (k − c)/(2x), summed from its series below x = 4 where that
    difference cancels. The JVP rule is itself differentiable (Hessians)."""
    x4 = 0.25 * x
    tiny = x4 < jnp.finfo(x.dtype).eps
    phi = jnp.sqrt(jnp.where(tiny, 1.0, x4))
    c, k = jnp.cos(phi), jnp.sin(phi) / phi
    return jnp.where(tiny, 1.0 - 0.5 * x4, c), jnp.where(tiny, 1.0 - x4 / 6.0, k)


def _half_m(x: jax.Array, c: jax.Array, k: jax.Array) -> jax.Array:
    """m = (k − c)/(2x) = −dk/dx for c = cos(θ/2), k = sin(θ/2)/(θ/2), x = θ²: summed from
    its series below x = 4, where the difference cancels."""
    y = 0.25 * x
    small = y < 1.0
    m_series = _horner("half_m", jnp.where(small, y, 1.0), 1.0)
    m_closed = (k - c) / (2.0 * jnp.where(small, 4.0, x))
    return jnp.where(small, m_series, m_closed)


@half_angle.defjvp
def _half_angle_jvp(primals, tangents):  # type: ignore[no-untyped-def]
    (x,), (dx,) = primals, tangents
    c, k = half_angle(x)
    return (c, k), (-0.125 * k * dx, -_half_m(x, c, k) * dx)


@jax.custom_jvp
def half_angle_of(theta: jax.Array) -> Tuple[jax.Array, jax.Array]:
    """(cos(θ/2), sin(θ/2)/(θ/2)) from a signed angle θ given as a coordinate (SE(2)).

    Unlike ``half_angle(θ²)`` it never forms θ² and takes its root, which loses the
    angle's last bits beyond π (55 ulp in float32 on an H100 at θ ≈ 30). Values: the
    closed forms, one sincos (1 − (θ/2)²/6 when (θ/2)² < eps, to avoid 0/0); derivatives
    the exact custom JVP dc/dθ = −θk/4, dk/dθ = −2θ m (m as in ``half_angle``)."""
    half = 0.5 * theta
    tiny = half * half < jnp.finfo(theta.dtype).eps
    hd = jnp.where(tiny, 1.0, half)
    return jnp.cos(half), jnp.where(tiny, 1.0 - half * half / 6.0, jnp.sin(hd) / hd)


@half_angle_of.defjvp
def _half_angle_of_jvp(primals, tangents):  # type: ignore[no-untyped-def]
    (theta,), (dtheta,) = primals, tangents
    c, k = half_angle_of(theta)
    m = _half_m(theta * theta, c, k)
    return (c, k), (-0.25 * theta * k * dtheta, -2.0 * theta * m * dtheta)


def F1(x: jax.Array) -> jax.Array:
    """F1 = (1 − cos θ)/θ² = ½ sinc(θ/2)², which has no cancellation anywhere."""
    half = sinc(0.25 * x)
    return 0.5 * half * half


def F2(x: jax.Array, f0: Optional[jax.Array] = None) -> jax.Array:
    """F2 = (θ − sin θ)/θ³ = (1 − F0)/θ² (Eberly 2024, §11.3; the third term of the series
    in eq. 42 is θ⁴/7!, not θ⁶/7!).

    The closed form cancels below θ ≈ 1.7 (1000 ulp at θ = 0.0625 in float32), its
    derivatives longer still, so the series runs up to x = 10 (θ ≈ 3.16). Above, with
    |F0| ≤ 1/θ < 0.32, (1 − F0)/θ² does not cancel; pass ``f0`` = sin θ/θ when it is at
    hand (from ``half_angle``: c·k) to save a sine."""

    def closed(x: jax.Array) -> jax.Array:
        if f0 is not None:
            return (1.0 - f0) / x
        theta = jnp.sqrt(x)
        return (theta - jnp.sin(theta)) / (x * theta)

    return _switched("F2", x, 10.0, closed)


def C2(x: jax.Array, f1: Optional[jax.Array] = None) -> jax.Array:
    """C2 = (θ² + 2 cos θ − 2)/(2θ⁴) = (½ − F1)/θ²; series below x = 12. Pass ``f1`` = F1(x)
    when it is at hand (from ``half_angle``: k²/2) to save a sine."""
    return _switched("C2", x, 12.0, lambda xc: (0.5 - (F1(xc) if f1 is None else f1)) / xc)


def D(x: jax.Array) -> jax.Array:
    """D = (2θ − 3 sin θ + θ cos θ)/(2θ⁵) = (C2 − 3·(1/6 − F2)/θ²)/2; series below
    x = 30, the direct formula above (writing it as a difference of C2 and F2 terms would
    cancel at large θ, where both are ≈ 1/(2θ²)). (The coupling coefficient of the SE(3)
    Jacobian, Barfoot's Q matrix.)"""

    def closed(x: jax.Array) -> jax.Array:
        theta = jnp.sqrt(x)
        return (2.0 * theta - 3.0 * jnp.sin(theta) + theta * jnp.cos(theta)) / (2.0 * x * x * theta)

    return _switched("D", x, 30.0, closed)


def G(x: jax.Array) -> jax.Array:
    """G = (1 − (θ/2) cot(θ/2))/θ², the ω̂² coefficient of the inverse SO(3) Jacobian
    and of the SE(3) log's V⁻¹ ((θ/2)cot(θ/2) = 1 − θ²G, the form of Zhang 2022, §9).

    Summed from its all-positive Bernoulli series for x < 16 (convergence ratio
    x/4π² ≤ 0.41); above that, the closed form (1 − h)/x with h < 0, which has no
    cancellation. Pole at θ = 2π."""
    switch = 16.0

    def closed(x: jax.Array) -> jax.Array:
        half = 0.5 * jnp.sqrt(x)
        return (1.0 - half * jnp.cos(half) / jnp.sin(half)) / x

    return _switched("G", x, switch, closed)


def G_principal(x: jax.Array) -> jax.Array:
    """G on the principal range x ≤ π² only (the logs' case): the series alone, with
    no closed-form branch to evaluate and discard."""
    return _horner("G", x, math.pi**2 * (1 + 1e-6))


def atan2_over(n2: jax.Array, w: jax.Array) -> jax.Array:
    """atan2(n, w) / n with n = √n2 ≥ 0 and w ≥ 0: half the SO(3) log's scale factor
    (θ = 2 atan2(n, w) for a quaternion (w, v), n = ‖v‖).

    Two half-angle reductions, atan(u) = 2 atan(u / (1 + √(1 + u²))), bring the argument
    to u′ ≤ tan(π/8) everywhere on w ≥ 0:

        r = √(n2 + w²),  u² = n2 / (w + r)²,  u′² = u² / (1 + √(1 + u²))²,
        atan2(n, w) / n = 4 A(u′²) / ((w + r)(1 + √(1 + u²))),

    with A(s) = atan(√s)/√s = Σ (−1)ᵏ sᵏ/(2k+1) summed as a polynomial (s ≤ 0.172).
    No branch, no √n2: values and derivatives of every order are smooth and accurate
    from n = 0 (the identity) to w = 0 (θ = π) inclusive, for 1e-15 < ‖q‖ < 4e18 in
    float32 (1e-145 < ‖q‖ < 1e153 in float64), measured against mpmath. Below, squares
    under 2^-126 flush to zero while w does not; what is lost stays under ε‖q‖² only for
    ‖q‖ ≳ 2^-51.5 ≈ 3e-16, and the angle is wrong (8e3 ulp at 1e-18). Above, (w + r)²
    overflows (from about 9e18) and the result is 0. (A rotation's quaternion has
    ‖q‖ ≈ 1.)"""
    wr = w + jnp.sqrt(n2 + w * w)
    inv = 1.0 / (wr + jnp.sqrt(wr * wr + n2))  # 1/((w + r)(1 + √(1 + u²)))
    return 4.0 * _horner("atan", n2 * inv * inv, _ATAN_X_MAX) * inv


def unit(v: jax.Array) -> jax.Array:
    """``v / ‖v‖`` along the last axis, for any finite nonzero ``v`` of normal floats.

    Where ``Σ vᵢ²`` overflows, or is so small (< 2^(emin + p + 2), p the significand's
    bits: float32 2^-100, float64 2^-967) that flushed squares could matter, ``v`` is first
    scaled by a power of two, 2^-(emax/2 + 2) (float32 2^-66) or 2^(3|emin|/4) (float32
    2^94; capped so that the scaled sum stays below 2^(emax − 2): float16, whose range is
    too narrow for both, gets 2^7: at 2^10 its squares overflow, NaN for components of
    0.5), which makes the largest square a normal float and keeps the sum finite.
    Power-of-two scaling is exact, so elsewhere the result is bit for bit the plain
    ``v / √(Σ vᵢ²)``, which gives 0 for a float32 quaternion with components of 3e38 and
    inf/NaN at 1e-30. A zero or non-finite ``v`` (subnormal components count as zero:
    XLA:CPU flushes them) has no direction and gives NaN in every component. Derivatives
    are those of the plain formula (the scale is piecewise constant)."""
    if not jnp.issubdtype(v.dtype, jnp.floating):  # integers: the default float, as elsewhere
        v = v.astype(jax.dtypes.canonicalize_dtype(jnp.float64))
    fi = jnp.finfo(v.dtype)
    n2 = sq_norm(v)[..., None]
    big = n2 == jnp.inf
    small_exp = fi.minexp + fi.nmant + 3
    small = n2 < 2.0**small_exp
    up = 2.0 ** min(-3 * fi.minexp // 4, (fi.maxexp - small_exp) // 2 - 1)
    down = 2.0 ** -(fi.maxexp // 2 + 2)
    scale = jnp.where(big, down, jnp.where(small, up, 1.0)).astype(v.dtype)
    s = v * scale
    n = jnp.sqrt(jnp.where(big | small, sq_norm(s)[..., None], n2))
    q = s / n
    # Where v has no direction, q already holds a NaN (0/0, inf/inf or NaN/NaN) and the sum
    # spreads it to every component. No NaN constant: under jax_debug_nans without jit, a
    # valid v must produce no NaN, even in a discarded branch.
    total = q[..., :1]
    for i in range(1, q.shape[-1]):
        total = total + q[..., i : i + 1]
    return jnp.where((n > 0) & (n < jnp.inf), q, total)


# ---------------------------------------------------------------------------------
# Joint kernels of Sim(3): functions of the log-scale σ and x = θ².
#
# Sim(3)'s exponential moves the translation by W = ∫₀¹ e^{τ(ω̂ + σI)} dτ, and
# W = D0 I + B ω̂ + C (ωωᵀ) with (axis-split form, as SE(3)'s F0, F1, F2)
#
#     A  = ∫ e^{στ} dτ                       = (e^σ − 1)/σ            (along ω)
#     D0 = ∫ e^{στ} cos τθ dτ                 = Re φ(σ + iθ)
#     B  = ∫ e^{στ} sin τθ / θ dτ             = Im φ(σ + iθ) / θ
#     C  = ∫ e^{στ} (1 − cos τθ)/θ² dτ        = (A − D0)/θ²
#
# with φ(z) = (e^z − 1)/z. Each is smooth and positive near 0 (A, B, C everywhere on
# θ ≤ π), but the textbook closed forms, e.g. B = (σ e^σ sin θ + θ(1 − e^σ cos θ)) /
# (θ(σ² + θ²)), cancel to O(|z|²) from O(1) terms as z = σ + iθ → 0 jointly, which a
# switch on θ alone or on σ alone does not remove. Here they are evaluated as
#
# * |z|² = σ² + θ² < 1/2: the double power series in σ and x, with rational coefficients
#   (from e^{στ} and the trigonometric series, integrated term by term):
#       D0 = Σ (−x)ʲ σⁿ / ((2j)! n! (n+2j+1)),   B = Σ (−x)ʲ σⁿ / ((2j+1)! n! (n+2j+2)),
#       C  = Σ (−x)ʲ σⁿ / ((2j+2)! n! (n+2j+3)),
#   truncated where the tail is below eps/8 of the sum at |z|² = 1/2;
# * elsewhere, exact weighted means of one-variable kernels, in which nothing cancels
#   (derived by writing e^σ cos θ − 1 = σ A cos θ − θ² F1 and sin θ/θ = 1 − θ² F2 in the
#   closed forms):
#       D0 = (σ² A cos θ       + θ² (e^σ F0 − σ F1)) / (σ² + θ²)
#       B  = (σ² I₁(σ)         + θ² e^σ (F1 − σ F2)) / (σ² + θ²)
#       C  = (σ² I₂(σ)/2       + θ² e^σ (F2 − σ C2)) / (σ² + θ²)
#   with Iₖ(σ) = ∫₀¹ τᵏ e^{στ} dτ (``sim3_moments``), and F0, F1, F2, C2 as above. At
#   σ = 0 they are SE(3)'s F0, F1, F2; at θ = 0 they are A, I₁ and I₂/2.
#
# Every one-variable piece is accurate to an ulp or two, and the weights σ²/(σ² + θ²),
# θ²/(σ² + θ²) lie in [0, 1], so the values are accurate. Their autodiff derivatives are
# not (the weights' derivatives multiply a difference of the two means that cancels), so
# the derivatives are members of the family T_{p,m} of the next section, in closed form
# (``sim3_coefficients``' custom JVP; docs/design/sim3-coefficients.md has the comparison).
#
# Measured worst errors in ulp against mpmath at 90 digits (``python tests/test_scalar.py``;
# ``tests/test_scalar.py`` asserts value ≤ 4, first derivatives ≤ 8, second ≤ 64), over
# σ ∈ {0, ±1e-8, ±1e-3, ±0.5, ±0.7, 2.4, 2.6, −3.9, 4.1, ±20} × θ ∈ {0, 1e-5, 1e-3, 0.1,
# 0.7, 2, π − 1e-3, π}, every partial derivative in (σ, x); scale: |f| (for D0, which
# crosses zero, the modulus √(D0² + x B²)), and x |∂f/∂x|, the change one ulp of x = θ²
# causes:
#
#     kernel   float32 (f, f′, f″)   float64 (f, f′, f″)
#     D0       2.0, 1.3, 1.8         1.3, 1.6, 3.4
#     B        1.7, 2.7, 2.8         1.8, 3.1, 4.1
#     C        1.6, 2.4, 5.8         1.9, 2.5, 5.3

_SIM3_SWITCH = 0.5  # |z|² = σ² + θ² below which the double series is summed
_SIM3_DIRECT = 2.5  # σ above which the closed forms are used as they stand
_MOMENT_SWITCH = 4.0  # |σ| below which the moments Iₖ(σ) are summed from their series


@functools.lru_cache(maxsize=None)
def _moment_series_terms(k: int, s_max: float, eps: float) -> int:
    """Terms of Σ sⁿ/(n!(n+k+1)) (its largest tail, both series of ``sim3_moments``) for the
    tail at s_max to stay below eps/16 of the sum."""
    terms = [s_max**n / (math.factorial(n) * (n + k + 1)) for n in range(90)]
    total = sum(terms)
    for n in range(1, len(terms)):
        if sum(terms[n:]) <= eps / 16 * min(total, terms[0]):
            return n
    raise AssertionError("moment series too short")  # pragma: no cover


@functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
def sim3_moments(sigma: jax.Array, k_max: int) -> jax.Array:
    """Iₖ(σ) = ∫₀¹ τᵏ e^{στ} dτ for k = 0 … k_max, stacked on a new last axis.

    I₀ = (e^σ − 1)/σ, I₁ = φ′(σ), I₂ = φ″(σ) for φ(σ) = I₀(σ); dIₖ/dσ = Iₖ₊₁ exactly (the
    custom JVP: derivatives of every order are values of the same function).

    Values, for |σ| < 4 from series with only positive terms,

        σ ≥ 0:  Iₖ = Σ σⁿ / (n! (n+k+1)),
        σ < 0:  Iₖ = k! e^σ Σ |σ|ⁿ / (n+k+1)!     (Kummer's transformation, τ → 1 − τ),

    and for |σ| ≥ 4 from I₀ = expm1(σ)/σ and the recursion Iₖ = (e^σ − k Iₖ₋₁)/σ (from
    integrating by parts), which loses less than a factor 2.2 per step there for
    k ≤ 4 (the orders a Hessian of Sim(3)'s C needs). e^σ overflows beyond σ ≈ 88
    (float32) and 709 (float64); below σ ≈ −87 (float32) it underflows and Iₖ → k!/|σ|ᵏ⁺¹
    is still returned by the recursion.
    """
    eps = float(jnp.finfo(sigma.dtype).eps)
    small = jnp.abs(sigma) < _MOMENT_SWITCH
    s = jnp.clip(sigma, -2.0 * _MOMENT_SWITCH, 2.0 * _MOMENT_SWITCH)
    a = jnp.abs(s)
    e_small = jnp.exp(s)
    out_small = []
    for k in range(k_max + 1):
        n = _moment_series_terms(k, _MOMENT_SWITCH, eps)
        pos = jnp.full_like(a, 1.0 / (n - 1 + k + 1) / math.factorial(n - 1))
        neg = jnp.full_like(a, 1.0 / math.factorial(n - 1 + k + 1))
        for m in range(n - 2, -1, -1):
            pos = pos * a + 1.0 / (math.factorial(m) * (m + k + 1))
            neg = neg * a + 1.0 / math.factorial(m + k + 1)
        out_small.append(jnp.where(sigma < 0, math.factorial(k) * e_small * neg, pos))
    b = jnp.where(jnp.abs(sigma) < 1.0, 1.0, sigma)
    e_big = jnp.exp(b)
    prev = jnp.expm1(b) / b
    out_big = [prev]
    for k in range(1, k_max + 1):
        prev = (e_big - k * prev) / b
        out_big.append(prev)
    return jnp.stack([jnp.where(small, lo, hi) for lo, hi in zip(out_small, out_big)], axis=-1)


@sim3_moments.defjvp
def _sim3_moments_jvp(k_max, primals, tangents):  # type: ignore[no-untyped-def]
    (sigma,), (dsigma,) = primals, tangents
    moments = sim3_moments(sigma, k_max + 1)
    return moments[..., :-1], moments[..., 1:] * dsigma[..., None]


@functools.lru_cache(maxsize=None)
def _sim3_series_coeffs(which: int, eps: float) -> list[list[float]]:
    """Coefficients c[j][n] of the double series of D0 (which = 0), B (1) or C (2) in
    (−x)ʲ σⁿ, truncated where the terms' tail at |z|² = 1/2 is below eps/8 of the sum."""
    r = math.sqrt(_SIM3_SWITCH)

    def coef(j: int, n: int) -> float:
        return 1.0 / (math.factorial(2 * j + which) * math.factorial(n) * (n + 2 * j + which + 1))

    # bound each term by its value at |σ| = r, x = r² (a bound on the disc's terms)
    degree = 1
    while True:
        tail = sum(
            coef(j, n) * r ** (n + 2 * j)
            for m in range(degree + 1, degree + 40)
            for j in range(m // 2 + 1)
            for n in [m - 2 * j]
        )
        if tail <= eps / 8 * coef(0, 0) / 4:
            break
        degree += 1
    return [[coef(j, n) for n in range(degree - 2 * j + 1)] for j in range(degree // 2 + 1)]


def sim3_coefficients(
    sigma: jax.Array, x: jax.Array, half: Optional[Tuple[jax.Array, jax.Array]] = None
) -> Tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """(A, D0, B, C) of Sim(3)'s W = D0 I + B ω̂ + C ωωᵀ (see the section comment), for
    log-scale σ and x = θ² of one shape and dtype; ``half`` = (cos(θ/2), sin(θ/2)/(θ/2))
    where the caller has them more accurately than from x (a log reads them off the
    quaternion: near π, cos(θ/2) recomputed from the rounded θ cost 5 ulp in v).

    Values: the double series near 0, the weighted means or (σ ≥ 2.5) the closed forms
    elsewhere. Derivatives (custom JVP): members of ``sim3_family``, e.g. ∂B/∂x =
    (T_{0,3} − T_{1,2})/2, in closed form, where autodiff of the weighted means cancels
    (8.9e3 ulp in ∂²D0/∂x² at σ = −20). Under differentiation the values come from the
    same family call (within 3 ulp of the others), so a differentiated program holds one
    evaluation of the family and none of the switched forms."""
    c_h, k_h = half_angle(x) if half is None else half
    return _sim3_coefficients(sigma, x, c_h, k_h)


@jax.custom_jvp
def _sim3_coefficients(
    sigma: jax.Array, x: jax.Array, c_h: jax.Array, k_h: jax.Array
) -> Tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """``sim3_coefficients``' values; c_h and k_h are functions of x, so the JVP reads
    only σ's and x's tangents."""
    eps = float(jnp.finfo(x.dtype).eps)
    near = sigma * sigma + x < _SIM3_SWITCH
    s_n, x_n = jnp.clip(sigma, -1.0, 1.0), jnp.minimum(x, 1.0)  # clamped away from |z|² = ½
    series = []
    for which in range(3):
        rows = _sim3_series_coeffs(which, eps)
        acc = jnp.zeros_like(s_n)
        for row in reversed(rows):  # Σⱼ (−x)ʲ Pⱼ(σ), each Pⱼ by Horner's scheme
            poly = jnp.full_like(s_n, row[-1])
            for coef in reversed(row[:-1]):
                poly = poly * s_n + coef
            acc = poly - x_n * acc
        series.append(acc)
    # away from 0: the weighted means (σ² + x ≥ 1/2 there; clamped only in the divisor)
    I = sim3_moments(sigma, 2)
    e = jnp.exp(sigma)
    f0 = c_h * k_h
    f1 = 0.5 * k_h * k_h
    f2, c2 = F2(x, f0), C2(x)
    # cos θ: 1 − θ² F1 below π/2, 2 cos²(θ/2) − 1 above (no rounding of 2 near π)
    cos_t = jnp.where(c_h * c_h < 0.5, 2.0 * c_h * c_h - 1.0, 1.0 - x * f1)
    s2 = sigma * sigma
    inv = 1.0 / jnp.where(s2 + x > 0.0, s2 + x, 1.0)
    big = sigma >= _SIM3_DIRECT
    d0 = jnp.where(
        big,
        sigma * (e * cos_t - 1.0) + x * e * f0,
        s2 * I[..., 0] * cos_t + x * (e * f0 - sigma * f1),
    )
    b = jnp.where(big, sigma * e * f0 - e * cos_t + 1.0, s2 * I[..., 1] + x * e * (f1 - sigma * f2))
    c = jnp.where(
        big,
        I[..., 0] - e * f0 + sigma * e * f1,
        s2 * 0.5 * I[..., 2] + x * e * (f2 - sigma * c2),
    )
    d0, b, c = d0 * inv, b * inv, c * inv
    return (
        I[..., 0],
        jnp.where(near, series[0], d0),
        jnp.where(near, series[1], b),
        jnp.where(near, series[2], c),
    )


# ---------------------------------------------------------------------------------
# The derivative family of Sim(3)'s kernels.
#
# D0, B and C are members of the two-index family
#
#     T_{p,m}(σ, x) = ∫₀¹ e^{στ} τ^{p+m} g_m(τ²x) dτ,   g_m(y) = Σⱼ (−y)ʲ/(2j+m)!,
#
# g₀ = cos θ, g₁ = sin θ/θ, g₂ = F1, g₃ = F2, g₄ = C2 (as functions of y = θ²): D0 = T_{0,0},
# B = T_{0,1}, C = T_{0,2}. Differentiating under the integral closes the family:
#
#     ∂T_{p,m}/∂σ = T_{p+1,m},      ∂T_{p,m}/∂x = −(T_{p+1,m+1} − m T_{p,m+2})/2,
#
# the second from g_m′ = −(g_{m+1} − m g_{m+2})/2 (compare the series term by term), so the
# derivatives of every order of D0, B and C are values of the same family, evaluated by
# one formula (``sim3_family``, whose custom JVP applies these two rules). Three
# expressions of T_{p,m}, each used where it loses at most a few ulp (measured against
# mpmath at 90 digits over σ ∈ [−20, 20], θ ∈ [0, π], p ≤ 3, m ≤ 6):
#
# * |σ| < 8, the series in x over the moments Iₙ(σ) = ∫₀¹ τⁿ e^{στ} dτ:
#       T_{p,m} = Σⱼ (−x)ʲ I_{p+m+2j}(σ)/(2j+m)!,
#   for m ≥ 2 up to x = 10 (θ ≈ 3.16; its terms alternate, but lose at most a factor 2.7
#   at θ = π, for m = 3), for m ≤ 1 up to x = 4 (θ = 2; beyond, the cosine's and sine's
#   own series lose up to a factor cosh θ). The moments come from the downward recursion
#   I_{n−1} = (e^σ − σIₙ)/n, stable for n > σ, started from Kummer's series
#   Iₙ = n! e^σ Σₖ (−σ)ᵏ/(n+k+1)! (ratio |σ|/(n+2) < 1/5), and for n + 1 < σ from the
#   upward recursion Iₙ = (e^σ − n I_{n−1})/σ, stable there: within 2.4 ulp for n ≤ 40.
# * the complex closed forms, for m ≤ 1 where |σ| ≥ 8 or x ≥ 4: D_p + iθB_p = φ_p(z),
#   φ_p(z) = ∫₀¹ τ^p e^{zτ} dτ at z = σ + iθ, φ₀ = (e^z − 1)/z and φ_p = (e^z − pφ_{p−1})/z
#   (integration by parts), carried as pairs (a, b) for a + iθb, so that θ never divides:
#       (a, b)·z = (aσ − xb, a + σb),   (a, b)/z = ((aσ + xb), (σb − a))/(σ² + x),
#   with e^z − 1 = (expm1(σ) cos θ − x F1, e^σ sin θ/θ).
# * for m ≥ 2 where |σ| ≥ 8, integration by parts in τ, upward in m:
#       σ T_{p,m} = e^σ g_m(x) − p T_{p−1,m} − T_{p,m−1},
#   stable for |σ| > m (each step divides the previous error by about |σ|/m); and for
#   m ≥ 2 beyond x = 10 (exp's derivatives beyond π) with |σ| < 8: the same recursion for
#   σ ≤ −4, else g_m(y) = 1/m! − y g_{m+2}(y):
#       T_{p,m} = (I_{p+m−2}(σ)/(m−2)! − T_{p,m−2})/x.
#
# Every branch is evaluated on the true (σ, x) near its region's edges (clamped only far
# from them, where a value is discarded): XLA may recompute x in several fused copies that
# round it differently, so a lane can select one branch by one copy's test while another
# copy clamped that branch's input; a clamp at the edge itself then returned garbage
# (measured: D0 = 0.026 for 0.426 at x = 4 − 2⁻²², in a batch of 45 only).
#
# Measured worst errors in ulp against mpmath at 90 digits, σ ∈ {0, ±1e-8, ±0.1, ±0.5, ±1,
# ±2, ±3, ±4, ±5, ±6, 8 ± 1e-4, −8 ± 1e-4, ±12, ±20} × θ ∈ {0, 1e-5, 1e-3, 0.1, 0.5, 1,
# 1.5, 2 ± 1e-4, 2.5, 3, √10 ± 5e-5, π}, scale as in the table above (m = 0: the modulus
# of φ_p), float32 / float64:
#
#     members                               θ ≤ π         beyond π (3.5, 5, 10)
#     p ≤ 1, m ≤ 4 (first derivatives)      2.4 / 2.5     3.7 / 2.7
#     p ≤ 3, −1 ≤ m ≤ 6                     4.6 / 6.3     21.6 / 35.7

_FAMILY_SIGMA = 8.0  # |σ| below which the x-series over moments is used
_FAMILY_X_LOW = 4.0  # x up to which T_{p,0}, T_{p,1} are summed from the x-series
_FAMILY_X_HIGH = 10.0  # x up to which T_{p,m}, m ≥ 2, are summed from the x-series


@functools.lru_cache(maxsize=None)
def _family_terms(m: int, x_max: float, eps: float) -> int:
    """Terms of Σⱼ (−x)ʲ I_{n+2j}/(2j+m)! for its tail at x_max to stay below eps/32 of its
    first term (the moments decrease with n: τ^{n+2} ≤ τⁿ on [0, 1])."""
    j = 1
    while x_max**j * math.factorial(m) / math.factorial(2 * j + m) > eps / 32:
        j += 1
    return j


@functools.lru_cache(maxsize=None)
def _kummer_terms(n: int, eps: float) -> int:
    """Terms of Kummer's series of Iₙ(σ) for |σ| < _FAMILY_SIGMA (ratio |σ|/(n+k+2))."""
    k, term = 0, 1.0
    while term > eps / 32:
        k += 1
        term *= _FAMILY_SIGMA / (n + k + 1)
    return k + 1


def _moments_upto(sigma: jax.Array, e: jax.Array, n_max: int) -> list[jax.Array]:
    """[I₀(σ), …, I_{n_max}(σ)] for |σ| < _FAMILY_SIGMA, e = e^σ (the section comment's
    recursions)."""
    eps = float(jnp.finfo(sigma.dtype).eps)
    top = n_max + 2
    acc = jnp.zeros_like(sigma)
    for k in reversed(range(_kummer_terms(top, eps))):
        acc = acc * -sigma + 1.0 / math.prod(range(top + 1, top + k + 2))
    moments = [e * acc]
    for n in range(top, 0, -1):
        moments.append((e - sigma * moments[-1]) / n)
    out = moments[::-1][: n_max + 1]
    # the upward recursion where n + 1 < σ < _FAMILY_SIGMA (e − 1 = expm1(σ) to an ulp there)
    s = jnp.where(sigma > 1.0, sigma, 1.0)
    inv = 1.0 / s
    up = (e - 1.0) * inv
    for n in range(min(n_max, int(_FAMILY_SIGMA) - 2) + 1):
        if n:
            up = (e - n * up) * inv
        out[n] = jnp.where(sigma > n + 1, up, out[n])
    return out


def _recur_g(top: float, lower: jax.Array, x: jax.Array) -> jax.Array:
    """(top − lower)/x: g_m = (1/(m−2)! − g_{m−2})/x above its switch."""
    return (top - lower) / x


def _g_list(m_max: int, x: jax.Array) -> list[jax.Array]:
    """[g₀(x), …, g_{m_max}(x)], g_m(x) = Σⱼ (−x)ʲ/(2j+m)!: cos θ, sin θ/θ, F1, F2, C2 from one
    ``half_angle`` (cos θ as 2cos²(θ/2) − 1 beyond π/2, where it does not round away 2),
    and beyond from g_m = (1/(m−2)! − g_{m−2})/x above x = 30 (its series below)."""
    c, k = half_angle(x)
    f1 = 0.5 * k * k
    g = [jnp.where(c * c < 0.5, 2.0 * c * c - 1.0, 1.0 - x * f1), c * k, f1]
    g += [F2(x, g[1]), C2(x, f1)]
    for m in range(5, m_max + 1):
        name = f"g{m}"
        _COEFFS.setdefault(
            name,
            tuple(float(Fraction((-1) ** j, math.factorial(2 * j + m))) for j in range(_N_MAX)),
        )
        top, lower = 1.0 / math.factorial(m - 2), g[m - 2]
        g.append(_switched(name, x, 30.0, functools.partial(_recur_g, top, lower)))
    return g[: m_max + 1]


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def sim3_family(
    sigma: jax.Array, x: jax.Array, index: Tuple[Tuple[int, int], ...]
) -> Tuple[jax.Array, ...]:
    """T_{p,m}(σ, x) = ∫₀¹ e^{στ} τ^{p+m} g_m(τ²x) dτ for each (p, m) of ``index``, a tuple
    of arrays of σ's and x's (common) shape and dtype; D0, B, C are (0, 0), (0, 1), (0, 2),
    and m = −1 stands for the moment I_p(σ) = ∫₀¹ τ^p e^{στ} dτ (A = I₀).
    (A tuple, not a stacked array: XLA:CPU vectorises a fused loop with separate outputs,
    not one that writes them interleaved; docs/design/sim3-coefficients.md.)

    The section comment has the three expressions and their regions. Derivatives (custom
    JVP) are members of the family: ∂/∂σ raises p, ∂/∂x = −(T_{p+1,m+1} − m T_{p,m+2})/2,
    so derivatives of every order are exact formulas, with no quadrature and no autodiff
    of the expressions. e^σ overflows beyond σ ≈ 88 (float32) and 709 (float64)."""
    eps = float(jnp.finfo(x.dtype).eps)
    p_max = max(p for p, _ in index)
    m_max = max(m for _, m in index)
    big = jnp.abs(sigma) >= _FAMILY_SIGMA
    low = x < _FAMILY_X_LOW
    high = x < _FAMILY_X_HIGH
    e = jnp.exp(sigma)

    # the complex closed forms (m ≤ 1) where |σ| ≥ 8 or x ≥ 4 (e^z − 1 without expm1:
    # |e^z − 1| > 1.6 there), and from them m ≥ 2 for |σ| ≥ 8 (integration by parts)
    closed = big | ~low
    g = _g_list(max(m_max, 1), x)
    e_cos, e_sinc = e * g[0], e * g[1]
    z2 = sigma * sigma + x
    inv = 1.0 / jnp.where(z2 > 0.0, z2, 1.0)
    a, b = e_cos - 1.0, e_sinc
    table: list[list[jax.Array]] = []
    for p in range(p_max + 1):
        if p:
            a, b = e_cos - p * table[-1][0], e_sinc - p * table[-1][1]
        table.append([(a * sigma + x * b) * inv, (sigma * b - a) * inv])
    # where |σ| ≥ 8, and beyond x = 10 for σ ≤ −4 (where the last expression cancels)
    recur = big | (~high & (sigma <= -0.5 * _FAMILY_SIGMA))
    inv_s = 1.0 / jnp.where(jnp.abs(sigma) < 1.0, 1.0, sigma)
    for m in range(2, m_max + 1):
        e_g = e * g[m]
        for p in range(p_max + 1):
            v = e_g - table[p][m - 1]
            if p:
                v = v - p * table[p - 1][m]
            table[p].append(v * inv_s)

    # the x-series over the moments for |σ| < 8
    s_x = jnp.clip(sigma, -_FAMILY_SIGMA, _FAMILY_SIGMA)
    e_x = jnp.exp(s_x)
    x_lo, x_hi = jnp.minimum(x, _FAMILY_X_LOW), jnp.minimum(x, _FAMILY_X_HIGH)
    terms = {
        m: _family_terms(m, _FAMILY_X_LOW if m < 2 else _FAMILY_X_HIGH, eps)
        for m in range(max(m_max, 0) + 1)
    }
    n_max = max(p + (m + 2 * terms[m] - 2 if m >= 0 else 0) for p, m in index)
    moments = _moments_upto(s_x, e_x, n_max)

    def series(p: int, m: int) -> jax.Array:
        xs = x_lo if m < 2 else x_hi
        acc = jnp.zeros_like(xs)
        for j in reversed(range(terms[m])):
            acc = acc * -xs + moments[p + m + 2 * j] * (1.0 / math.factorial(2 * j + m))
        return acc

    # beyond x = 10 for |σ| < 8: T_{p,m} = (I_{p+m−2}/(m−2)! − T_{p,m−2})/x
    inv_far = 1.0 / jnp.maximum(x, _FAMILY_X_HIGH)
    far: dict[Tuple[int, int], jax.Array] = {}

    def beyond(p: int, m: int) -> jax.Array:
        if m < 2:
            return table[p][m]
        if (p, m) not in far:
            lower = beyond(p, m - 2)
            far[p, m] = (moments[p + m - 2] * (1.0 / math.factorial(m - 2)) - lower) * inv_far
        return far[p, m]

    out = []
    for p, m in index:
        if m < 0:  # I_p: (e^σ − p I_{p−1})/σ upward for |σ| ≥ 8
            up = (e - 1.0) * inv_s
            for n in range(1, p + 1):
                up = (e - n * up) * inv_s
            value = jnp.where(big, up, moments[p])
        elif m < 2:
            value = jnp.where(closed, table[p][m], series(p, m))
        else:
            value = jnp.where(recur, table[p][m], jnp.where(high, series(p, m), beyond(p, m)))
        out.append(value)
    return tuple(out)


@sim3_family.defjvp
def _sim3_family_jvp(index, primals, tangents):  # type: ignore[no-untyped-def]
    sigma, x = primals
    d_sigma, d_x = tangents
    derived = sorted(
        {(p + 1, m) for p, m in index}
        | {(p + 1, m + 1) for p, m in index if m >= 0}
        | {(p, m + 2) for p, m in index if m > 0}
    )
    values = sim3_family(sigma, x, index)
    at = dict(zip(derived, sim3_family(sigma, x, tuple(derived))))
    cols = []
    for p, m in index:
        d = at[p + 1, m] * d_sigma
        if m >= 0:
            d = d - 0.5 * at[p + 1, m + 1] * d_x
        if m > 0:
            d = d + 0.5 * m * at[p, m + 2] * d_x
        cols.append(d)
    return values, tuple(cols)


@_sim3_coefficients.defjvp
def _sim3_coefficients_jvp(primals, tangents):  # type: ignore[no-untyped-def]
    sigma, x = primals[:2]
    d_sigma, d_x = tangents[:2]
    a, d0, b, c, a1, d1_0, d1_1, d1_2, d0_3, d1_3, d0_4 = sim3_family(
        sigma, x, COEFFICIENTS_AND_DERIVATIVES
    )
    d_a = a1 * d_sigma
    d_d0 = d1_0 * d_sigma - 0.5 * d1_1 * d_x
    d_b = d1_1 * d_sigma + 0.5 * (d0_3 - d1_2) * d_x
    d_c = d1_2 * d_sigma + (d0_4 - 0.5 * d1_3) * d_x
    return (a, d0, b, c), (d_a, d_d0, d_b, d_c)


# The members of the family that (A, D0, B, C) and their first derivatives read, in this
# order: A = I₀, D0, B, C; A_σ = I₁; the derivatives of D0, B, C (``_sim3_coefficients_jvp``).
COEFFICIENTS_AND_DERIVATIVES = (
    (0, -1),
    (0, 0),
    (0, 1),
    (0, 2),
    (1, -1),
    (1, 0),
    (1, 1),
    (1, 2),
    (0, 3),
    (1, 3),
    (0, 4),
)
