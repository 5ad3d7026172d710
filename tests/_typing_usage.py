"""User code whose types a static checker must infer exactly (``tests/test_typing.py``).

Each ``assert_type(expr, T)`` is checked twice. mypy checks it statically: the inferred type
must be ``T`` itself, not ``Any`` and not a base class. The module also runs, and then the
runtime ``assert_type`` below checks that the value really is an instance of ``T``. So the
annotations can drift neither from what an editor infers nor from what the code returns.
"""

from __future__ import annotations

import typing
from typing import TYPE_CHECKING, Any, Tuple

import jax
import jax.numpy as jnp

import jaxlie_geo as jaxlie
from jaxlie_geo import SE2, SE3, SO2, SO3, jacobians, manifold, motion, uncertainty

if TYPE_CHECKING:
    from typing_extensions import assert_type
else:

    def assert_type(value: Any, typ: Any) -> Any:
        """The runtime half: ``value`` is an instance of ``typ`` (of its origin, if
        generic)."""
        origin = typing.get_origin(typ) or typ
        assert isinstance(value, origin), f"{type(value).__name__} is not {typ}"
        if origin is tuple:
            for item, item_type in zip(value, typing.get_args(typ)):
                assert_type(item, item_type)
        return value


key = jax.random.key(0)

# Every group: factories, the group operations, the tangent-space maps.
assert_type(SO2.identity(), SO2)
assert_type(SO2.exp(jnp.zeros(1)), SO2)
assert_type(SO2.from_radians(0.3), SO2)
assert_type(SO2(unit_complex=jnp.array([1.0, 0.0])), SO2)
assert_type(SO2.from_radians(0.3).as_radians(), jax.Array)
assert_type(SO2.from_radians(0.3).unit_complex, jax.Array)
assert_type(SE2.identity(), SE2)
assert_type(SE2.exp(jnp.zeros(3)), SE2)
assert_type(SE2.from_xy_theta(1.0, 2.0, 0.3), SE2)
assert_type(SE2(unit_complex_xy=jnp.array([1.0, 0.0, 0.0, 0.0])), SE2)
assert_type(SE2.from_xy_theta(1.0, 2.0, 0.3).rotation(), SO2)
assert_type(SO3.identity(), SO3)
assert_type(SO3.exp(jnp.zeros(3)), SO3)
assert_type(SO3(wxyz=jnp.array([1.0, 0.0, 0.0, 0.0])), SO3)
assert_type(SO3.from_rpy_radians(0.1, 0.2, 0.3), SO3)
assert_type(SO3.from_x_radians(0.1), SO3)
assert_type(SO3.from_quaternion_xyzw(jnp.array([0.0, 0.0, 0.0, 1.0])), SO3)
assert_type(SO3.identity().as_rpy_radians(), jaxlie.hints.RollPitchYaw)
assert_type(SO3.identity().as_quaternion_xyzw(), jax.Array)
assert_type(SO3.identity().compute_yaw_radians(), jax.Array)
assert_type(SO3.identity().wxyz, jax.Array)
assert_type(SE3.exp(jnp.zeros(6)).rotation(), SO3)
assert_type(SE3(wxyz_xyz=jnp.array([1.0, 0, 0, 0, 0, 0, 0])), SE3)
assert_type(SE3.from_rotation(SO3.identity()), SE3)
assert_type(SE3.from_translation(jnp.zeros(3)), SE3)
assert_type(SE3.from_rotation_and_translation(SO3.identity(), jnp.zeros(3)), SE3)

R2, P2, R3 = SO2.from_radians(0.3), SE2.from_xy_theta(1.0, 2.0, 0.3), SO3.from_y_radians(0.3)
assert_type(R2 @ R2.inverse(), SO2)
assert_type(P2 @ P2.inverse(), SE2)
assert_type(R3 @ R3.inverse(), SO3)
assert_type(R2 @ jnp.ones(2), jax.Array)
assert_type(P2.interpolate(P2, 0.5), SE2)
assert_type(SE2.from_rotation_and_translation(R2, jnp.zeros(2)), SE2)

T = SE3.sample_uniform(key, batch_axes=(4,))
p = jnp.ones((4, 3))
x = T.log()
assert_type(T, SE3)
assert_type(SE3.identity((4,)), SE3)
assert_type(SE3.from_matrix(T.as_matrix()), SE3)
assert_type(T @ T, SE3)
assert_type(T @ p, jax.Array)
assert_type(T.multiply(T), SE3)
assert_type(T.inverse(), SE3)
assert_type(T.apply(p), jax.Array)
assert_type(T.normalize(), SE3)
assert_type(T.is_valid(), jax.Array)
assert_type(T.is_valid(1e-3), jax.Array)
jaxlie.check_valid(T, atol=1e-3)
assert_type(T.interpolate(T.inverse(), 0.5), SE3)
assert_type(x, jax.Array)
assert_type(T.translation(), jax.Array)
assert_type(T.wxyz_xyz, jax.Array)
assert_type(T.parameters(), jax.Array)
assert_type(T.as_matrix(), jax.Array)
assert_type(T.adjoint(), jax.Array)
assert_type(T.jlog(), jax.Array)
assert_type(SE3.hat(x), jax.Array)
assert_type(SE3.vee(SE3.hat(x)), jax.Array)
assert_type(SE3.ad(x), jax.Array)
assert_type(SE3.jac_right(x), jax.Array)
assert_type(SE3.jac_left(x), jax.Array)
assert_type(SE3.jac_right_inv(x), jax.Array)
assert_type(SE3.jac_left_inv(x), jax.Array)
assert_type(T.get_batch_axes(), Tuple[int, ...])

# Batches.
assert_type(T[0], SE3)
assert_type(T[1:], SE3)
assert_type(T.reshape(2, 2), SE3)
assert_type(jaxlie.stack([T, T]), SE3)
for element in T:
    assert_type(element, SE3)

# Geodesics, motion, Jacobians, uncertainty, the manifold helpers.
assert_type(jaxlie.geodesic(T, T.inverse()), jaxlie.Geodesic[SE3])
assert_type(jaxlie.geodesic(T, T.inverse())(0.25), SE3)
assert_type(jaxlie.between(T, T.inverse()), SE3)
assert_type(motion.velocity_between(T, T.inverse(), 2.0), jax.Array)
assert_type(motion.pose_at(T, x, 0.5), SE3)
assert_type(motion.arc(SE2.identity(), jnp.array([1.0, 0.0, 0.5])), motion.Arc)
assert_type(jacobians.compose(T, T), Tuple[jax.Array, jax.Array])
assert_type(jacobians.inverse(T), jax.Array)
assert_type(jacobians.apply(T, p), Tuple[jax.Array, jax.Array])
assert_type(jacobians.between(T, T), Tuple[jax.Array, jax.Array])
assert_type(jacobians.rminus(T, T), Tuple[jax.Array, jax.Array])
assert_type(jacobians.rplus(T, x), Tuple[jax.Array, jax.Array])
assert_type(jacobians.exp(SE3, x), jax.Array)
assert_type(jacobians.log(T), jax.Array)
assert_type(jacobians.generator_action(SE3, p), jax.Array)
cov = jnp.broadcast_to(jnp.eye(6), (4, 6, 6))
assert_type(uncertainty.propagate_compose(T, cov, T, cov), jax.Array)
assert_type(uncertainty.propagate_inverse(T, cov), jax.Array)
assert_type(uncertainty.propagate_apply(T, cov, p), jax.Array)
assert_type(uncertainty.sample(key, T, cov), SE3)
assert_type(uncertainty.mean(T), SE3)
assert_type(manifold.rplus(T, x), SE3)
assert_type(manifold.normalize_all(T), SE3)
assert_type(manifold.rplus_jacobian_parameters_wrt_delta(T), jax.Array)
