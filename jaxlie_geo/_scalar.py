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
no NaN or inf from the unused branch reaches a gradient. The switch sits where the
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

import decimal
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


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """Dot product over the last axis, ``(*batch, n) -> batch``, written out as products and
    sums rather than a reduction, so that it stays in its neighbours' fused loop."""
    out = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        out = out + a[..., i] * b[..., i]
    return out


def sq_norm(w: jax.Array) -> jax.Array:
    """Σ wᵢ² over the last axis (``dot(w, w)``)."""
    return dot(w, w)


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


def C2(x: jax.Array) -> jax.Array:
    """C2 = (θ² + 2 cos θ − 2)/(2θ⁴) = (½ − F1)/θ²; series below x = 12."""
    return _switched("C2", x, 12.0, lambda x: (0.5 - F1(x)) / x)


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
# the derivatives come from Gauss–Legendre quadrature of the differentiated integrands
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
#     D0       2.0, 3.4, 3.9         1.3, 1.0, 1.0
#     B        1.6, 3.2, 3.9         1.8, 1.6, 1.7
#     C        2.3, 3.1, 4.0         2.9, 1.0, 1.9

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
    s = jnp.where(small, sigma, 0.0)
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
    b = jnp.where(small, _MOMENT_SWITCH, sigma)
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
    elsewhere. Derivatives (custom JVP): Gauss–Legendre quadrature (``_sim3_integrals``) of
    the integrands and of their derivatives, e.g. ∂B/∂x = ∫ e^{στ} τ ∂sinc(τ²x)/∂x dτ, with
    ``sinc``, ``cos_`` and ``F1`` of τ²x and their exact derivatives: nothing there
    cancels, where autodiff of the weighted means does (8.9e3 ulp in ∂²D0/∂x² at
    σ = −20). Under differentiation the values come from the same quadrature (within
    2.6 ulp of the others), so a differentiated program holds one plain, differentiable
    expression: its Hessian compiles 2.6x faster than through the switched forms. The
    quadrature is exact to rounding for |σ| ≤ 20 (see ``_SIM3_NODES``)."""
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
    s_n, x_n = jnp.where(near, sigma, 0.0), jnp.where(near, x, 0.0)
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
    inv = 1.0 / jnp.where(near, 1.0, s2 + x)
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


# Gauss–Legendre nodes on [0, 1] for the JVP of ``sim3_coefficients``: exact for polynomials
# of degree 2n − 1; e^{στ} at |σ| = 20 needs n = 30 for float64's eps, 22 for float32's.
_SIM3_NODES = {4: 28, 8: 40}


@functools.lru_cache(maxsize=None)
def _gauss_legendre(n: int) -> Tuple[Tuple[float, ...], Tuple[float, ...]]:
    """Gauss–Legendre nodes and weights on [0, 1], correctly rounded to float64: Newton's
    iteration on Pₙ at 40 decimal digits (``decimal``), from Chebyshev-like first guesses
    (numpy's ``leggauss`` weights are off by up to ~1e-14 relative for n = 40)."""
    ctx = decimal.Context(prec=40)
    one, two = decimal.Decimal(1), decimal.Decimal(2)

    def legendre(z: decimal.Decimal) -> Tuple[decimal.Decimal, decimal.Decimal]:
        p0, p1 = one, z
        for k in range(2, n + 1):
            p0, p1 = p1, ctx.divide((2 * k - 1) * z * p1 - (k - 1) * p0, decimal.Decimal(k))
        dp = ctx.divide(n * (z * p1 - p0), z * z - one)
        return p1, dp

    nodes, weights = [], []
    for i in range(1, n + 1):
        z = decimal.Decimal(math.cos(math.pi * (i - 0.25) / (n + 0.5)))
        for _ in range(8):
            p, dp = legendre(z)
            z = ctx.subtract(z, ctx.divide(p, dp))
        _, dp = legendre(z)
        nodes.append(float((one - z) / two))  # τ = (1 − z)/2 ∈ (0, 1), ascending
        weights.append(float(ctx.divide(one, (one - z * z) * dp * dp)))  # (2/((1−z²)P′²))/2
    return tuple(nodes), tuple(weights)


def _sim3_integrals(sigma: jax.Array, x: jax.Array) -> jax.Array:
    """(A, D0, B, C) by quadrature, stacked on a new last axis: ∫ e^{στ} g(τ) dτ for
    g = 1, cos τθ, τ sinc τθ and τ² F1(τ²θ²), each written with the kernels above as a
    function of τ²x."""
    nodes, weights = _gauss_legendre(_SIM3_NODES.get(jnp.dtype(x.dtype).itemsize, 40))
    shape = (1,) * x.ndim + (len(nodes),)  # the nodes on a new last axis, ranks equal
    tau = jnp.asarray(nodes, x.dtype).reshape(shape)
    w = jnp.asarray(weights, x.dtype).reshape(shape)
    t2x = tau * tau * x[..., None]
    e = w * jnp.exp(sigma[..., None] * tau)
    parts = (e, e * cos_(t2x), e * tau * sinc(t2x), e * tau * tau * F1(t2x))
    return jnp.stack([jnp.sum(p, axis=-1) for p in parts], axis=-1)


@_sim3_coefficients.defjvp
def _sim3_coefficients_jvp(primals, tangents):  # type: ignore[no-untyped-def]
    out, d = jax.jvp(_sim3_integrals, primals[:2], tangents[:2])
    return tuple(out[..., i] for i in range(4)), tuple(d[..., i] for i in range(4))
