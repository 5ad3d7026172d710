"""Jacobians of the group operations with respect to right perturbations.

Convention (Solà, Deray and Atchuthan, *A micro Lie theory for state estimation in
robotics*, 2018, §III): for f: G → H, the right Jacobian

    J = ∂ log(f(X)⁻¹ f(X ⊕ δ)) / ∂δ  at δ = 0,   X ⊕ δ = X @ exp(δ),

so that ``f(X ⊕ δ) ≈ f(X) ⊕ J δ``. Points are perturbed additively. A function of two
arguments returns a tuple of two Jacobians, in argument order; one of a single element or
tangent (``inverse``, ``exp``, ``log``, ``generator_action``) returns one array. The
arguments' batch axes broadcast; shapes ``(*batch, out_dim, in_dim)``, k = ``tangent_dim``.

| operation     | value              | Jacobians           |
|---------------|--------------------|---------------------|
| compose(a, b) | a @ b              | Ad(b⁻¹), I          |
| inverse(a)    | a⁻¹                | −Ad(a)              |
| apply(T, p)   | T @ p              | R K(p), R           |
| between(a, b) | a⁻¹ @ b            | −Ad(b⁻¹a), I        |
| rminus(a, b)  | log(a⁻¹ b) = b ⊖ a | −J_l⁻¹(τ), J_r⁻¹(τ) |
| rplus(a, δ)   | a @ exp(δ)         | Ad(exp(−δ)), J_r(δ) |
| exp(x)        | exp(x)             | J_r(x)              |
| log(a)        | log(a)             | J_r⁻¹(log a)        |

These are Solà et al.'s elementary Jacobian blocks (2018, §III), written once for every
group through ``adjoint``, ``jac_right`` and ``jac_right_inv``; the groups' closed forms of
J_r and J_r⁻¹ are, for example, eqs. 143–144 of the same paper for SO(3) and eq. 163 for
SE(2). τ = log(a⁻¹ b), and J_l(τ) = J_r(−τ).

K(p) is the generators' action on the point: column i is the first ``space_dim`` entries
of ``hat(eᵢ) p̃`` (p̃ = (p, 1) for SE groups), e.g. [I, −p̂] for SE(3), −p̂ for SO(3).
"""

from __future__ import annotations

from typing import Tuple, Type

import jax
import jax.numpy as jnp

from . import hints
from ._base import GroupT, MatrixLieGroup, SOBase
from ._checks import as_float_array, check_batches
from ._jit import jit_function
from ._xla import aligned


def _eye_like(T: MatrixLieGroup) -> jax.Array:
    p = T.parameters()
    return jnp.broadcast_to(
        jnp.eye(T.tangent_dim, dtype=p.dtype), (*p.shape[:-1], T.tangent_dim, T.tangent_dim)
    )


def _broadcast(a: jax.Array, b: jax.Array) -> Tuple[jax.Array, jax.Array]:
    batch = jnp.broadcast_shapes(a.shape[:-2], b.shape[:-2])
    return (
        jnp.broadcast_to(a, (*batch, *a.shape[-2:])),
        jnp.broadcast_to(b, (*batch, *b.shape[-2:])),
    )


@jit_function()
def compose(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a @ b`` with respect to ``a`` and ``b``.

    Args:
        a: element of any group.
        b: element of the same group; batch axes broadcast with ``a``'s.

    Returns:
        ``(Ad(b⁻¹), I)``, each ``(*batch, k, k)``, ``batch`` the broadcast batch axes.
    """
    return _broadcast(b.inverse().adjoint(), _eye_like(a.multiply(b)))


@jit_function()
def inverse(a: GroupT) -> jax.Array:
    """Jacobian of ``a⁻¹`` with respect to ``a``.

    Args:
        a: element with batch axes ``batch``.

    Returns:
        ``−Ad(a)``, ``(*batch, k, k)``.
    """
    return -a.adjoint()


@jit_function()
def between(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a⁻¹ @ b`` with respect to ``a`` and ``b``.

    Args:
        a: element of any group.
        b: element of the same group; batch axes broadcast with ``a``'s.

    Returns:
        ``(−Ad(b⁻¹ a), I)``, each ``(*batch, k, k)``, ``batch`` the broadcast batch axes.
    """
    return _broadcast(-b._between(a).adjoint(), _eye_like(a._between(b)))


@jit_function()
def rminus(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``τ = log(a⁻¹ @ b)`` (the pose-graph residual, ``manifold.rminus``)
    with respect to ``a`` and ``b``.

    Args:
        a: element of any group.
        b: element of the same group; batch axes broadcast with ``a``'s.

    Returns:
        ``(−J_l⁻¹(τ), J_r⁻¹(τ))``, each ``(*batch, k, k)``, ``batch`` the broadcast batch
        axes. J_r⁻¹(τ) is ``jlog`` of ``a⁻¹ b`` (the log is principal), and for rotation
        groups J_l⁻¹ = J_r⁻¹ᵀ.
    """
    G = type(a)
    e = a._between(b)
    J_r_inv = e.jlog()  # the log is principal: the groups' faster jlog applies
    if isinstance(e, SOBase):  # rotation groups: J_l(τ) = J_r(τ)ᵀ
        return -jnp.swapaxes(J_r_inv, -1, -2), J_r_inv
    return -G.jac_left_inv(e.log()), J_r_inv


@jit_function()
def rplus(a: GroupT, delta: hints.Array) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a @ exp(δ)`` with respect to ``a`` and ``δ``.

    Args:
        a: element of any group.
        delta: ``(*batch', k)`` tangent δ; batch axes broadcast with ``a``'s.

    Returns:
        ``(Ad(exp(−δ)), J_r(δ))``, each ``(*batch, k, k)``, ``batch`` the broadcast batch
        axes.

    Raises:
        ValueError: the batch axes of ``a`` and ``delta`` do not broadcast.
    """
    G = type(a)
    delta = G._check_tangent(delta, "jacobians.rplus", like=a.parameters(), name="delta")
    check_batches(
        "jacobians.rplus",
        "batch axes of the element and `delta`",
        a.get_batch_axes(),
        delta.shape[:-1],
    )
    J_a, J_d = _broadcast(G.exp(-delta).adjoint(), G.jac_right(delta))
    J_a, _ = _broadcast(J_a, _eye_like(a))  # the element's batch axes broadcast too
    return _broadcast(J_a, J_d)


@jit_function("G")
def exp(G: Type[MatrixLieGroup], tangent: hints.Array) -> jax.Array:
    """Jacobian of ``G.exp`` at ``tangent``: the right Jacobian ``J_r``.

    Args:
        G: the group class, e.g. ``SE3``.
        tangent: ``(*batch, k)``.

    Returns:
        ``G.jac_right(tangent)``, ``(*batch, k, k)``.
    """
    return G.jac_right(tangent)


@jit_function()
def log(a: MatrixLieGroup) -> jax.Array:
    """Jacobian of ``a.log()`` with respect to ``a``.

    Args:
        a: element with batch axes ``batch``.

    Returns:
        ``J_r⁻¹(log a)`` (= ``a.jlog()``), ``(*batch, k, k)``.
    """
    return a.jlog()


@jit_function("G")
def generator_action(G: Type[MatrixLieGroup], points: hints.Array) -> jax.Array:
    """The generators' action on points, K(p) = ``d (hat(δ) p̃)[:space_dim] / dδ``
    (p̃ = (p, 1) for SE groups): e.g. ``[I, −p̂]`` for SE(3), ``−p̂`` for SO(3). Entry (i, j)
    is Σ_l hat(e_j)[i, l] p̃_l.

    Args:
        G: the group class.
        points: ``(*batch, space_dim)``.

    Returns:
        ``(*batch, space_dim, tangent_dim)``.
    """
    p = as_float_array(points, "points", (G.space_dim,), "jacobians.generator_action")
    return G._generator_action(p)


@jit_function()
def apply(T: GroupT, points: hints.Array) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``T @ p`` with respect to ``T`` (right perturbation) and ``p``.

    Args:
        T: element of any group.
        points: ``(*batch', space_dim)``; batch axes broadcast with ``T``'s.

    Returns:
        ``(R K(p), R)`` with R the rotation matrix (``generator_action`` for K), of shapes
        ``(*batch, space_dim, tangent_dim)`` and ``(*batch, space_dim, space_dim)``.
    """
    return _apply(T, points, "jacobians.apply")


def _apply(T: GroupT, points: hints.Array, where: str) -> Tuple[jax.Array, jax.Array]:
    """``apply``'s body; errors about ``points`` name ``where``."""
    T, p = aligned(T, T._check_points(points, where, "points"))
    R = T._linear_part()
    R = R.astype(jnp.result_type(R, p))
    batch = jnp.broadcast_shapes(R.shape[:-2], p.shape[:-1])
    return T._action_jacobian(p.astype(R.dtype)), jnp.broadcast_to(R, (*batch, *R.shape[-2:]))


__all__ = [
    "compose",
    "inverse",
    "apply",
    "between",
    "rminus",
    "rplus",
    "exp",
    "log",
    "generator_action",
]
