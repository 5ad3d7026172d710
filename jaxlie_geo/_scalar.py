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

Sim(3)'s coefficients are functions of two variables, the log-scale σ and x = θ²: they live
in ``_scalar_sim3``, with their series, switches and error table.
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
