"""Jacobians of the group operations with respect to right perturbations.

Convention (Solà, Deray, Atchuthan, *A micro Lie theory for state estimation in
robotics*, 2018, §III–IV): for f: G → H,

    J = d f(X)⁻¹ f(X ⊕ δ) / dδ  at δ = 0,   X ⊕ δ = X @ exp(δ),

so that ``f(X ⊕ δ) ≈ f(X) ⊕ J δ``. Points are perturbed additively. Every function
returns one Jacobian per argument, in argument order, with the arguments' batch axes
broadcast; shapes ``(*batch, out_dim, in_dim)``.

=================  ====================================  ==========================
operation          value                                 Jacobians (eq. in Solà)
=================  ====================================  ==========================
compose(a, b)      a @ b                                 Ad(b⁻¹), I        (173, 174)
inverse(a)         a⁻¹                                   −Ad(a)            (160)
apply(T, p)        T @ p                                 R K(p), R         (166, 181)
between(a, b)      a⁻¹ @ b                               −Ad(b⁻¹a), I
rminus(a, b)       log(a⁻¹ b) = b ⊖ a                    −J_l⁻¹(τ), J_r⁻¹(τ)  (176)
rplus(a, δ)        a @ exp(δ)                            Ad(exp(−δ)), J_r(δ)  (175)
exp(x)             exp(x)                                J_r(x)            (143)
log(a)             log(a)                                J_r⁻¹(log a)      (144)
=================  ====================================  ==========================

K(p) is the generators' action on the point: column i is the first ``space_dim`` entries
of ``hat(eᵢ) p̃`` (p̃ = (p, 1) for SE groups), e.g. [I, −p̂] for SE(3), −p̂ for SO(3).
"""

from __future__ import annotations

from typing import Tuple, TypeVar

import jax
import jax.numpy as jnp

from . import hints
from ._base import MatrixLieGroup, SEBase

GroupT = TypeVar("GroupT", bound=MatrixLieGroup)


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


def compose(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a @ b`` w.r.t. ``a`` and ``b``: ``(Ad(b⁻¹), I)``."""
    return _broadcast(b.inverse().adjoint(), _eye_like(a.multiply(b)))


def inverse(a: GroupT) -> jax.Array:
    """Jacobian of ``a⁻¹`` w.r.t. ``a``: ``−Ad(a)``."""
    return -a.adjoint()


def between(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a⁻¹ @ b`` w.r.t. ``a`` and ``b``: ``(−Ad(b⁻¹ a), I)``."""
    return _broadcast(-(b.inverse().multiply(a)).adjoint(), _eye_like(a.inverse().multiply(b)))


def rminus(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``τ = log(a⁻¹ @ b)`` (the pose-graph residual, ``manifold.rminus``)
    w.r.t. ``a`` and ``b``: ``(−J_l⁻¹(τ), J_r⁻¹(τ))``."""
    G = type(a)
    tau = a.inverse().multiply(b).log()
    return -G.jac_left_inv(tau), G.jac_right_inv(tau)


def rplus(a: GroupT, delta: hints.Array) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a @ exp(δ)`` w.r.t. ``a`` and ``δ``: ``(Ad(exp(−δ)), J_r(δ))``."""
    G = type(a)
    delta = G._check_tangent(delta, "rplus")
    J_a, J_d = _broadcast(G.exp(-delta).adjoint(), G.jac_right(delta))
    J_a, _ = _broadcast(J_a, _eye_like(a))  # the element's batch axes broadcast too
    return _broadcast(J_a, J_d)


def exp(G: type, tangent: hints.Array) -> jax.Array:
    """Jacobian of ``G.exp`` at ``tangent``: the right Jacobian ``J_r``."""
    return G.jac_right(tangent)


def log(a: MatrixLieGroup) -> jax.Array:
    """Jacobian of ``a.log()`` w.r.t. ``a``: ``J_r⁻¹(log a)`` (= ``a.jlog()``)."""
    return a.jlog()


def generator_action(G: type, points: hints.Array) -> jax.Array:
    """K(p): ``d (hat(δ) p̃)[:space_dim] / dδ``, shape ``(*batch, space_dim, tangent_dim)``."""
    n, k, d = G.matrix_dim, G.tangent_dim, G.space_dim
    p = jnp.asarray(points)
    E = G.hat(jnp.eye(k, dtype=p.dtype))  # (k, n, n): the generators, entries 0 and ±1
    if n > d:  # homogeneous coordinates
        p = jnp.concatenate([p, jnp.ones((*p.shape[:-1], 1), p.dtype)], axis=-1)
    return jnp.einsum("kij,...j->...ik", E[:, :d, :], p)


def apply(T: GroupT, points: hints.Array) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``T @ p`` w.r.t. ``T`` (right perturbation) and ``p``:
    ``(R K(p), R)`` with R the rotation matrix; shapes ``(*batch, space_dim, tangent_dim)``
    and ``(*batch, space_dim, space_dim)``."""
    p = T._check_points(points)
    R = T.rotation().as_matrix() if isinstance(T, SEBase) else T.as_matrix()
    R = R.astype(jnp.result_type(R, p))
    J_T = R @ generator_action(type(T), p.astype(R.dtype))
    batch = jnp.broadcast_shapes(R.shape[:-2], p.shape[:-1])
    return (
        jnp.broadcast_to(J_T, (*batch, *J_T.shape[-2:])),
        jnp.broadcast_to(R, (*batch, *R.shape[-2:])),
    )


__all__ = ["compose", "inverse", "apply", "between", "rminus", "rplus", "exp", "log", "generator_action"]
