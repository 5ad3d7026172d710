"""SE₂(3): extended poses (rotation, position, velocity), the group of inertial navigation.

Elements are the 5×5 matrices [[R, p, v], [0, 1, 0], [0, 0, 1]] (Barrau and Bonnabel,
*The invariant extended Kalman filter as a stable observer*, 2017, §III): SO(3) acting on
two vectors at once. Every operation is SE(3)'s applied to both, with the same rotation
kernels: exp and log share one half-angle and one quaternion log between position and
velocity, and the Jacobians carry one SE(3) coupling block Q per vector.
"""

from __future__ import annotations

from typing import Any, Tuple

import jax
import jax.numpy as jnp
from typing_extensions import override

from . import _scalar, hints
from ._base import MatrixLieGroup
from ._checks import as_float_array, check_batches, check_type, resolve_dtype
from ._jit import deprecated_alias
from ._pytree import pytree_dataclass
from ._scalar import dot, sq_norm
from ._se3 import SE3, coupled_inverse, coupling_entries, exp_translation, log_translation
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
    Schedule,
    aligned,
    block_matrix,
    from_block_entries,
    materialize_columns,
    matmul,
    matmul_unrolled,
)


@pytree_dataclass
class SE23(MatrixLieGroup):
    """Extended poses: a rotation R, a position p and a velocity v, acting on points as the
    pose (R, p) does.

    Parameters: ``wxyz_xyz_vel = (qw, qx, qy, qz, px, py, pz, vx, vy, vz)``, shape
    ``(*batch, 10)``: the first seven are an ``SE3``'s ``wxyz_xyz`` (the pose).
    Tangent: ``(ρ, ω, ν)`` = (position part, rotation, velocity part), shape ``(*batch, 9)``:
    the first six are an ``SE3`` tangent, the order of manif's ``SE_2_3``
    (docs/conventions.md has the conversion to GTSAM's ``NavState``).
    Matrix: ``[[R, p, v], [0, 1, 0], [0, 0, 1]]``; hat(ρ, ω, ν) = ``[[ω̂, ρ, ν], [0, 0, 0],
    [0, 0, 0]]``. A point x is the homogeneous vector (x, 1, 0): ``T @ x = R x + p``, the
    velocity does not act on points.
    """

    wxyz_xyz_vel: jax.Array
    """``(qw, qx, qy, qz, px, py, pz, vx, vy, vz)``, shape ``(*batch, 10)``."""

    matrix_dim = 5
    parameters_dim = 10
    tangent_dim = 9
    space_dim = 3
    _schedule = Schedule(reread=True, interpolate_in_memory=True)

    # -- construction and accessors -------------------------------------------------

    @classmethod
    def from_rotation_translation_and_velocity(
        cls, rotation: SO3, translation: hints.Array, velocity: hints.Array
    ) -> SE23:
        """The extended pose (R, p, v); batch axes of the three broadcast.

        Args:
            rotation: an ``SO3``.
            translation: ``(*batch, 3)``, the position p.
            velocity: ``(*batch, 3)``.
        """
        where = "SE23.from_rotation_translation_and_velocity"
        check_type(where, "rotation", rotation, SO3)
        r = rotation.parameters()
        p = as_float_array(translation, "translation", (3,), where, like=r)
        v = as_float_array(velocity, "velocity", (3,), where, like=r)
        batch = check_batches(
            where,
            "rotation, translation and velocity batch axes",
            r.shape[:-1],
            p.shape[:-1],
            v.shape[:-1],
        )
        dtype = jnp.result_type(r, p, v)
        parts = [jnp.broadcast_to(a.astype(dtype), (*batch, a.shape[-1])) for a in (r, p, v)]
        return SE23(jnp.concatenate(parts, axis=-1))

    @classmethod
    def from_pose_and_velocity(cls, pose: SE3, velocity: hints.Array) -> SE23:
        """The extended pose of an ``SE3`` pose (R, p) and a velocity v."""
        check_type("SE23.from_pose_and_velocity", "pose", pose, SE3)
        return cls.from_rotation_translation_and_velocity(
            pose.rotation(), pose.translation(), velocity
        )

    def rotation(self) -> SO3:
        """R, an ``SO3`` with the same batch axes."""
        return SO3(self.wxyz_xyz_vel[..., :4])

    def translation(self) -> jax.Array:
        """p, the position, ``(*batch, 3)``."""
        return self.wxyz_xyz_vel[..., 4:7]

    def velocity(self) -> jax.Array:
        """v, ``(*batch, 3)``."""
        return self.wxyz_xyz_vel[..., 7:]

    from_rotation_position_velocity = deprecated_alias(
        "from_rotation_position_velocity",
        "from_rotation_translation_and_velocity",
        on_class=True,
        renamed={"position": "translation"},
    )
    from_pose_velocity = deprecated_alias(
        "from_pose_velocity", "from_pose_and_velocity", on_class=True
    )
    position = deprecated_alias("position", "translation")

    def pose(self) -> SE3:
        """The pose (R, p) as an ``SE3`` (the first seven parameters)."""
        return SE3(self.wxyz_xyz_vel[..., :7])

    def _parts(self) -> Tuple[SO3, jax.Array, jax.Array]:
        return self.rotation(), self.translation(), self.velocity()

    def _unit_part(self) -> jax.Array:
        return self.wxyz_xyz_vel[..., :4]

    def _linear_part(self) -> jax.Array:
        return self.rotation().as_matrix()

    @classmethod
    @override
    def identity(cls, batch_axes: Tuple[int, ...] = (), dtype: Any = None) -> SE23:
        dtype = resolve_dtype(dtype)
        p = jnp.zeros((*batch_axes, 10), dtype)
        return SE23(p.at[..., 0].set(1.0))

    @classmethod
    @override
    def sample_uniform(
        cls, key: jax.Array, batch_axes: Tuple[int, ...] = (), dtype: Any = None
    ) -> SE23:
        """Haar-uniform rotation; position and velocity uniform in [−1, 1]³."""
        dtype = resolve_dtype(dtype)
        k0, k1 = jax.random.split(key)
        rot = SO3.sample_uniform(k0, batch_axes, dtype)
        pv = jax.random.uniform(k1, (*batch_axes, 6), dtype=dtype, minval=-1.0, maxval=1.0)
        return cls.from_rotation_translation_and_velocity(rot, pv[..., :3], pv[..., 3:])

    # -- exp, log and the algebra ---------------------------------------------------

    @classmethod
    @override
    def exp(cls, tangent: hints.Array) -> SE23:
        """Exponential map of (ρ, ω, ν): q = exp_SO3(ω), p = V(ω) ρ, v = V(ω) ν with SE(3)'s
        V (``_se3.exp_translation``; one half-angle for all three).

        Args:
            tangent: ``(*batch, 9)``.
        """
        xi = cls._check_tangent(tangent)
        rho, w, nu = xi[..., :3], xi[..., 3:6], xi[..., 6:]
        half = exp_half_angle(w)
        p = exp_translation(rho, w, half=half)
        v = exp_translation(nu, w, half=half)
        return SE23(jnp.concatenate([exp_quaternion(w, half), p, v], axis=-1))

    @override
    def log(self) -> jax.Array:
        """Principal logarithm (ρ, ω, ν), ``(*batch, 9)``, ‖ω‖ ∈ [0, π]: ρ = V⁻¹ p and
        ν = V⁻¹ v as in ``SE3.log`` (``_se3.log_translation``), from one quaternion log."""
        u, s, h = log_quaternion_parts(self.wxyz_xyz_vel[..., :4])
        rho = log_translation(self.translation(), u, s, h)
        nu = log_translation(self.velocity(), u, s, h)
        return jnp.concatenate([rho, s[..., None] * u, nu], axis=-1)

    @classmethod
    @override
    def hat(cls, tangent: hints.Array) -> jax.Array:
        xi = as_float_array(tangent, "tangent", (9,), "SE23.hat")
        top = jnp.concatenate([skew(xi[..., 3:6]), xi[..., :3, None], xi[..., 6:, None]], -1)
        bottom = jnp.zeros((*xi.shape[:-1], 2, 5), xi.dtype)
        return jnp.concatenate([top, bottom], axis=-2)

    @classmethod
    @override
    def vee(cls, matrix: hints.Array) -> jax.Array:
        m = as_float_array(matrix, "matrix", (5, 5), "SE23.vee")
        return jnp.concatenate([m[..., :3, 3], SO3.vee(m[..., :3, :3]), m[..., :3, 4]], -1)

    @override
    def adjoint(self) -> jax.Array:
        """``(*batch, 9, 9)``: [[R, p̂R, 0], [0, R, 0], [0, v̂R, R]] in the (ρ, ω, ν) order."""
        R = self.rotation().as_matrix()
        return block_matrix(
            [
                [R, matmul(skew(self.translation()), R), None],
                [None, R, None],
                [None, matmul(skew(self.velocity()), R), R],
            ]
        )

    @classmethod
    @override
    def ad(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 9, 9)``: [[ω̂, ρ̂, 0], [0, ω̂, 0], [0, ν̂, ω̂]]."""
        xi = cls._check_tangent(tangent, "ad")
        W = skew(xi[..., 3:6])
        return block_matrix(
            [[W, skew(xi[..., :3]), None], [None, W, None], [None, skew(xi[..., 6:]), W]]
        )

    @override
    def _adjoint_apply(self, tangent: jax.Array) -> jax.Array:
        """Ad(T)(ρ, ω, ν) = (R ρ + p × R ω, R ω, R ν + v × R ω), without the 9×9 matrix."""
        R = self.rotation().as_matrix()
        Rx = [matmul_unrolled(R, tangent[..., i : i + 3, None])[..., 0] for i in (0, 3, 6)]
        return jnp.concatenate(
            [
                Rx[0] + cross(self.translation(), Rx[1]),
                Rx[1],
                Rx[2] + cross(self.velocity(), Rx[1]),
            ],
            -1,
        )

    @classmethod
    @override
    def _bracket(cls, a: jax.Array, b: jax.Array) -> jax.Array:
        """[(ρ₁, ω₁, ν₁), (ρ₂, ω₂, ν₂)] = (ω₁ × ρ₂ + ρ₁ × ω₂, ω₁ × ω₂, ω₁ × ν₂ + ν₁ × ω₂)."""
        w1, w2 = a[..., 3:6], b[..., 3:6]
        return jnp.concatenate(
            [
                cross(w1, b[..., :3]) + cross(a[..., :3], w2),
                cross(w1, w2),
                cross(w1, b[..., 6:]) + cross(a[..., 6:], w2),
            ],
            -1,
        )

    @classmethod
    @override
    def jac_right(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 9) -> (*batch, 9, 9)``: [[J, Q(ρ), 0], [0, J, 0], [0, Q(ν), J]] with
        J = J_r(ω) of SO(3) and Q SE(3)'s coupling block (Barfoot and Furgale 2014, eq. 102,
        at −ξ; ``_se3.coupling_entries``), once per vector."""
        xi = cls._check_tangent(tangent, "jac_right")
        rho, w, nu = xi[..., :3], xi[..., 3:6], xi[..., 6:]
        x = sq_norm(w)
        x, f1, f2, c2, d, dp, dv = materialize_columns(
            x, _scalar.F1(x), _scalar.F2(x), _scalar.C2(x), _scalar.D(x), dot(w, rho), dot(w, nu)
        )
        J = rodrigues_entries(w, 1.0 - f2 * x, -f1, f2)
        Qp = coupling_entries(rho, w, x, f2, c2, d, dp)
        Qv = coupling_entries(nu, w, x, f2, c2, d, dv)
        return from_block_entries([[J, Qp, None], [None, J, None], [None, Qv, J]])

    @classmethod
    @override
    def jac_right_inv(cls, tangent: hints.Array) -> jax.Array:
        """``(*batch, 9) -> (*batch, 9, 9)``: the block inverse of ``jac_right`` in closed
        form, [[J⁻¹, −J⁻¹Q(ρ)J⁻¹, 0], [0, J⁻¹, 0], [0, −J⁻¹Q(ν)J⁻¹, J⁻¹]]."""
        xi = cls._check_tangent(tangent, "jac_right_inv")
        rho, w, nu = xi[..., :3], xi[..., 3:6], xi[..., 6:]
        x = sq_norm(w)
        x, f2, c2, d, g, dp, dv = materialize_columns(
            x, _scalar.F2(x), _scalar.C2(x), _scalar.D(x), _scalar.G(x), dot(w, rho), dot(w, nu)
        )
        Ji = rodrigues_entries(w, 1.0 - x * g, 0.5, g)
        Cp = coupled_inverse(Ji, coupling_entries(rho, w, x, f2, c2, d, dp))
        Cv = coupled_inverse(Ji, coupling_entries(nu, w, x, f2, c2, d, dv))
        return from_block_entries([[Ji, Cp, None], [None, Ji, None], [None, Cv, Ji]])

    # -- group operations -----------------------------------------------------------

    @override
    def as_matrix(self) -> jax.Array:
        R, p, v = self._parts()
        top = jnp.concatenate([R.as_matrix(), p[..., None], v[..., None]], axis=-1)
        bottom = jnp.broadcast_to(jnp.eye(5, dtype=p.dtype)[3:], (*p.shape[:-1], 2, 5))
        return jnp.concatenate([top, bottom], axis=-2)

    @classmethod
    @override
    def from_matrix(cls, matrix: hints.Array, project: bool = False) -> SE23:
        """The rotation of the 3×3 block (``SO3.from_matrix``, with ``project`` the
        nearest rotation to any block), p and v the fourth and fifth columns as they are;
        the bottom rows are not read."""
        m = cls._check_matrix(matrix, "from_matrix")
        return cls.from_rotation_translation_and_velocity(
            SO3.from_matrix(m[..., :3, :3], project), m[..., :3, 3], m[..., :3, 4]
        )

    @override
    def apply(self, target: hints.Array) -> jax.Array:
        """Points x ↦ R x + p, ``(*batch, 3)`` (the pose's action; v does not act)."""
        return self.pose().apply(target)

    @override
    def multiply(self, other: SE23) -> SE23:
        """(R₁R₂, R₁p₂ + p₁, R₁v₂ + v₁)."""
        a, b = self._schedule.inputs(*aligned(self, other))
        R = a.rotation()
        return SE23(
            jnp.concatenate(
                [
                    R._multiply_kernel(b.rotation()).wxyz,
                    R._apply_kernel(b.translation()) + a.translation(),
                    R._apply_kernel(b.velocity()) + a.velocity(),
                ],
                axis=-1,
            )
        )

    def _between(self, other: SE23) -> SE23:
        """``self⁻¹ @ other`` = (R₁⁻¹R₂, R₁⁻¹(p₂ − p₁), R₁⁻¹(v₂ − v₁)): nearby positions
        and velocities subtract exactly (as ``SE3``'s)."""
        a, b = self._schedule.inputs(*aligned(self, other))
        R_inv = a.rotation().inverse()
        return SE23(
            jnp.concatenate(
                [
                    R_inv._multiply_kernel(b.rotation()).wxyz,
                    R_inv._apply_kernel(b.translation() - a.translation()),
                    R_inv._apply_kernel(b.velocity() - a.velocity()),
                ],
                axis=-1,
            )
        )

    @override
    def inverse(self) -> SE23:
        """(R⁻¹, −R⁻¹p, −R⁻¹v)."""
        T = self._schedule.inputs(self)
        R_inv = T.rotation().inverse()
        return SE23(
            jnp.concatenate(
                [
                    R_inv.wxyz,
                    -R_inv._apply_kernel(T.translation()),
                    -R_inv._apply_kernel(T.velocity()),
                ],
                axis=-1,
            )
        )

    @override
    def normalize(self) -> SE23:
        return SE23(
            jnp.concatenate([self.rotation().normalize().wxyz, self.wxyz_xyz_vel[..., 4:]], axis=-1)
        )

    @override
    def _rplus_jacobian(self) -> jax.Array:
        # T @ exp(δ): q' = q ⊗ exp(δω), p' = p + R δρ, v' = v + R δν to first order.
        R = self.rotation()
        return block_matrix(
            [
                [None, R._rplus_jacobian(), None],
                [R.as_matrix(), None, None],
                [None, None, R.as_matrix()],
            ]
        )
