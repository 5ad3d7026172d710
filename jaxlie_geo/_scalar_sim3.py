"""The numerically delicate scalar functions of Sim(3): its joint kernels, functions of the
log-scale σ and x = θ² (``_scalar`` has the one-variable kernels they build on).

Sim(3)'s exponential moves the translation by W = ∫₀¹ e^{τ(ω̂ + σI)} dτ, and
W = D0 I + B ω̂ + C (ωωᵀ) with (axis-split form, as SE(3)'s F0, F1, F2)

    A  = ∫ e^{στ} dτ                       = (e^σ − 1)/σ            (along ω)
    D0 = ∫ e^{στ} cos τθ dτ                 = Re φ(σ + iθ)
    B  = ∫ e^{στ} sin τθ / θ dτ             = Im φ(σ + iθ) / θ
    C  = ∫ e^{στ} (1 − cos τθ)/θ² dτ        = (A − D0)/θ²

with φ(z) = (e^z − 1)/z. Each is smooth and positive near 0 (A, B, C everywhere on
θ ≤ π), but the textbook closed forms, e.g. B = (σ e^σ sin θ + θ(1 − e^σ cos θ)) /
(θ(σ² + θ²)), cancel to O(|z|²) from O(1) terms as z = σ + iθ → 0 jointly, which a
switch on θ alone or on σ alone does not remove. Here they are evaluated as

* |z|² = σ² + θ² < 1/2: the double power series in σ and x, with rational coefficients
  (from e^{στ} and the trigonometric series, integrated term by term):
      D0 = Σ (−x)ʲ σⁿ / ((2j)! n! (n+2j+1)),   B = Σ (−x)ʲ σⁿ / ((2j+1)! n! (n+2j+2)),
      C  = Σ (−x)ʲ σⁿ / ((2j+2)! n! (n+2j+3)),
  truncated where the tail is below eps/8 of the sum at |z|² = 1/2;
* elsewhere, exact weighted means of one-variable kernels, in which nothing cancels
  (derived by writing e^σ cos θ − 1 = σ A cos θ − θ² F1 and sin θ/θ = 1 − θ² F2 in the
  closed forms):
      D0 = (σ² A cos θ       + θ² (e^σ F0 − σ F1)) / (σ² + θ²)
      B  = (σ² I₁(σ)         + θ² e^σ (F1 − σ F2)) / (σ² + θ²)
      C  = (σ² I₂(σ)/2       + θ² e^σ (F2 − σ C2)) / (σ² + θ²)
  with Iₖ(σ) = ∫₀¹ τᵏ e^{στ} dτ (``sim3_moments``), and F0, F1, F2, C2 as in ``_scalar``. At
  σ = 0 they are SE(3)'s F0, F1, F2; at θ = 0 they are A, I₁ and I₂/2.

Every one-variable piece is accurate to an ulp or two, and the weights σ²/(σ² + θ²),
θ²/(σ² + θ²) lie in [0, 1], so the values are accurate. Their autodiff derivatives are
not (the weights' derivatives multiply a difference of the two means that cancels), so
the derivatives are members of the family T_{p,m} below (``sim3_family``), in closed form
(``sim3_coefficients``' custom JVP; docs/design/sim3-coefficients.md has the comparison).

Measured worst errors in ulp against mpmath at 90 digits (``python tests/test_scalar.py``;
``tests/test_scalar.py`` asserts value ≤ 4, first derivatives ≤ 8, second ≤ 64), over
σ ∈ {0, ±1e-8, ±1e-3, ±0.5, ±0.7, 2.4, 2.6, −3.9, 4.1, ±20} × θ ∈ {0, 1e-5, 1e-3, 0.1,
0.7, 2, π − 1e-3, π}, every partial derivative in (σ, x); scale: |f| (for D0, which
crosses zero, the modulus √(D0² + x B²)), and x |∂f/∂x|, the change one ulp of x = θ²
causes:

    kernel   float32 (f, f′, f″)   float64 (f, f′, f″)
    D0       2.0, 1.3, 1.8         1.3, 1.6, 3.4
    B        1.7, 2.7, 2.8         1.8, 3.1, 4.1
    C        1.6, 2.4, 5.8         1.9, 2.5, 5.3
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction
from typing import Optional, Tuple

import jax
import jax.numpy as jnp

from ._scalar import _COEFFS, _N_MAX, C2, F2, _switched, half_angle

__all__ = ["sim3_moments", "sim3_coefficients", "sim3_family", "COEFFICIENTS_AND_DERIVATIVES"]


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
