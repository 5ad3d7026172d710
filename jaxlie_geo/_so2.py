"""SO(2): planar rotations as unit complex numbers."""

from __future__ import annotations

from typing import Any, Tuple

import jax
import jax.numpy as jnp
from typing_extensions import override

from . import _scalar, hints
from ._base import SOBase
from ._checks import as_float_array, resolve_dtype
from ._projection import nearest_unit_complex, rotation_unit_complex
from ._pytree import pytree_dataclass
from ._scalar import components
from ._xla import constant


@pytree_dataclass
class SO2(SOBase):
    """Special orthogonal group of planar rotations.

    Parameters: ``unit_complex = (cos θ, sin θ)``, shape ``(*batch, 2)``.
    Tangent: ``(θ,)``, shape ``(*batch, 1)``. Matrix: ``[[c, -s], [s, c]]``
    (Eberly 2024, eq. 15).
    """

    unit_complex: jax.Array
    """``(cos θ, sin θ)``, shape ``(*batch, 2)``."""

    matrix_dim = 2
    parameters_dim = 2
    tangent_dim = 1
    space_dim = 2
    # -- factories ------------------------------------------------------------------

    @staticmethod
    def from_radians(theta: hints.Scalar) -> SO2:
        """Rotation by ``theta`` radians.

        Args:
            theta: angle, scalar or array of shape ``batch``.

        Returns:
            SO2 with batch axes ``batch``.
        """
        theta = as_float_array(theta, "theta", (), "SO2.from_radians")
        return SO2(jnp.stack([jnp.cos(theta), jnp.sin(theta)], axis=-1))

    def as_radians(self) -> jax.Array:
        """Angle atan2(sin, cos), shape ``batch``, in [-π, π]: -π only for a rotation by π
        whose stored sine is -0.0 (``SO2(jnp.array([-1.0, -0.0]))``), as in jaxlie and NumPy.
        Depends on the direction of ``unit_complex`` only."""
        c, s = components(self.unit_complex)
        return jnp.arctan2(s, c)

    @classmethod
    @override
    def identity(cls, batch_axes: Tuple[int, ...] = (), dtype: Any = None) -> SO2:
        dtype = resolve_dtype(dtype)
        return SO2(jnp.broadcast_to(jnp.array([1.0, 0.0], dtype), (*batch_axes, 2)))

    @classmethod
    @override
    def from_matrix(cls, matrix: hints.Array, project: bool = False) -> SO2:
        """The rotation nearest to ``matrix`` in the Frobenius norm (a projection onto SO(2)).

        θ = atan2(m10 − m01, m00 + m11), which maximises tr(R(θ)ᵀM) =
        (m00 + m11) cos θ + (m10 − m01) sin θ; stored as the unit vector along
        (m00 + m11, m10 − m01), without trigonometry (``jaxlie_geo/_projection.py``). A
        rotation matrix gives its own first column within 1 ulp (jaxlie reads that column
        as is). Where m00 + m11 = m10 − m01 = 0 (the zero matrix and every reflection
        [[a, b], [b, −a]]) all rotations are equally near, and the result is the
        identity. Differentiable; the derivative is 0 on that set.

        Both settings of ``project`` give this rotation. ``project=False`` signs a zero
        sine as m10, as jaxlie's first column does (``from_matrix(-I)`` with −0.0 below
        the diagonal: angle −π), and squares entries unscaled (entries beyond about 1e19
        overflow in float32); ``project=True`` scales the matrix by a power of two first
        and stores the sine +0.0 at −I (angle π).

        Args:
            matrix: ``(*batch, 2, 2)``, any real matrix (not only a rotation).
            project: static; the variant above.

        Returns:
            SO2 with batch axes ``batch``, in the matrix's dtype.
        """
        m = cls._check_matrix(matrix, "from_matrix")
        return SO2(nearest_unit_complex(m) if project else rotation_unit_complex(m))

    @classmethod
    @override
    def sample_uniform(
        cls, key: jax.Array, batch_axes: Tuple[int, ...] = (), dtype: Any = None
    ) -> SO2:
        dtype = resolve_dtype(dtype)
        theta = jax.random.uniform(key, batch_axes, dtype=dtype, minval=0.0, maxval=2.0 * jnp.pi)
        return SO2.from_radians(theta)

    # -- Lie algebra ----------------------------------------------------------------

    @classmethod
    @override
    def exp(cls, tangent: hints.Array) -> SO2:
        """Exponential map: ``(*batch, 1)`` tangent (θ,) -> (cos θ, sin θ)
        (Eberly 2024, eq. 15); SO2 with batch axes ``batch``."""
        theta = cls._check_tangent(tangent)[..., 0]
        return SO2(jnp.stack([jnp.cos(theta), jnp.sin(theta)], axis=-1))

    @override
    def log(self) -> jax.Array:
        """Principal logarithm: ``(*batch, 1)``, θ = atan2(sin, cos) in [-π, π]
        (Eberly 2024, §7.2; see ``as_radians``)."""
        return self.as_radians()[..., None]

    @classmethod
    @override
    def hat(cls, tangent: hints.Array) -> jax.Array:
        theta = as_float_array(tangent, "tangent", (1,), "SO2.hat")[..., 0]
        z = jnp.zeros_like(theta)
        return jnp.stack([jnp.stack([z, -theta], -1), jnp.stack([theta, z], -1)], -2)

    @classmethod
    @override
    def vee(cls, matrix: hints.Array) -> jax.Array:
        m = as_float_array(matrix, "matrix", (2, 2), "SO2.vee")
        return 0.5 * (m[..., 1, 0:1] - m[..., 0, 1:2])

    @override
    def adjoint(self) -> jax.Array:
        return jnp.ones((*self.get_batch_axes(), 1, 1), self.unit_complex.dtype)

    @classmethod
    @override
    def jac_right(cls, tangent: hints.Array) -> jax.Array:
        x = cls._check_tangent(tangent, "jac_right")
        return jnp.ones_like(x)[..., None]

    @classmethod
    @override
    def jac_right_inv(cls, tangent: hints.Array) -> jax.Array:
        x = cls._check_tangent(tangent, "jac_right_inv")
        return jnp.ones_like(x)[..., None]

    @classmethod
    @override
    def ad(cls, tangent: hints.Array) -> jax.Array:
        x = cls._check_tangent(tangent, "ad")
        return jnp.zeros_like(x)[..., None]

    # -- operations -----------------------------------------------------------------

    @override
    def as_matrix(self) -> jax.Array:
        # Row 0 is (c, −s) = u·(1, −1), row 1 is (s, c) = u reversed: one select between
        # two broadcast rows, instead of nested stacks that pick among four sources per
        # element.
        u = self.unit_complex
        top = (u * constant([1.0, -1.0], u))[..., None, :]
        row = jax.lax.broadcasted_iota(jnp.int32, (*u.shape[:-1], 2, 2), u.ndim - 1)
        return jnp.where(row == 0, top, u[..., None, ::-1])

    @override
    def _matrix_block(self) -> jax.Array:
        # Inside SE2's matrices a stack fuses better than as_matrix's select.
        c, s = components(self.unit_complex)
        return jnp.stack([jnp.stack([c, -s], -1), jnp.stack([s, c], -1)], -2)

    @override
    def _apply_kernel(self, points: jax.Array) -> jax.Array:
        c, s = components(self.unit_complex)
        x, y = components(points)
        return jnp.stack([c * x - s * y, s * x + c * y], axis=-1)

    @override
    def _multiply_kernel(self, other: SO2) -> SO2:
        c1, s1 = components(self.unit_complex)
        c2, s2 = components(other.unit_complex)
        return SO2(jnp.stack([c1 * c2 - s1 * s2, s1 * c2 + c1 * s2], axis=-1))

    @override
    def _action_jacobian(self, points: jax.Array) -> jax.Array:
        # R K(p) = R J p = J R p (plane rotations commute with J = hat(1)): one rotation of
        # p, read from (c, s), written as a·e₀ + b·e₁ (scalars broadcast onto constant
        # columns), a form XLA:CPU writes faster than a stack.
        c, s = self.unit_complex[..., 0, None, None], self.unit_complex[..., 1, None, None]
        x, y = points[..., 0, None, None], points[..., 1, None, None]
        e0, e1 = constant([[1.0], [0.0]], x), constant([[0.0], [1.0]], x)
        col = -(s * x + c * y) * e0 + (c * x - s * y) * e1
        batch = jnp.broadcast_shapes(self.get_batch_axes(), points.shape[:-1])
        return jnp.broadcast_to(col, (*batch, 2, 1))

    @override
    def inverse(self) -> SO2:
        p = self.unit_complex
        return SO2(p * constant([1.0, -1.0], p))

    @override
    def normalize(self) -> SO2:
        return SO2(_scalar.unit(self.unit_complex))

    @override
    def _rplus_jacobian(self) -> jax.Array:
        c, s = components(self.unit_complex)
        return jnp.stack([-s, c], axis=-1)[..., None]
