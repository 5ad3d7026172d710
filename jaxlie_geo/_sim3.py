"""Sim(3): similarity transforms x ↦ s R x + t, the group of monocular SLAM's scale drift.

The exponential's translation integrates exp(τ(ω̂ + σI)) over τ ∈ [0, 1]; its coefficients
are joint functions of the rotation angle θ and the log-scale σ, evaluated by
``_scalar_sim3.sim3_coefficients`` without the cancellation of the textbook closed forms as
θ and σ go to 0 together.
"""

from __future__ import annotations

from typing import Any, Optional, Tuple

import jax
import jax.numpy as jnp
from typing_extensions import override

from . import _scalar, _scalar_sim3, hints
from ._alignment import umeyama_parts
from ._base import MatrixLieGroup
from ._checks import as_float_array, check_batches, check_type, resolve_dtype
from ._jit import deprecated_alias
from ._pytree import pytree_dataclass
from ._scalar import components, dot, pow2_inverse, sq_norm
from ._so3 import (
    SO3,
    cross,
    exp_half_angle,
    exp_quaternion,
    jac_right_inv_so3,
    jac_right_so3,
    log_quaternion_parts,
    skew,
)
from ._xla import Schedule, aligned, block_matrix, materialize_columns, matmul


def _eye3(like: jax.Array) -> jax.Array:
    """The 3×3 identity with as many leading unit axes as ``like`` has batch axes."""
    return jnp.eye(3, dtype=like.dtype).reshape((1,) * (like.ndim - 1) + (3, 3))


def _w_apply(coeffs: Tuple[jax.Array, ...], w: jax.Array, v: jax.Array) -> jax.Array:
    """W v = D0 v + B ω × v + C (ω·v) ω for ``coeffs`` = (A, D0, B, C)."""
    _, d0, b, c = coeffs
    return d0[..., None] * v + b[..., None] * cross(w, v) + (c * dot(w, v))[..., None] * w


def _w_inverse_apply(
    coeffs: Tuple[jax.Array, ...], u: jax.Array, t: jax.Array, k: Optional[jax.Array] = None
) -> jax.Array:
    """W⁻¹ t for ω = k·u (k = 1 when omitted). On the plane across ω, W acts as the complex
    number φ(σ + iθ) = D0 + iθB and along ω as A, so

        W⁻¹ = (D0 I − B ω̂ + ((B² − C D0)/A) ωωᵀ) / |φ|²,   |φ|² = D0² + θ²B² > 0 (θ < 2π).

    (A, D0, B, C) are first scaled by the power of two nearest 1/A (``pow2_inverse``),
    exactly (W⁻¹ is homogeneous of degree −1 in them): |φ|² stays near 1 (≈ exp(2σ)/σ²
    otherwise, whose third negative power, in second derivatives, underflows float32 from
    σ ≈ 18). ω enters as
    k·u, the quaternion's vector part and the log's scale, without forming the rounded ω
    (as ``SE3.log``)."""
    a, d0, b, c = coeffs
    k = jnp.ones_like(a) if k is None else k
    scale = _scalar.pow2_inverse(jax.lax.stop_gradient(a))
    a, d0, b, c = (v * scale for v in (a, d0, b, c))
    kb = k * b
    inv = 1.0 / (d0 * d0 + sq_norm(u) * kb * kb)
    g = (b * b - c * d0) * k * k / a
    inv = inv * scale
    return inv[..., None] * (
        d0[..., None] * t - kb[..., None] * cross(u, t) + (g * dot(u, t))[..., None] * u
    )


def _w_matrix(coeffs: Tuple[jax.Array, ...], w: jax.Array) -> jax.Array:
    """W as a ``(*batch, 3, 3)`` matrix."""
    eye = jnp.eye(3, dtype=w.dtype)
    cols = [_w_apply(coeffs, w, jnp.broadcast_to(e, w.shape)) for e in eye]
    return jnp.stack(cols, axis=-1)


@pytree_dataclass
class Sim3(MatrixLieGroup):
    """Similarity transforms ``x ↦ s R x + t`` in 3D, s > 0.

    Parameters: ``wxyz_xyz_log_scale = (qw, qx, qy, qz, x, y, z, σ)``, shape ``(*batch, 8)``,
    with σ = log s. Storing the log-scale makes every parameter vector with a unit
    quaternion a valid element (an additive optimiser step cannot make s ≤ 0), keeps σ
    exact through exp, log, compose (σ₁ + σ₂) and inverse (−σ), and holds scales from
    e^-87 to e^88 in float32.
    Tangent: ``(v, ω, σ)``: translation part, rotation vector, log-scale; shape
    ``(*batch, 7)``, translation first as in ``SE3``.
    Matrix: ``[[s R, t], [0, 1]]``; hat(v, ω, σ) = ``[[ω̂ + σ I, v], [0, 0]]``.
    """

    wxyz_xyz_log_scale: jax.Array
    """``(qw, qx, qy, qz, x, y, z, log s)``, shape ``(*batch, 8)``."""

    matrix_dim = 4
    parameters_dim = 8
    tangent_dim = 7
    space_dim = 3
    _schedule = Schedule(reread=True, interpolate_in_memory=True)

    # -- construction and accessors -------------------------------------------------

    @classmethod
    def from_rotation_translation_and_scale(
        cls, rotation: SO3, translation: hints.Array, scale: hints.Array
    ) -> Sim3:
        """The similarity x ↦ s R x + t; batch axes of the three broadcast.

        Args:
            rotation: an ``SO3``.
            translation: ``(*batch, 3)``.
            scale: s, shape ``batch`` (a scalar for one element). Stored as log s: s ≤ 0
                gives a log-scale of NaN (s < 0) or −inf (s = 0), which ``is_valid`` reports.
        """
        where = "Sim3.from_rotation_translation_and_scale"
        check_type(where, "rotation", rotation, SO3)
        r = rotation.parameters()
        t = as_float_array(translation, "translation", (3,), where, like=r)
        s = as_float_array(scale, "scale", (), where, like=r)
        return cls._assemble(where, r, t, jnp.log(s))

    from_rotation_translation_scale = deprecated_alias(
        "from_rotation_translation_scale", "from_rotation_translation_and_scale", on_class=True
    )

    @classmethod
    def _assemble(cls, where: str, r: jax.Array, t: jax.Array, log_s: jax.Array) -> Sim3:
        batch = check_batches(
            where,
            "rotation, translation and scale batch axes",
            r.shape[:-1],
            t.shape[:-1],
            log_s.shape,
        )
        dtype = jnp.result_type(r, t, log_s)
        parts = [
            jnp.broadcast_to(r.astype(dtype), (*batch, 4)),
            jnp.broadcast_to(t.astype(dtype), (*batch, 3)),
            jnp.broadcast_to(log_s.astype(dtype), batch)[..., None],
        ]
        return Sim3(jnp.concatenate(parts, axis=-1))

    def rotation(self) -> SO3:
        """R, an ``SO3`` with the same batch axes."""
        return SO3(self.wxyz_xyz_log_scale[..., :4])

    def translation(self) -> jax.Array:
        """t, ``(*batch, 3)``."""
        return self.wxyz_xyz_log_scale[..., 4:7]

    def log_scale(self) -> jax.Array:
        """σ = log s, shape ``batch``."""
        return self.wxyz_xyz_log_scale[..., 7]

    def scale(self) -> jax.Array:
        """s = e^σ, shape ``batch``."""
        return jnp.exp(self.log_scale())

    def _unit_part(self) -> jax.Array:
        return self.wxyz_xyz_log_scale[..., :4]

    def _linear_part(self) -> jax.Array:
        return self.scale()[..., None, None] * self.rotation().as_matrix()

    @classmethod
    @override
    def identity(cls, batch_axes: Tuple[int, ...] = (), dtype: Any = None) -> Sim3:
        dtype = resolve_dtype(dtype)
        return Sim3(jnp.zeros((*batch_axes, 8), dtype).at[..., 0].set(1.0))

    @classmethod
    @override
    def sample_uniform(
        cls, key: jax.Array, batch_axes: Tuple[int, ...] = (), dtype: Any = None
    ) -> Sim3:
        """Haar-uniform rotation; translation uniform in [−1, 1]³; log-scale uniform in
        [−1, 1] (scales from 1/e to e)."""
        dtype = resolve_dtype(dtype)
        k0, k1 = jax.random.split(key)
        rot = SO3.sample_uniform(k0, batch_axes, dtype)
        u = jax.random.uniform(k1, (*batch_axes, 4), dtype=dtype, minval=-1.0, maxval=1.0)
        return cls._assemble("Sim3.sample_uniform", rot.wxyz, u[..., :3], u[..., 3])

    # -- exp, log and the algebra ---------------------------------------------------

    @classmethod
    @override
    def exp(cls, tangent: hints.Array) -> Sim3:
        """Exponential map of (v, ω, σ): q = exp_SO3(ω), log-scale σ (exactly), and
        t = W v with W = ∫₀¹ exp(τ(ω̂ + σI)) dτ = D0 I + B ω̂ + C ωωᵀ, the coefficients
        from ``_scalar_sim3.sim3_coefficients`` (accurate jointly in θ and σ).

        Args:
            tangent: ``(*batch, 7)``.

        Returns:
            Sim3 with batch axes ``batch``. e^σ overflows beyond σ ≈ 88 in float32 (709 in
            float64): t is then inf or NaN.
        """
        xi = cls._check_tangent(tangent)
        v, w, sigma = xi[..., :3], xi[..., 3:6], xi[..., 6]
        half = exp_half_angle(w)
        coeffs = _scalar_sim3.sim3_coefficients(sigma, sq_norm(w), half)
        t = _w_apply(coeffs, w, v)
        return Sim3(jnp.concatenate([exp_quaternion(w, half), t, sigma[..., None]], axis=-1))

    @override
    def log(self) -> jax.Array:
        """Principal logarithm (v, ω, σ), ``(*batch, 7)``, ‖ω‖ ∈ [0, π]: ω from the
        quaternion as in ``SO3.log``, σ as stored, v = W⁻¹ t (``_w_inverse_apply``)."""
        q = self.wxyz_xyz_log_scale[..., :4]
        u, s, _ = log_quaternion_parts(q)
        w = s[..., None] * u
        sigma = self.log_scale()
        # cos(θ/2) = |q_w|/‖q‖ and sin(θ/2)/(θ/2) = 2/(s‖q‖), read off the quaternion
        norm = jnp.sqrt(sq_norm(q))
        half = (jnp.abs(q[..., 0]) / norm, 2.0 / (s * norm))
        coeffs = _scalar_sim3.sim3_coefficients(sigma, sq_norm(w), half)
        v = _w_inverse_apply(coeffs, u, self.translation(), s)
        return jnp.concatenate([v, w, sigma[..., None]], axis=-1)

    @classmethod
    @override
    def hat(cls, tangent: hints.Array) -> jax.Array:
        xi = as_float_array(tangent, "tangent", (7,), "Sim3.hat")
        block = skew(xi[..., 3:6]) + xi[..., 6, None, None] * _eye3(xi)
        top = jnp.concatenate([block, xi[..., :3, None]], axis=-1)
        bottom = jnp.zeros((*xi.shape[:-1], 1, 4), xi.dtype)
        return jnp.concatenate([top, bottom], axis=-2)

    @classmethod
    @override
    def vee(cls, matrix: hints.Array) -> jax.Array:
        """(v, ω, σ) from ``[[ω̂ + σI, v], [·, ·]]``: the antisymmetric part of the 3×3 block
        gives ω, a third of its trace σ (the traceless symmetric part is ignored)."""
        m = as_float_array(matrix, "matrix", (4, 4), "Sim3.vee")
        block = m[..., :3, :3]
        d0, d1, d2 = block[..., 0, 0], block[..., 1, 1], block[..., 2, 2]
        sigma = d0 + ((d1 - d0) + (d2 - d0)) / 3.0  # the mean, exact for an equal diagonal
        return jnp.concatenate([m[..., :3, 3], SO3.vee(block), sigma[..., None]], axis=-1)

    @override
    def adjoint(self) -> jax.Array:
        """``(*batch, 7, 7)``: [[sR, t̂R, −t], [0, R, 0], [0, 0, 1]] for (v, ω, σ)."""
        R = self.rotation().as_matrix()
        t = self.translation()
        s = self.scale()[..., None, None]
        one = jnp.ones((*t.shape[:-1], 1, 1), t.dtype)
        return block_matrix(
            [[s * R, matmul(skew(t), R), -t[..., None]], [None, R, None], [None, None, one]]
        )

    @classmethod
    @override
    def ad(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 7, 7)``: [[ω̂ + σI, v̂, −v], [0, ω̂, 0], [0, 0, 0]]."""
        xi = cls._check_tangent(tangent, "ad")
        v, w, sigma = xi[..., :3], xi[..., 3:6], xi[..., 6]
        W = skew(w)
        Y = W + sigma[..., None, None] * _eye3(xi)
        zero = jnp.zeros((*xi.shape[:-1], 1, 1), xi.dtype)
        return block_matrix([[Y, skew(v), -v[..., None]], [None, W, None], [None, None, zero]])

    @classmethod
    def _jac_parts(cls, xi: jax.Array) -> Tuple[jax.Array, Tuple[jax.Array, ...], jax.Array]:
        """(R, (A, D0, B, C), [W | ∂t/∂ω | ∂t/∂σ]) at ξ = (v, ω, σ), the last ``(*batch, 3, 7)``.

        J_r = Σ (−ad ξ)ⁿ/(n+1)! is block triangular, [[W(−ξ), Q, c], [0, J_r(ω), 0],
        [0, 0, 1]]. Its translation row is exp(−Y) ∂(W v)/∂(v, ω, σ) for Y = ω̂ + σI (the
        first-order change of the translation of exp(ξ)⁻¹ exp(ξ + δ)), exp(−Y) = exp(−σ) Rᵀ.
        With x = θ², the derivatives of t = W v = D0 v + B ω×v + C (ω·v) ω are

            ∂t/∂σ = D0_σ v + B_σ ω×v + C_σ (ω·v) ω,
            ∂t/∂ω = 2 (D0_x v + B_x ω×v + C_x (ω·v) ω) ωᵀ − B v̂ + C (ω vᵀ + (ω·v) I),

        and every coefficient is a member of ``_scalar_sim3.sim3_family``, in closed form:
        (D0, B, C)_σ = T_{1,0}, T_{1,1}, T_{1,2}; 2 D0_x = −T_{1,1}, 2 B_x = T_{0,3} − T_{1,2},
        2 C_x = 2T_{0,4} − T_{1,3}."""
        v, w, sigma = xi[..., :3], xi[..., 3:6], xi[..., 6]
        x = sq_norm(w)
        q = exp_quaternion(w)
        # Computed once into one array: fused, each is recomputed per entry that reads it.
        a, d0, b, c, _, d1_0, d1_1, d1_2, d0_3, d1_3, d0_4, q0, q1, q2, q3 = materialize_columns(
            *_scalar_sim3.sim3_family(sigma, x, _scalar_sim3.COEFFICIENTS_AND_DERIVATIVES),
            *components(q),
        )
        coeffs = (a, d0, b, c)
        d1_0, d1_1, d1_2, d0_3, d1_3, d0_4 = (
            k[..., None] for k in (d1_0, d1_1, d1_2, d0_3, d1_3, d0_4)
        )
        wxv = cross(w, v)
        wv = dot(w, v)[..., None]
        dt_dsigma = d1_0 * v + d1_1 * wxv + (d1_2 * wv) * w
        radial = -d1_1 * v + (d0_3 - d1_2) * wxv + ((2.0 * d0_4 - d1_3) * wv) * w
        bm, cm = b[..., None, None], c[..., None, None]
        dt_dw = (
            radial[..., :, None] * w[..., None, :]
            - bm * skew(v)
            + cm * (w[..., :, None] * v[..., None, :] + wv[..., None] * _eye3(xi))
        )
        M = jnp.concatenate([_w_matrix(coeffs, w), dt_dw, dt_dsigma[..., None]], axis=-1)
        return SO3(jnp.stack([q0, q1, q2, q3], -1)).as_matrix(), coeffs, M

    @classmethod
    @override
    def jac_right(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 7) -> (*batch, 7, 7)``: [[W(−ξ), Q, c], [0, J_r(ω), 0], [0, 0, 1]] with
        [W(−ξ) | Q | c] = exp(−σ) Rᵀ [W | ∂t/∂ω | ∂t/∂σ] (``_jac_parts``), J_r(ω) in closed
        form."""
        xi = cls._check_tangent(tangent, "jac_right")
        R, _, M = cls._jac_parts(xi)
        top = jnp.exp(-xi[..., 6])[..., None, None] * matmul(jnp.swapaxes(R, -1, -2), M)
        one = jnp.ones((*xi.shape[:-1], 1, 1), xi.dtype)
        return block_matrix(
            [
                [top[..., :3], top[..., 3:6], top[..., 6:]],
                [None, jac_right_so3(xi[..., 3:6]), None],
                [None, None, one],
            ]
        )

    @classmethod
    @override
    def jac_right_inv(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 7) -> (*batch, 7, 7)``: the block inverse of ``jac_right``,
        [[W(−ξ)⁻¹, −W(−ξ)⁻¹ Q J⁻¹, −W(−ξ)⁻¹ c], [0, J⁻¹, 0], [0, 0, 1]]; with
        W(−ξ)⁻¹ = exp(σ) W⁻¹ R (W(−Y) = exp(−Y) W(Y)) its top row is
        [exp(σ) W⁻¹ R, −W⁻¹ (∂t/∂ω) J⁻¹, −W⁻¹ ∂t/∂σ], W⁻¹ and J_r(ω)⁻¹ in closed form
        (``_w_inverse_apply``; no matrix inverse)."""
        xi = cls._check_tangent(tangent, "jac_right_inv")
        w = xi[..., 3:6]
        R, coeffs, M = cls._jac_parts(xi)
        Ji = jac_right_inv_so3(w)
        X = jnp.concatenate(
            [jnp.exp(xi[..., 6])[..., None, None] * R, -matmul(M[..., 3:6], Ji), -M[..., 6:]],
            axis=-1,
        )
        # W⁻¹ applied to the seven columns at once (the columns as rows of Xᵀ)
        top = jnp.swapaxes(
            _w_inverse_apply(
                tuple(k[..., None] for k in coeffs), w[..., None, :], jnp.swapaxes(X, -1, -2)
            ),
            -1,
            -2,
        )
        one = jnp.ones((*xi.shape[:-1], 1, 1), xi.dtype)
        return block_matrix(
            [
                [top[..., :3], top[..., 3:6], top[..., 6:]],
                [None, Ji, None],
                [None, None, one],
            ]
        )

    # -- group operations -----------------------------------------------------------

    @override
    def as_matrix(self) -> jax.Array:
        t = self.translation()
        top = jnp.concatenate([self._linear_part(), t[..., None]], axis=-1)
        bottom = jnp.broadcast_to(jnp.eye(4, dtype=t.dtype)[3], (*t.shape[:-1], 1, 4))
        return jnp.concatenate([top, bottom], axis=-2)

    @classmethod
    @override
    def from_matrix(cls, matrix: hints.Array, project: bool = False) -> Sim3:
        """The similarity of a ``(*batch, 4, 4)`` matrix [[sR, t], [·, ·]], t the last
        column as it is (the bottom row is not read).

        ``project=False``: s = ‖M‖_F/√3 for the 3×3 block M and R = ``SO3.from_matrix``
        of M/s; for M = sR(I + E) both are the nearest similarity's to second order in E.
        ``project=True``: the similarity nearest to M in the Frobenius norm: min over
        s > 0 and R of ‖sR − M‖ takes R nearest to M (``SO3.from_matrix(M,
        project=True)``, whatever s) and s = tr(RᵀM)/3; where that is not positive (M far
        from any similarity) the log-scale is NaN or −inf, which ``is_valid`` reports. A
        zero block gives a log-scale of −inf with either setting."""
        m = cls._check_matrix(matrix, "from_matrix")
        M = m[..., :3, :3]
        if project:
            R = SO3.from_matrix(M, project=True)
            s = jnp.sum(R.as_matrix() * M, axis=(-2, -1)) / 3.0
        else:
            # ‖M‖_F/√3 of M scaled by a power of two (exact), so that the squares neither
            # overflow nor underflow over the whole range of the dtype.
            big = jax.lax.stop_gradient(jnp.max(jnp.abs(M), axis=(-2, -1)))
            c = pow2_inverse(big)[..., None, None]
            s = jnp.sqrt(jnp.sum((M * c) ** 2, axis=(-2, -1)) / 3.0) / c[..., 0, 0]
            ok = s > 0
            R = SO3.from_matrix(M / jnp.where(ok, s, 1.0)[..., None, None])
        return cls._assemble("Sim3.from_matrix", R.wxyz, m[..., :3, 3], jnp.log(s))

    @override
    def apply(self, target: hints.Array) -> jax.Array:
        """Points x ↦ s R x + t, ``(*batch, 3)``."""
        T, p = self._schedule.inputs(*aligned(self, self._check_points(target)))
        return T.scale()[..., None] * T.rotation()._apply_kernel(p) + T.translation()

    @override
    def multiply(self, other: Sim3) -> Sim3:
        """(R₁R₂, s₁R₁t₂ + t₁, σ₁ + σ₂)."""
        a, b = self._schedule.inputs(*aligned(self, other))
        R = a.rotation()
        t = a.scale()[..., None] * R._apply_kernel(b.translation()) + a.translation()
        return Sim3(
            jnp.concatenate(
                [
                    R._multiply_kernel(b.rotation()).wxyz,
                    t,
                    (a.log_scale() + b.log_scale())[..., None],
                ],
                axis=-1,
            )
        )

    def _between(self, other: Sim3) -> Sim3:
        """``self⁻¹ @ other`` = (R₁⁻¹R₂, s₁⁻¹R₁⁻¹(t₂ − t₁), σ₂ − σ₁)."""
        a, b = self._schedule.inputs(*aligned(self, other))
        R_inv = a.rotation().inverse()
        t = jnp.exp(-a.log_scale())[..., None] * R_inv._apply_kernel(
            b.translation() - a.translation()
        )
        return Sim3(
            jnp.concatenate(
                [
                    R_inv._multiply_kernel(b.rotation()).wxyz,
                    t,
                    (b.log_scale() - a.log_scale())[..., None],
                ],
                axis=-1,
            )
        )

    @override
    def inverse(self) -> Sim3:
        """(R⁻¹, −s⁻¹R⁻¹t, −σ)."""
        T = self._schedule.inputs(self)
        R_inv = T.rotation().inverse()
        t = -jnp.exp(-T.log_scale())[..., None] * R_inv._apply_kernel(T.translation())
        return Sim3(jnp.concatenate([R_inv.wxyz, t, -T.log_scale()[..., None]], axis=-1))

    @override
    def normalize(self) -> Sim3:
        return Sim3(
            jnp.concatenate(
                [self.rotation().normalize().wxyz, self.wxyz_xyz_log_scale[..., 4:]], axis=-1
            )
        )

    @override
    def _rplus_jacobian(self) -> jax.Array:
        # T @ exp(δ): q' = q ⊗ exp(δω), t' = t + sR δv, σ' = σ + δσ to first order.
        R = self.rotation()
        one = jnp.ones((*self.get_batch_axes(), 1, 1), self.wxyz_xyz_log_scale.dtype)
        return block_matrix(
            [
                [None, R._rplus_jacobian(), None],
                [self._linear_part(), None, None],
                [None, None, one],
            ]
        )

    # -- fitting --------------------------------------------------------------------

    @classmethod
    def align(
        cls,
        source: hints.Array,
        target: hints.Array,
        weights: Optional[hints.Array] = None,
    ) -> Sim3:
        """The element T minimising Σ w ‖target − T @ source‖², in closed form (Umeyama,
        IEEE TPAMI 13(4), 1991, eqs. 34–43; ``jaxlie_geo._alignment.umeyama`` states the
        formulas, the degenerate cases and the accuracy).

        The usual alignment of an estimated trajectory (monocular, scale-ambiguous) to its
        ground truth before the absolute trajectory error is measured: ``source`` the
        estimated positions, ``target`` the true ones, then ``T @ source`` the aligned
        estimate.

        Args:
            source: ``(*batch, N, 3)``, the points to be mapped.
            target: ``(*batch, N, 3)``, their counterparts.
            weights: ``(*batch, N)``, non-negative; None for uniform weights. A point of
                zero weight is ignored.

        Returns:
            Sim3 with batch axes ``batch`` (the broadcast batch axes of the arguments).
            Degenerate data give one of the minimisers: the identity rotation with scale 1
            for coincident source points, the identity for zero total weight; where
            ``target`` has no spread (or no correlation with ``source``) the least-squares
            scale is 0, stored as a log-scale of −inf (``is_valid`` reports it).

        Raises:
            ValueError: at trace time, naming the argument and the shapes, for inputs not
                of the shapes above.
        """
        r, t, s = umeyama_parts(source, target, weights, True, "Sim3.align")
        return cls.from_rotation_translation_and_scale(SO3.from_matrix(r), t, s)
