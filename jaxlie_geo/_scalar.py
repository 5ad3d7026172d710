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

Both branches are evaluated on clamped arguments (the ``jnp.where``-safe pattern), so
no NaN or inf from the unused branch reaches a gradient. The switch sits where the
closed form's value *and its first two autodiff derivatives* are accurate, which for
cancellation-prone kernels is far from zero (e.g. ``x = 6`` for F2): a trig formula
above a small cutoff is not enough (seed 001 §11.4 and issue [2]).

Notation (seed 001 §9–11, with θ² = x):

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

Measured worst errors (float32 / float64, in ulp of the value, against mpmath at 50
digits, over the kernels' whole domain including subnormal and exactly-zero inputs)
are reported by ``tests/scalar/test_scalar_accuracy.py``; see the README's accuracy
section.
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction
from typing import Callable

import jax
import jax.numpy as jnp

__all__ = ["cos_", "sinc", "F1", "F2", "C2", "D", "G", "G_principal", "atan2_over"]


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


_N_MAX = 40  # longest series any kernel may need (G in float64 needs ~27 terms)

_COEFFS: dict[str, tuple[float, ...]] = {
    "cos": tuple(float(Fraction((-1) ** k, math.factorial(2 * k))) for k in range(_N_MAX)),
    "sinc": tuple(
        float(Fraction((-1) ** k, math.factorial(2 * k + 1))) for k in range(_N_MAX)
    ),
    "F2": tuple(
        float(Fraction((-1) ** k, math.factorial(2 * k + 3))) for k in range(_N_MAX)
    ),
    "C2": tuple(
        float(Fraction((-1) ** k, math.factorial(2 * k + 4))) for k in range(_N_MAX)
    ),
    "D": tuple(
        float(Fraction((-1) ** k * (k + 1), math.factorial(2 * k + 5)))
        for k in range(_N_MAX)
    ),
    "G": tuple(
        float(abs(b) / math.factorial(2 * k + 2))
        for k, b in enumerate(_bernoulli_even(_N_MAX + 1)[1:])
    ),
}


@functools.lru_cache(maxsize=None)
def _n_terms(name: str, x_max: float, eps: float) -> int:
    """Fewest terms whose truncation error at ``x_max`` is below ``eps / 8`` of the
    smallest partial sum magnitude (a proxy for the function's size there)."""
    coeffs = _COEFFS[name]
    partial = 0.0
    smallest = math.inf
    for k, c in enumerate(coeffs):
        term = c * x_max**k
        partial += term
        smallest = min(smallest, abs(partial))
        tail = sum(abs(cc) * x_max**j for j, cc in enumerate(coeffs) if j > k)
        if tail <= eps / 8 * smallest:
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
# Kernels. All take x = θ² >= 0 (any shape, floating dtype) and return x's dtype.


def cos_(x: jax.Array) -> jax.Array:
    """cos θ as a function of x = θ². Series below x = 1."""
    return _switched("cos", x, 1.0, lambda x: jnp.cos(jnp.sqrt(x)))


def sinc(x: jax.Array) -> jax.Array:
    """F0 = sin θ / θ as a function of x = θ² (seed 001 §11.1). Series below x = 1."""

    def closed(x: jax.Array) -> jax.Array:
        theta = jnp.sqrt(x)
        return jnp.sin(theta) / theta

    return _switched("sinc", x, 1.0, closed)


def F1(x: jax.Array) -> jax.Array:
    """F1 = (1 − cos θ)/θ² = ½ sinc(θ/2)², which has no cancellation anywhere."""
    half = sinc(0.25 * x)
    return 0.5 * half * half


def F2(x: jax.Array) -> jax.Array:
    """F2 = (θ − sin θ)/θ³ (seed 001 §11.3; eq. 42's third term is θ⁴/7!).

    The closed form cancels below θ ≈ 1.7 (1000 ulp at θ = 0.0625 in float32), its
    derivatives longer still, so the series runs up to x = 6 (θ ≈ 2.45)."""

    def closed(x: jax.Array) -> jax.Array:
        theta = jnp.sqrt(x)
        return (theta - jnp.sin(theta)) / (x * theta)

    return _switched("F2", x, 6.0, closed)


def C2(x: jax.Array) -> jax.Array:
    """C2 = (θ² + 2 cos θ − 2)/(2θ⁴) = (½ − F1)/θ²; series below x = 10."""
    return _switched("C2", x, 10.0, lambda x: (0.5 - F1(x)) / x)


def D(x: jax.Array) -> jax.Array:
    """D = (2θ − 3 sin θ + θ cos θ)/(2θ⁵) = (C2 − 3·(1/6 − F2)/θ²)/2; series below
    x = 10. (The coupling coefficient of the SE(3) Jacobian, Barfoot's Q matrix.)"""
    return _switched("D", x, 10.0, lambda x: 0.5 * (C2(x) - 3.0 * (1.0 / 6.0 - F2(x)) / x))


def G(x: jax.Array) -> jax.Array:
    """G = (1 − (θ/2) cot(θ/2))/θ², the ω̂² coefficient of the inverse SO(3) Jacobian
    and of the SE(3) log's V⁻¹ (the seeds' (θ/2)cot(θ/2) form: 1 − θ²G).

    Summed from its all-positive Bernoulli series for x ≤ π² (the principal range,
    convergence ratio ≤ 1/4); above that, the closed form (1 − h)/x with h ≤ 0, which
    has no cancellation. Pole at θ = 2π."""
    switch = math.pi**2 * (1 + 1e-6)

    def closed(x: jax.Array) -> jax.Array:
        half = 0.5 * jnp.sqrt(x)
        return (1.0 - half * jnp.cos(half) / jnp.sin(half)) / x

    return _switched("G", x, switch, closed)


def G_principal(x: jax.Array) -> jax.Array:
    """G on the principal range x ≤ π² only (the logs' case): the series alone, with
    no closed-form branch to evaluate and discard."""
    return _horner("G", x, math.pi**2 * (1 + 1e-6))


def atan2_over(n2: jax.Array, w: jax.Array) -> jax.Array:
    """atan2(n, w) / n with n = √n2 ≥ 0 and w ≥ 0: half the SO(3) log's scale factor.

    Below n²/w² = 1/4 it is summed as Σ (−1)ᵏ tᵏ / ((2k+1) w) with t = n²/w² (the
    Taylor series of atan(√t)/√t); above, the closed form, whose derivative no longer
    cancels. Accurate to the last bits at θ = π (w = 0), with no snapping."""
    small = n2 < 0.25 * w * w
    w_safe = jnp.where(small, w, 1.0)
    t = jnp.where(small, n2 / (w_safe * w_safe), 0.0)
    eps = float(jnp.finfo(jnp.result_type(n2, w)).eps)
    n_terms = next(k for k in range(1, 200) if 0.25**k / (2 * k + 1) < eps / 8)
    acc = jnp.full_like(t, (-1) ** (n_terms - 1) / (2 * n_terms - 1))
    for k in range(n_terms - 2, -1, -1):
        acc = acc * t + (-1) ** k / (2 * k + 1)
    series = acc / w_safe
    n_safe = jnp.sqrt(jnp.where(small, 1.0, n2))
    direct = jnp.arctan2(n_safe, w) / n_safe
    return jnp.where(small, series, direct)

