"""SE(3): rigid transforms, a unit quaternion and a translation, in closed-form vectors."""

from __future__ import annotations

from typing import Optional, Tuple

import jax
import jax.numpy as jnp
from typing_extensions import override

from . import _scalar, hints
from ._alignment import umeyama_parts
from ._base import SEBase
from ._checks import as_float_array
from ._pytree import pytree_dataclass
from ._scalar import components, dot, sq_norm
from ._so3 import (
    SO3,
    cross,
    exp_half_angle,
    exp_quaternion,
    log_quaternion_parts,
    rodrigues_entries,
    skew,
)
from ._xla import (
    Entries,
    Schedule,
    entries_product,
    from_block_entries,
    materialize_columns,
    matmul,
    matmul_unrolled,
)


def exp_translation(
    v: jax.Array, w: jax.Array, half: Optional[Tuple[jax.Array, jax.Array]] = None
) -> jax.Array:
    """Translation t = V(ω) v of ``SE3.exp((v, ω))``, θ = ‖ω‖, with v split along and
    across the rotation axis: t = F0 v + F1 (ω × v) + F2 (ω·v) ω.

    This is Zhang 2022, §8.4, t = θ⁻¹(R − I)(v × a) + (vᵀa) a for a *unit* axis a,
    rewritten for the tangent's ω = θa with ω × (v × ω) = θ² v⊥: no 0/0 is left, and
    nothing cancels at large angles (F0 = sin θ/θ is computed directly). The equal
    textbook form v + F1 (ω × v) + F2 ω × (ω × v) (Eberly 2024, eq. 36; Barfoot 2017,
    eq. 7.82) cancels v against θ²F2·v beyond π (docs/design/se3-kernel-forms.md).

    Args:
        v: ``(*batch, 3)``, the tangent's translation part.
        w: ``(*batch, 3)``, the tangent's rotation vector ω.
        half: ``(cos(θ/2), sin(θ/2)/(θ/2))``, each of shape ``batch``, from
            ``exp_half_angle``; passing it shares one sincos with the rotation.

    Returns:
        ``(*batch, 3)``: t, with F0 = c·k, F1 = k²/2 and F2 all read from ``half``.
    """
    c, k = exp_half_angle(w) if half is None else half
    x = sq_norm(w)
    f0 = c * k
    f1, f2 = (0.5 * k * k)[..., None], _scalar.F2(x, f0)[..., None]
    return f0[..., None] * v + f1 * cross(w, v) + f2 * dot(w, v)[..., None] * w


def log_translation(t: jax.Array, u: jax.Array, s: jax.Array, h: jax.Array) -> jax.Array:
    """Translation part v = V(ω)⁻¹ t of the principal ``SE3.log`` (θ ≤ π), with t split
    along and across the axis: (θ/2)cot(θ/2) t⊥ + ½ t × ω + (tᵀω)ω/θ² (Zhang 2022, §9,
    rewritten for ω = θ·axis).

    It is evaluated as h t − ½ s (u × t) + G s² (u·t) u (= h t⊥ + t∥ − ½ ω × t): two
    non-negative multiples of t∥, no cancellation; u is stored, so ω's rounding is not
    multiplied by |t|. The equal textbook form t − ½ ω × t + G ω × (ω × t) (Barfoot 2017,
    eq. 7.85) cancels t⊥ in its last term near π, where h → 0
    (docs/design/se3-kernel-forms.md).

    Args:
        t: ``(*batch, 3)``, the translation.
        u: ``(*batch, 3)``, the quaternion's vector part, sign chosen so that w ≥ 0
            (from ``log_quaternion_parts``).
        s: shape ``batch``, θ/‖u‖, so that ω = s·u.
        h: shape ``batch``, (θ/2)cot(θ/2).

    Returns:
        ``(*batch, 3)``: v.
    """
    g = _scalar.G_principal(sq_norm(s[..., None] * u))
    # G s² = (1 − h)/‖u‖² exactly; where h < ½ (θ > 2.3) that form has no cancellation
    # and does not carry s's rounding twice.
    far = h < 0.5
    n2 = jnp.where(far, sq_norm(u), 1.0)
    coef = jnp.where(far, (1.0 - h) / n2, g * s * s)
    return h[..., None] * t - (0.5 * s)[..., None] * cross(u, t) + (coef * dot(u, t))[..., None] * u


def coupling_entries(
    rho: jax.Array,
    phi: jax.Array,
    x: jax.Array,
    f2: jax.Array,
    c2: jax.Array,
    d: jax.Array,
    delta: jax.Array,
) -> Entries:
    """Q(−ρ, −φ), the coupling block of SE(3)'s J_r (Barfoot and Furgale 2014, eq. 102, at
    −ξ), entry by entry, from x = θ² = ‖φ‖², F2, C2 and D at x (``_scalar``) and δ = φ·ρ.

    Eq. 102 reads −½ρ̂ + F2 (φ̂ρ̂ + ρ̂φ̂ − φ̂ρ̂φ̂) − C2 (φ̂²ρ̂ + ρ̂φ̂² − 3φ̂ρ̂φ̂) + D (φ̂ρ̂φ̂² + φ̂²ρ̂φ̂).
    With â b̂ = b aᵀ − (a·b) I and φᵀφ̂ = 0 its products reduce to φ̂ρ̂φ̂ = −δ φ̂,
    φ̂²ρ̂ + ρ̂φ̂² − 3φ̂ρ̂φ̂ = 2δ φ̂ − θ² ρ̂ and φ̂ρ̂φ̂² + φ̂²ρ̂φ̂ = −2δ φ̂², so that

        Q = (C2 θ² − ½) ρ̂ + (F2 − 2 C2) δ φ̂ + F2 (ρφᵀ + φρᵀ) − 2 D δ φφᵀ + 2 δ (D θ² − F2) I,

    with no matrix product (each coefficient is bounded, so nothing cancels)."""
    k_rho = c2 * x - 0.5
    k_phi = (f2 - 2.0 * c2) * delta
    k_eye = 2.0 * delta * (d * x - f2)
    k_pp = -2.0 * d * delta
    r, p = components(rho), components(phi)
    s = [k_rho * r[i] + k_phi * p[i] for i in range(3)]  # Q's skew part is ŝ

    def sym(i: int, j: int) -> jax.Array:
        return f2 * (r[i] * p[j] + p[i] * r[j]) + k_pp * p[i] * p[j]

    return [
        [sym(0, 0) + k_eye, sym(0, 1) - s[2], sym(0, 2) + s[1]],
        [sym(1, 0) + s[2], sym(1, 1) + k_eye, sym(1, 2) - s[0]],
        [sym(2, 0) - s[1], sym(2, 1) + s[0], sym(2, 2) + k_eye],
    ]


def coupled_inverse(j_inv: Entries, q: Entries) -> Entries:
    """−J⁻¹ Q J⁻¹, the coupling block of an inverse Jacobian [[J, Q], [0, J]]⁻¹."""
    t = entries_product(entries_product(j_inv, q), j_inv)
    return [[-e for e in row] for row in t]


@pytree_dataclass
class SE3(SEBase[SO3]):
    """Special Euclidean group of 3D rigid transforms ``x ↦ R x + t``.

    Parameters: ``wxyz_xyz = (qw, qx, qy, qz, x, y, z)``, shape ``(*batch, 7)``.
    Tangent: ``(vx, vy, vz, ωx, ωy, ωz)``, translation first (jaxlie's order; Eberly 2024,
    §10, and GTSAM put the rotation first), shape ``(*batch, 6)``. Matrix:
    ``[[R, t], [0, 1]]``, acting on homogeneous points ``(x, y, z, 1)``.
    """

    wxyz_xyz: jax.Array
    """``(qw, qx, qy, qz, x, y, z)``, shape ``(*batch, 7)``."""

    matrix_dim = 4
    parameters_dim = 7
    tangent_dim = 6
    space_dim = 3
    _rotation_type = SO3
    _schedule = Schedule(reread=True, interpolate_in_memory=True, interpolate_in_chunks=True)

    @classmethod
    @override
    def exp(cls, tangent: hints.Array) -> SE3:
        """Exponential map of the tangent (v, ω).

        q = exp_SO3(ω) as in ``SO3.exp``; t = V(ω) v, θ = ‖ω‖, evaluated as
        F0 v + F1 (ω × v) + F2 (ω·v) ω (Zhang 2022, §8.4, adapted to ω = θ·axis; equal to
        Eberly 2024, eq. 36, v + F1 ω × v + F2 ω × (ω × v), which cancels beyond π; see
        ``exp_translation``), with cross products and no 3×3 matrices.

        Args:
            tangent: ``(*batch, 6)``, ``(vx, vy, vz, ωx, ωy, ωz)``.

        Returns:
            SE3 with batch axes ``batch``. Any rotation angle whose square is finite is
            accepted (float32 θ < 1.8e19, float64 θ < 1.3e154); beyond, the result is NaN.
        """
        xi = cls._check_tangent(tangent)
        v, w = xi[..., :3], xi[..., 3:]
        half = exp_half_angle(w)
        t = exp_translation(v, w, half)
        return SE3(jnp.concatenate([exp_quaternion(w, half), t], axis=-1))

    @override
    def log(self) -> jax.Array:
        """Principal logarithm: the tangent (v, ω), ``(*batch, 6)``, with ‖ω‖ in [0, π].

        ω = log_SO3(q) as in ``SO3.log``; v = V(ω)⁻¹ t (= t − ½ ω × t + G ω × (ω × t),
        Barfoot 2017, eq. 7.85), evaluated as h t − ½ ω × t + G (ω·t) ω with
        h = (θ/2)cot(θ/2) and G = (1 − h)/θ² (Zhang 2022, §9, adapted to ω = θ·axis: no
        cancellation near π; see ``log_translation``)."""
        p = self.wxyz_xyz
        u, s, h = log_quaternion_parts(p[..., :4])
        v = log_translation(p[..., 4:], u, s, h)
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
        """Adjoint ``Ad(T)``, ``(*batch, 6, 6)``: [[R, t̂ R], [0, R]] for the (v, ω) ordering
        (Eberly 2024, eq. 41, with the blocks permuted to translation first)."""
        R = self.rotation().as_matrix()
        tR = matmul(skew(self.translation()), R)
        zero = jnp.zeros_like(R)
        return jnp.concatenate(
            [jnp.concatenate([R, tR], -1), jnp.concatenate([zero, R], -1)], axis=-2
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
        [0, J_r(φ)]] for ξ = (ρ, φ), J_r(φ) = (1 − F2 θ²) I − F1 φ̂ + F2 φφᵀ
        (``coupling_entries`` for Q)."""
        xi = cls._check_tangent(tangent, "jac_right")
        rho, phi = xi[..., :3], xi[..., 3:]
        x = sq_norm(phi)
        x, f1, f2, c2, d, delta = materialize_columns(
            x, _scalar.F1(x), _scalar.F2(x), _scalar.C2(x), _scalar.D(x), dot(phi, rho)
        )
        J = rodrigues_entries(phi, 1.0 - f2 * x, -f1, f2)
        return from_block_entries([[J, coupling_entries(rho, phi, x, f2, c2, d, delta)], [None, J]])

    @classmethod
    @override
    def jac_right_inv(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 6) -> (*batch, 6, 6)``: J_r⁻¹(ξ) = [[J⁻¹, −J⁻¹ Q J⁻¹], [0, J⁻¹]],
        J⁻¹ = J_r⁻¹(φ) = (1 − G θ²) I + ½ φ̂ + G φφᵀ of SO(3), Q = Q(−ρ, −φ) (the block
        inverse of ``jac_right``, in closed form)."""
        xi = cls._check_tangent(tangent, "jac_right_inv")
        rho, phi = xi[..., :3], xi[..., 3:]
        x = sq_norm(phi)
        x, f2, c2, d, g, delta = materialize_columns(
            x, _scalar.F2(x), _scalar.C2(x), _scalar.D(x), _scalar.G(x), dot(phi, rho)
        )
        Ji = rodrigues_entries(phi, 1.0 - x * g, 0.5, g)
        return from_block_entries(
            [[Ji, coupled_inverse(Ji, coupling_entries(rho, phi, x, f2, c2, d, delta))], [None, Ji]]
        )

    @classmethod
    @override
    def ad(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 6) -> (*batch, 6, 6)``: [[φ̂, ρ̂], [0, φ̂]] for ξ = (ρ, φ) (translation
        first)."""
        xi = cls._check_tangent(tangent, "ad")
        return cls._blocks(skew(xi[..., 3:]), skew(xi[..., :3]))

    @override
    def _adjoint_apply(self, tangent: jax.Array) -> jax.Array:
        """Ad(T)(v, ω) = (R v + t × R ω, R ω), without the 6×6 matrix."""
        R = self.rotation().as_matrix()
        Rv = matmul_unrolled(R, tangent[..., :3, None])[..., 0]
        Rw = matmul_unrolled(R, tangent[..., 3:, None])[..., 0]
        return jnp.concatenate([Rv + cross(self.translation(), Rw), Rw], -1)

    @classmethod
    @override
    def _bracket(cls, a: jax.Array, b: jax.Array) -> jax.Array:
        """[(ρ₁, φ₁), (ρ₂, φ₂)] = (φ₁ × ρ₂ + ρ₁ × φ₂, φ₁ × φ₂)."""
        rho1, phi1, rho2, phi2 = a[..., :3], a[..., 3:], b[..., :3], b[..., 3:]
        return jnp.concatenate([cross(phi1, rho2) + cross(rho1, phi2), cross(phi1, phi2)], -1)

    # -- fitting --------------------------------------------------------------------

    @classmethod
    def align(
        cls,
        source: hints.Array,
        target: hints.Array,
        weights: Optional[hints.Array] = None,
    ) -> SE3:
        """The element T minimising Σ w ‖target − T @ source‖², in closed form (Umeyama,
        IEEE TPAMI 13(4), 1991, eqs. 34–43 with the scale fixed to 1, the Kabsch
        solution; ``jaxlie_geo._alignment.umeyama`` states the formulas, the degenerate
        cases and the accuracy).

        Args:
            source: ``(*batch, N, 3)``, the points to be mapped.
            target: ``(*batch, N, 3)``, their counterparts.
            weights: ``(*batch, N)``, non-negative; None for uniform weights. A point of
                zero weight is ignored.

        Returns:
            SE3 with batch axes ``batch`` (the broadcast batch axes of the arguments).
            Degenerate data give one of the minimisers: for collinear points a rotation
            about the line chosen by the projection onto the rotations, the identity
            rotation where the covariance vanishes (coincident source or target points),
            the identity for zero total weight.

        Raises:
            ValueError: at trace time, naming the argument and the shapes, for inputs not
                of the shapes above.
        """
        r, t, _ = umeyama_parts(source, target, weights, False, "SE3.align")
        return cls.from_rotation_and_translation(SO3.from_matrix(r), t)
