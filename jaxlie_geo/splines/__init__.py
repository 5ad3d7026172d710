"""Uniform cumulative B-splines on every group, with exact time derivatives and Jacobians
with respect to the control points.

A spline of degree ``k − 1`` (order ``k``, 2 ≤ k ≤ 6) with control points T₀ … Tₙ₋₁ and
knot spacing Δt is, on segment ``s`` (time ``t = t0 + (s + u)·Δt``, ``u ∈ [0, 1]``),

    T(t) = T_s · A₁ · … · Aₖ₋₁,    A_j = exp(λ_j(u) d_j),    d_j = log(Tₛ₊ⱼ₋₁⁻¹ Tₛ₊ⱼ),

the cumulative form of Kim, Kim and Shin, "A General Construction Scheme for Unit
Quaternion Curves with Simple High Order Derivatives" (SIGGRAPH 1995), written for any Lie
group. λ(u) = M̃ (1, u, …, uᵏ⁻¹)ᵀ with M̃ the cumulative blending matrix of the uniform
B-spline (Qin, "General matrix representations for B-splines", The Visual Computer 2000,
eq. 5; ``cumulative_basis``). Segment ``s`` depends on the ``k`` control points
``T_s … Tₛ₊ₖ₋₁`` only. The valid times are ``[t0, t0 + (n − k + 1)·Δt]``.

Derivatives are the recursions of Sommer, Usenko, Schubert, Demmel, Cremers, "Efficient
Derivative Computation for Cumulative B-Splines on Lie Groups" (CVPR 2020), not autodiff:
with ω⁽⁰⁾ = 0 and Ad_j = Ad(A_j⁻¹),

    ω⁽ʲ⁾ = Ad_j ω⁽ʲ⁻¹⁾ + λ̇_j d_j
    ω̇⁽ʲ⁾ = Ad_j ω̇⁽ʲ⁻¹⁾ + λ̇_j [ω⁽ʲ⁾, d_j] + λ̈_j d_j
    ω̈⁽ʲ⁾ = Ad_j ω̈⁽ʲ⁻¹⁾ + 2 λ̇_j [ω̇⁽ʲ⁾, d_j] + λ̈_j [ω⁽ʲ⁾, d_j] − λ̇_j² [[ω⁽ʲ⁾, d_j], d_j] + λ⃛_j d_j,

derivatives in u (dots), divided by Δt, Δt², Δt³ for time. The third line is this module's
derivation, by differentiating the second once more. [a, b] = vee(â b̂ − b̂ â) = ``ad(a) b``.
ω = ω⁽ᵏ⁻¹⁾/Δt is the body velocity: T⁻¹ Ṫ = hat(ω).

Control-point Jacobians come from the same products, as one forward recursion (derived
here). A right perturbation T_m → T_m exp(δ_m) moves d_j by
Δd_j = J_r⁻¹(d_j)(δₛ₊ⱼ − Ad(exp(−d_j)) δₛ₊ⱼ₋₁) and A_j to A_j exp(η_j), with
η_j = λ_j J_r(λ_j d_j) Δd_j; the value moves to T exp(P δ), with P⁽⁰⁾ = [I, 0, …] and
P⁽ʲ⁾ = Ad_j P⁽ʲ⁻¹⁾ + η_j; the velocity and acceleration follow by perturbing their
recursions, with Ad(exp(−η)) w ≈ w + ad(w) η.
"""

from ._curve import MAX_DEGREE as MAX_DEGREE
from ._curve import ControlPointJacobians as ControlPointJacobians
from ._curve import Spline as Spline
from ._curve import SplineEvaluation as SplineEvaluation
from ._curve import SplineTime as SplineTime
from ._curve import cumulative_basis as cumulative_basis
from ._fit import SplineFit as SplineFit
from ._fit import fit as fit

__all__ = [
    "MAX_DEGREE",
    "Spline",
    "SplineTime",
    "SplineEvaluation",
    "ControlPointJacobians",
    "cumulative_basis",
    "fit",
    "SplineFit",
]
