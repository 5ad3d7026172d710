"""SE(3): rigid transforms, a unit quaternion and a translation, in closed-form vectors."""

from __future__ import annotations

from typing import Optional, Tuple

import jax
import jax.numpy as jnp
from typing_extensions import override

from . import _scalar, hints
from ._base import SEBase, as_float_array, materialize, matmul, pytree_dataclass
from ._batch import in_chunks
from ._so3 import (
    SO3,
    cross,
    by_angle,
    dot,
    exp_half_angle,
    exp_quaternion,
    jac_right_inv_so3,
    jac_right_so3,
    log_quaternion_parts,
    skew,
    skew_sq,
    sq_norm,
)


def _dot(a: jax.Array, b: jax.Array) -> jax.Array:
    return dot(a, b)[..., None]


def exp_translation(
    v: jax.Array,
    w: jax.Array,
    form: str = "seed000",
    half: Optional[Tuple[jax.Array, jax.Array]] = None,
    compensated: bool = True,
) -> jax.Array:
    """t = V(ω) v, θ = ‖ω‖, in one of two algebraically equal forms:

    * ``"textbook"``: v + F1 (ω × v) + F2 ω × (ω × v) (seed 001 eq. 36, Barfoot eq. 7.82);
      beyond π, v and θ²F2·v ≈ v cancel to the much shorter t (14 ulp at θ ≈ 29);
    * ``"seed000"``: (R − I)(v × ω)/θ² + (vᵀω)ω/θ² (seed 000 §8.4 with ω = θ·axis), which
      with ω × (v × ω) = θ² v⊥ reduces to F0 v + F1 (ω × v) + F2 (ω·v) ω — no 0/0 left and
      no cancellation at large angles (F0 = sin θ/θ is computed directly).

    F0 = c k, F1 = k²/2 and F2 come from ``half`` = (cos(θ/2), sin(θ/2)/(θ/2))
    (``exp_half_angle``), so exp costs one sincos in all. ``compensated``: the seed000
    form's ω·v as an error-free dot, needed only near θ = 2πk (see ``by_angle``).
    """
    c, k = exp_half_angle(w) if half is None else half
    x = sq_norm(w)
    f0 = c * k
    wxv = cross(w, v)
    f1, f2 = (0.5 * k * k)[..., None], _scalar.F2(x, f0)[..., None]
    if form == "seed000":
        # cancels for v ⟂ ω near θ = 2πk, where F0 → 0; see the kernel
        wv = (materialize(_scalar.dot_compensated(w, v)) if compensated else dot(w, v))[..., None]
        return f0[..., None] * v + f1 * wxv + f2 * wv * w
    return v + f1 * wxv + f2 * cross(w, wxv)


def log_translation(
    t: jax.Array, u: jax.Array, s: jax.Array, h: jax.Array, form: str = "seed000"
) -> jax.Array:
    """v = V(ω)⁻¹ t for the principal log (θ ≤ π), with ω = s·u and h = (θ/2)cot(θ/2) from
    ``log_quaternion_parts``, in two algebraically equal forms:

    * ``"textbook"``: t − ½ ω × t + G ω × (ω × t) (Barfoot eq. 7.85, G from _scalar); the
      last term cancels t⊥ near π, where h → 0 (5 ulp measured at π − 1e-3, |t| = 1e3);
    * ``"seed000"``: (θ/2)cot(θ/2) t⊥ + ½ t × ω + (tᵀω)ω/θ² (seed 000 §9), evaluated as
      h t − ½ s (u × t) + G s² (u·t) u (= h t⊥ + t∥ − ½ ω × t: two non-negative multiples of
      t∥, no cancellation; u is stored, so ω's rounding is not multiplied by |t|).
    """
    w = s[..., None] * u
    x = sq_norm(w)
    g = _scalar.G_principal(x)
    if form == "seed000":
        # G s² = (1 − h)/‖u‖² exactly; where h < ½ (θ > 2.3) that form has no cancellation
        # and does not carry s's rounding twice (5 → 3 ulp in v near π, |t| = 1e3).
        far = h < 0.5
        n2 = jnp.where(far, sq_norm(u), 1.0)
        coef = jnp.where(far, (1.0 - h) / n2, g * s * s)
        return h[..., None] * t - (0.5 * s)[..., None] * cross(u, t) + (coef * dot(u, t))[..., None] * u
    wxt = cross(w, t)
    return t - 0.5 * wxt + g[..., None] * cross(w, wxt)


_KERNEL_FORM = "seed000"  # more accurate (see the docstrings); speed in benchmarks/RESULTS.md


@pytree_dataclass
class SE3(SEBase[SO3]):
    """Special Euclidean group of 3D rigid transforms ``x ↦ R x + t``.

    Parameters: ``wxyz_xyz = (qw, qx, qy, qz, x, y, z)``, shape ``(*batch, 7)``.
    Tangent: ``(vx, vy, vz, ωx, ωy, ωz)``, translation first (jaxlie's order; Eberly's
    seed 001 §10 and GTSAM put the rotation first), shape ``(*batch, 6)``.
    """

    wxyz_xyz: jax.Array
    """``(qw, qx, qy, qz, x, y, z)``, shape ``(*batch, 7)``."""

    matrix_dim = 4
    parameters_dim = 7
    tangent_dim = 6
    space_dim = 3
    _rotation_type = SO3

    @classmethod
    @override
    def exp(cls, tangent: hints.Array) -> SE3:
        """``(*batch, 6)`` tangent (v, ω) -> SE3 of batch ``batch``.

        q = exp_SO3(ω); t = V v, θ = ‖ω‖, evaluated as F0 v + F1 (ω × v) + F2 (ω·v) ω
        (seed 000 §8.4; equal to seed 001 eq. 36's v + F1 ω × v + F2 ω × (ω × v), which
        cancels beyond π: ``exp_translation``), as cross products: no 3×3 matrices. On CPU a
        batch of at least 2^19 runs in 2^16-element chunks (``_batch.in_chunks``: 10^6
        elements, float32, 39 → 29 ns/element). Rotation angles as in ``SO3.exp``: any θ
        whose square is finite (float32 θ < 1.8e19), NaN beyond."""
        xi = materialize(cls._check_tangent(tangent))

        def kernel(compensated: bool, w: jax.Array, v: jax.Array) -> jax.Array:
            half = exp_half_angle(w, compensated)
            if compensated:
                # With jax 0.12 XLA:CPU recomputed the error-free sums per consumer inside
                # the chunk loop: 10^6 N(0, 1) tangents took 102-109 ns/element, 25-30 with
                # this barrier and the one on the compensated dot (jax 0.10.2: 22-28 either way).
                half = materialize(half)
            t = exp_translation(v, w, _KERNEL_FORM, half, compensated)
            return jnp.concatenate([exp_quaternion(w, half), t], axis=-1)

        def whole(xi: jax.Array) -> jax.Array:
            return by_angle(kernel, xi[..., 3:], xi[..., :3])

        return SE3(in_chunks(whole, xi.shape[:-1], xi))

    @override
    def log(self) -> jax.Array:
        """Tangent (v, ω), ``(*batch, 6)``, with ‖ω‖ in [0, π].

        ω = log_SO3(q); v = V⁻¹ t (= t − ½ ω × t + G ω × (ω × t), Barfoot eq. 7.85),
        evaluated as h t − ½ ω × t + G (ω·t) ω with h = (θ/2)cot(θ/2) and
        G = (1 − h)/θ² (seed 000 §9: no cancellation near π; ``log_translation``)."""
        p = materialize(self.wxyz_xyz)
        u, s, h = log_quaternion_parts(p[..., :4])
        v = log_translation(p[..., 4:], u, s, h, _KERNEL_FORM)
        return jnp.concatenate([v, s[..., None] * u], axis=-1)

    @classmethod
    @override
    def hat(cls, tangent: hints.Array) -> jax.Array:
        xi = as_float_array(tangent, "tangent", (6,), "SE3.hat")
        top = jnp.concatenate([skew(xi[..., 3:]), xi[..., :3, None]], axis=-1)
        bottom = jnp.zeros((*xi.shape[:-1], 1, 4), xi.dtype)
        return jnp.concatenate([top, bottom], axis=-2)

    @classmethod
    @override
    def vee(cls, matrix: hints.Array) -> jax.Array:
        m = as_float_array(matrix, "matrix", (4, 4), "SE3.vee")
        return jnp.concatenate([m[..., :3, 3], SO3.vee(m[..., :3, :3])], axis=-1)

    @override
    def adjoint(self) -> jax.Array:
        """``(*batch, 6, 6)``: [[R, t̂ R], [0, R]] for the (v, ω) ordering (seed 001 eq. 41,
        permuted)."""
        R = self.rotation().as_matrix()
        tR = matmul(skew(self.translation()), R)
        zero = jnp.zeros_like(R)
        return jnp.concatenate(
            [jnp.concatenate([R, tR], -1), jnp.concatenate([zero, R], -1)], axis=-2
        )

    @staticmethod
    def _q_block(xi: jax.Array) -> jax.Array:
        """Q(−ρ, −φ), the coupling block of J_r (Barfoot & Furgale 2014, eq. 102, at −ξ):
        −½ρ̂ + F2 (φ̂ρ̂ + ρ̂φ̂ − φ̂ρ̂φ̂) − C2 (φ̂²ρ̂ + ρ̂φ̂² − 3φ̂ρ̂φ̂) + D (φ̂ρ̂φ̂² + φ̂²ρ̂φ̂)."""
        rho, phi = xi[..., :3], xi[..., 3:]
        x = sq_norm(phi)
        P, Rh = skew(phi), skew(rho)
        PR, RP = matmul(P, Rh), matmul(Rh, P)
        PRP = matmul(PR, P)
        PP = skew_sq(phi)
        a = _scalar.F2(x)[..., None, None]
        b = _scalar.C2(x)[..., None, None]
        c = _scalar.D(x)[..., None, None]
        return (
            -0.5 * Rh
            + a * (PR + RP - PRP)
            - b * (matmul(PP, Rh) + matmul(Rh, PP) - 3.0 * PRP)
            + c * (matmul(PRP, P) + matmul(P, PRP))
        )

    @staticmethod
    def _blocks(top_left: jax.Array, top_right: jax.Array) -> jax.Array:
        zero = jnp.zeros_like(top_left)
        return jnp.concatenate(
            [
                jnp.concatenate([top_left, top_right], -1),
                jnp.concatenate([zero, top_left], -1),
            ],
            axis=-2,
        )

    @classmethod
    @override
    def jac_right(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 6) -> (*batch, 6, 6)``: J_r(ξ) = J_l(−ξ) = [[J_r(φ), Q(−ρ, −φ)],
        [0, J_r(φ)]] for ξ = (ρ, φ)."""
        xi = cls._check_tangent(tangent, "jac_right")
        return cls._blocks(jac_right_so3(xi[..., 3:]), cls._q_block(xi))

    @classmethod
    @override
    def jac_right_inv(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 6) -> (*batch, 6, 6)``: J_r⁻¹(ξ) = [[J⁻¹, −J⁻¹ Q J⁻¹], [0, J⁻¹]],
        J⁻¹ = J_r⁻¹(φ) of SO(3), Q = Q(−ρ, −φ) (block inverse of ``jac_right``, in closed
        form)."""
        xi = cls._check_tangent(tangent, "jac_right_inv")
        # In memory before the products, which read every entry three times over.
        Jinv, Q = materialize(jac_right_inv_so3(xi[..., 3:]), cls._q_block(xi))
        return cls._blocks(Jinv, -matmul(matmul(Jinv, Q), Jinv))

    @classmethod
    @override
    def ad(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 6) -> (*batch, 6, 6)``: [[φ̂, ρ̂], [0, φ̂]] for ξ = (ρ, φ) (translation
        first)."""
        xi = cls._check_tangent(tangent, "ad")
        return cls._blocks(skew(xi[..., 3:]), skew(xi[..., :3]))
