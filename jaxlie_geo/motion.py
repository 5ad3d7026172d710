"""Motion at constant body velocity (Zhang, *A Geometric Introduction to Lie Theory*, 2022,
§3–§9; the time-scaled logarithm ω = ln_τ R, the angular velocity that turns the identity
into R in time τ).

A body moving with constant *local* (body-frame) linear and angular velocity ``ξ`` —
``(vx, vy, ω)`` for SE(2), ``(v, ω)`` for SE(3), ``ω`` for SO(3) — follows

    T(t) = T₀ @ exp(t · ξ),

the group's one-parameter subgroup moved to T₀. The velocity that carries ``start`` to
``end`` in time ``duration`` is ``log(start⁻¹ end) / duration``. In the plane the path is a
circular arc of signed curvature ω/|v| (a line when ω = 0); in space, a helix.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from . import hints
from ._base import GroupT
from ._checks import as_float_array, check_batches
from ._geodesic import Geodesic
from ._jit import jit_function
from ._pytree import pytree_dataclass
from ._se2 import SE2
from ._xla import aligned


def velocity_between(start: GroupT, end: GroupT, duration: hints.Scalar) -> jax.Array:
    """Constant body velocity ξ with ``start @ exp(duration · ξ) == end``.

    Uses the principal log: the rotation turned over the motion is at most π (at exactly π
    the log's tie-break picks the axis; see ``SO3.log``). For a longer turn (a duck going
    around twice) give the velocity directly to ``pose_at``.

    Args:
        start: element of a group; batch axes broadcast with ``end``'s.
        end: element of the same group.
        duration: non-zero scalar or array broadcasting with the batch axes; a negative
            duration runs the path backwards. A concrete zero raises ``ValueError``; a traced
            zero gives inf/NaN, as any division by zero.

    Returns:
        ``(*batch, tangent_dim)``: velocity per unit time in ``start``'s body frame.
        ``velocity_between(identity, R, τ)`` is the time-scaled logarithm ln_τ R, the ω
        with exp(ω̂ τ) = R.

    Raises:
        TypeError: ``start`` and ``end`` are not the same group.
        ValueError: ``duration`` is a concrete zero, or the batch axes do not broadcast.
    """
    if type(start) is not type(end):
        raise TypeError(
            f"velocity_between: endpoints must be the same group, got "
            f"{type(start).__name__} and {type(end).__name__}."
        )
    duration = as_float_array(duration, "duration", (), "velocity_between")
    if not isinstance(duration, jax.core.Tracer) and bool(jnp.any(duration == 0)):
        raise ValueError("velocity_between: `duration` must be non-zero.")
    tangent = start._between(end).log()
    check_batches(
        "velocity_between",
        "batch axes of the poses and `duration`",
        tangent.shape[:-1],
        duration.shape,
    )
    tangent, duration = aligned(tangent, duration[..., None].astype(tangent.dtype))
    return tangent / duration


@jit_function()
def pose_at(start: GroupT, velocity: hints.Array, t: hints.Scalar) -> GroupT:
    """Pose at time ``t`` of a body leaving ``start`` with constant body velocity:
    ``start @ exp(t · velocity)``.

    Args:
        start: element, batch ``B``.
        velocity: ``(*B', tangent_dim)``, body frame; any rotation rate (turns beyond π are
            followed, not wrapped).
        t: scalar or array; broadcasts numpy-style against the batch axes, as in
            ``interpolate`` (a batch of times on one body: ``t`` of shape (K,)).

    Returns:
        Element of ``start``'s group, batch the broadcast of ``B``, ``B'`` and ``t``'s
        shape (numpy-style, as ``interpolate``).
    """
    G = type(start)
    velocity = G._check_tangent(
        velocity, "motion.pose_at", like=start.parameters(), name="velocity"
    )
    return Geodesic(start, velocity)(t)


@pytree_dataclass
class Arc:
    """The planar path of ``pose_at(start, velocity, t)`` for SE(2), in the world frame.

    All fields have the batch shape of the inputs (points: ``(*batch, 2)``).
    """

    start: jax.Array
    """Start point (the start pose's translation), ``(*batch, 2)``."""
    heading: jax.Array
    """Direction of travel at the start, in radians (atan2 of the world-frame linear
    velocity; 0 when the linear velocity is zero)."""
    speed: jax.Array
    """|v|, the linear speed."""
    angular_velocity: jax.Array
    """ω, the turning rate (positive: counter-clockwise)."""
    curvature: jax.Array
    """Signed curvature ω/|v| (positive: turning left). 0 on a straight line (ω = 0);
    ±inf when turning on the spot (|v| = 0, ω ≠ 0); 0 when standing still."""
    centre: jax.Array
    """Centre of the circle, ``start + J u / ω`` with u the world-frame velocity and J the
    90° rotation. Meaningful only where ω ≠ 0; equal to ``start`` where ω = 0."""

    @property
    def radius(self) -> jax.Array:
        """|v|/|ω|, shape ``batch``: inf on a straight line and, as 1/|curvature|, when
        standing still; 0 when turning on the spot."""
        still = (self.speed == 0) & (self.angular_velocity == 0)
        return jnp.where(still, jnp.inf, self.speed / jnp.abs(self.angular_velocity))


@jit_function()
def arc(start: SE2, velocity: hints.Array) -> Arc:
    """The circle (or line) traced by an SE(2) body with constant body velocity
    ``(vx, vy, ω)`` (Zhang 2022, §5.1–5.4, with the chord AB = (R − I)·OA; the text's
    (I − R)·OA is a sign slip).

    Geometry: the world-frame velocity is u = R₀ v; the body turns about the centre
    c = p₀ + J u/ω (J = 90° rotation), with radius |v|/|ω|; after time t it has turned by
    ωt, and its position is c + R(ωt)(p₀ − c) — the same pose as ``pose_at``.

    Args:
        start: SE2, batch ``B``.
        velocity: ``(*B', 3)``, body frame (vx, vy, ω).

    Returns:
        An ``Arc`` whose fields have the batch shape ``broadcast(B, B')``.
    """
    if not isinstance(start, SE2):
        raise TypeError(f"arc: `start` must be SE2, got {type(start).__name__}.")
    xi = SE2._check_tangent(velocity, "motion.arc", like=start.parameters(), name="velocity")
    check_batches(
        "arc", "batch axes of `start` and `velocity`", start.get_batch_axes(), xi.shape[:-1]
    )
    v, omega = xi[..., :2], xi[..., 2]
    u = start.rotation().apply(v)
    p0 = start.translation()
    batch = jnp.broadcast_shapes(u.shape[:-1], p0.shape[:-1])
    u = jnp.broadcast_to(u, (*batch, 2))
    p0 = jnp.broadcast_to(p0.astype(u.dtype), (*batch, 2))
    omega = jnp.broadcast_to(omega, batch)
    # At zero speed the square root and atan2 are not differentiable; their inputs are
    # swapped for harmless values there, so gradients are 0 there instead of NaN.
    n2 = jnp.sum(u * u, axis=-1)
    moving = n2 > 0
    turning = omega != 0
    safe_speed = jnp.sqrt(jnp.where(moving, n2, 1.0))
    speed = jnp.where(moving, safe_speed, 0.0)
    safe_omega = jnp.where(turning, omega, 1.0)
    safe_u = jnp.where(moving[..., None], u, jnp.ones_like(u))
    # ±inf by a select, not sign(ω)·inf: 0·inf would make a NaN (discarded, but caught by
    # jax_debug_nans without jit) wherever ω = 0.
    spin = jnp.where(omega > 0, jnp.inf, -jnp.inf)
    curvature = jnp.where(moving, omega / safe_speed, jnp.where(turning, spin, 0.0))
    Ju = jnp.stack([-u[..., 1], u[..., 0]], axis=-1)
    centre = jnp.where(turning[..., None], p0 + Ju / safe_omega[..., None], p0)
    heading = jnp.where(moving, jnp.arctan2(safe_u[..., 1], safe_u[..., 0]), 0.0)
    return Arc(
        start=p0,
        heading=heading,
        speed=speed,
        angular_velocity=omega,
        curvature=curvature,
        centre=centre,
    )


__all__ = ["velocity_between", "pose_at", "arc", "Arc"]
