"""SE(2): planar rigid transforms, a unit complex number and a translation."""

from __future__ import annotations

from typing import Callable, Optional

import jax
import jax.numpy as jnp
import numpy as onp
from typing_extensions import override

from . import _scalar, hints
from ._base import SEBase
from ._checks import as_float_array, check_batches
from ._pytree import pytree_dataclass
from ._scalar import components
from ._so2 import SO2
from ._xla import Schedule, constant

_I2, _ROT90, _E02, _E12, _E22 = (
    onp.array(m, dtype=onp.float64).reshape(3, 3)
    for m in (
        [1, 0, 0, 0, 1, 0, 0, 0, 0],
        [0, -1, 0, 1, 0, 0, 0, 0, 0],
        [0, 0, 1, 0, 0, 0, 0, 0, 0],
        [0, 0, 0, 0, 0, 1, 0, 0, 0],
        [0, 0, 0, 0, 0, 0, 0, 0, 1],
    )
)


@pytree_dataclass
class SE2(SEBase[SO2]):
    """Special Euclidean group of planar rigid transforms ``x ↦ R x + t``.

    Parameters: ``unit_complex_xy = (cos θ, sin θ, x, y)``, shape ``(*batch, 4)``.
    Tangent: ``(vx, vy, θ)``, translation first (jaxlie's order; Eberly 2024, §8, puts the
    angle first), shape ``(*batch, 3)``. Matrix: ``[[R, t], [0, 1]]``, acting on
    homogeneous points ``(x, y, 1)``.
    """

    unit_complex_xy: jax.Array
    """``(cos θ, sin θ, x, y)``, shape ``(*batch, 4)``."""

    matrix_dim = 3
    parameters_dim = 4
    tangent_dim = 3
    space_dim = 2
    _rotation_type = SO2
    _schedule = Schedule(reread=True)

    @staticmethod
    def from_xy_theta(x: hints.Scalar, y: hints.Scalar, theta: hints.Scalar) -> SE2:
        """Transform with translation ``(x, y)`` and rotation by ``theta`` radians.

        Args:
            x: translation along x.
            y: translation along y.
            theta: rotation angle, radians. The three are scalars or arrays that broadcast
                to a common batch shape.

        Returns:
            SE2 with that batch shape.

        Raises:
            ValueError: the shapes do not broadcast.
        """
        x = as_float_array(x, "x", (), "SE2.from_xy_theta")
        y = as_float_array(y, "y", (), "SE2.from_xy_theta")
        theta = as_float_array(theta, "theta", (), "SE2.from_xy_theta")
        batch = check_batches(
            "SE2.from_xy_theta", "shapes of x, y, theta", x.shape, y.shape, theta.shape
        )
        x, y, theta = (jnp.broadcast_to(a, batch) for a in (x, y, theta))
        return SE2.from_rotation_and_translation(
            SO2.from_radians(theta), jnp.stack([x, y], axis=-1)
        )

    @classmethod
    @override
    def exp(cls, tangent: hints.Array) -> SE2:
        """Exponential map of the tangent (vx, vy, θ).

        R = R(θ), t = V v with V = [[A, −B], [B, A]], A = sin θ/θ = F0,
        B = (1 − cos θ)/θ = θ F1 (Eberly 2024, §8.1, eq. 21; Zhang 2022, §5.1–5.2, derives
        the same arc). All come from one half-angle sincos: with c = cos(θ/2),
        k = sinc(θ/2) and s = θk/2 = sin(θ/2), A = c k, B = s k, sin θ = 2 c s and
        cos θ = (c − s)(c + s) (absolute error ~eps at every angle).

        Args:
            tangent: ``(*batch, 3)``, ``(vx, vy, θ)``.

        Returns:
            SE2 with batch axes ``batch``.
        """
        xi = cls._check_tangent(tangent)
        vx, vy, theta = components(xi)
        c, k = _scalar.half_angle_of(theta)
        s = 0.5 * theta * k
        A, B = c * k, s * k
        return SE2(
            jnp.stack([(c - s) * (c + s), 2.0 * s * c, A * vx - B * vy, B * vx + A * vy], axis=-1)
        )

    @override
    def log(self) -> jax.Array:
        """Principal logarithm: the tangent (vx, vy, θ), ``(*batch, 3)``, with
        θ = ``rotation().as_radians()`` in [−π, π].

        θ = atan2(s, c) (Eberly 2024, §8.2); v = V⁻¹ t with V⁻¹ = h I − (θ/2) J, J the 90°
        rotation and h = (θ/2)cot(θ/2) = 1 − θ² G(θ²) (the inverse of exp's V, since
        A² + B² = sinc²(θ/2); Zhang 2022, §5.3, reaches the same velocity geometrically)."""
        p = self.unit_complex_xy
        c, s, tx, ty = components(p)
        theta = jnp.arctan2(s, c)
        x = theta * theta
        h = 1.0 - x * _scalar.G_principal(x)
        half = 0.5 * theta
        return jnp.stack([h * tx + half * ty, h * ty - half * tx, theta], axis=-1)

    @classmethod
    @override
    def hat(cls, tangent: hints.Array) -> jax.Array:
        xi = as_float_array(tangent, "tangent", (3,), "SE2.hat")
        vx, vy, th = components(xi)
        z = jnp.zeros_like(th)
        return jnp.stack(
            [jnp.stack([z, -th, vx], -1), jnp.stack([th, z, vy], -1), jnp.stack([z, z, z], -1)],
            axis=-2,
        )

    @classmethod
    @override
    def vee(cls, matrix: hints.Array) -> jax.Array:
        m = as_float_array(matrix, "matrix", (3, 3), "SE2.vee")
        return jnp.stack([m[..., 0, 2], m[..., 1, 2], 0.5 * (m[..., 1, 0] - m[..., 0, 1])], -1)

    @override
    def adjoint(self) -> jax.Array:
        """Adjoint ``Ad(T)``, ``(*batch, 3, 3)``: [[R, (ty, −tx)ᵀ], [0, 1]] for the
        (vx, vy, θ) ordering (Eberly 2024, eq. 24, with the blocks permuted to translation
        first)."""
        p = self.unit_complex_xy
        c, s, tx, ty = components(p)
        z, one = jnp.zeros_like(c), jnp.ones_like(c)
        return jnp.stack(
            [jnp.stack([c, -s, ty], -1), jnp.stack([s, c, -tx], -1), jnp.stack([z, z, one], -1)],
            axis=-2,
        )

    @staticmethod
    def _jac_parts(xi: jax.Array):
        rx, ry, th = components(xi)
        x = th * th
        f1, tf2 = _scalar.F1(x), th * _scalar.F2(x)
        # J_r's translation column p (Solà et al. 2018, eq. 163, in kernels).
        px, py = tf2 * rx - f1 * ry, f1 * rx + tf2 * ry
        return th, x, f1, px, py

    @staticmethod
    def _mat3(
        a: Optional[jax.Array], b: jax.Array, p: jax.Array, q: jax.Array, corner: float
    ) -> jax.Array:
        """[[a, −b, p], [b, a, q], [0, 0, corner]], shape ``(*batch, 3, 3)`` (``a = None``:
        0), the shape of every SE(2) Jacobian. Built as broadcast scalars times constant
        3×3 patterns rather than as a stack, so that the kernels several entries share
        (jlog: the atan2 and G's series) are evaluated once per element, not once per
        entry."""
        terms = [(b, _ROT90), (p, _E02), (q, _E12)] + ([] if a is None else [(a, _I2)])
        like = p[..., None, None]
        out = corner * constant(_E22, like)
        for coef, pattern in terms:
            out = out + coef[..., None, None] * constant(pattern, like)
        return out

    @classmethod
    @override
    def jac_right(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 3) -> (*batch, 3, 3)``: J_r(ξ) = [[A, B, p_x], [−B, A, p_y], [0, 0, 1]],
        A = sin θ/θ, B = (1 − cos θ)/θ, p = (θF2 ρx − F1 ρy, F1 ρx + θF2 ρy) (Solà et al.
        2018, eq. 163)."""
        xi = cls._check_tangent(tangent, "jac_right")
        th, x, f1, px, py = cls._jac_parts(xi)
        A, B = _scalar.sinc(x), th * f1
        return cls._mat3(A, -B, px, py, 1.0)

    @classmethod
    @override
    def jac_right_inv(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 3) -> (*batch, 3, 3)``:
        J_r⁻¹(ξ) = [[h, −θ/2, θG ρx + ρy/2], [θ/2, h, θG ρy − ρx/2], [0, 0, 1]] with
        h = (θ/2)cot(θ/2) = 1 − θ² G(θ²): ``jac_right`` inverted in closed form. Its
        translation column −M⁻¹p (p from Solà et al. 2018, eq. 163) simplifies, with
        1 − cos θ = 2 sin²(θ/2), to (θG I − ½ J) ρ, J the 90° rotation: one kernel (G)
        where the literal inverse needs F1, F2 and G."""
        return cls._jac_right_inv(cls._check_tangent(tangent, "jac_right_inv"), _scalar.G)

    @override
    def jlog(self) -> jax.Array:
        # log's angle is principal (|θ| ≤ π): G's series alone, shared with log() by CSE.
        return self._jac_right_inv(self.log(), _scalar.G_principal)

    @classmethod
    def _jac_right_inv(cls, xi: jax.Array, G: Callable[[jax.Array], jax.Array]) -> jax.Array:
        rx, ry, th = components(xi)
        x = th * th
        g = G(x)
        h, tg, half = 1.0 - x * g, th * g, 0.5 * th
        return cls._mat3(h, half, tg * rx + 0.5 * ry, tg * ry - 0.5 * rx, 1.0)

    @classmethod
    @override
    def ad(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 3) -> (*batch, 3, 3)``: [[0, −θ, vy], [θ, 0, −vx], [0, 0, 0]] for the
        (vx, vy, θ) ordering."""
        xi = cls._check_tangent(tangent, "ad")
        vx, vy, th = components(xi)
        return cls._mat3(None, th, vy, -vx, 0.0)
