"""Jacobians of the group operations with respect to right perturbations.

Convention (Solà, Deray, Atchuthan, *A micro Lie theory for state estimation in
robotics*, 2018, §III–IV): for f: G → H,

    J = d f(X)⁻¹ f(X ⊕ δ) / dδ  at δ = 0,   X ⊕ δ = X @ exp(δ),

so that ``f(X ⊕ δ) ≈ f(X) ⊕ J δ``. Points are perturbed additively. A function of two
arguments returns a tuple of two Jacobians, in argument order; one of a single element or
tangent (``inverse``, ``exp``, ``log``, ``generator_action``) returns one array. The
arguments' batch axes broadcast; shapes ``(*batch, out_dim, in_dim)``, k = ``tangent_dim``.

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

from typing import Sequence, Tuple, Type, TypeVar

import jax
import jax.numpy as jnp
import numpy as onp

from . import hints
from ._base import MatrixLieGroup, SEBase, aligned, as_float_array, check_batches, constant, jit_function
from ._so2 import SO2

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


@jit_function()
def compose(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a @ b`` w.r.t. ``a`` and ``b``: ``(Ad(b⁻¹), I)``, each
    ``(*batch, k, k)``, batch the broadcast of ``a``'s and ``b``'s."""
    return _broadcast(b.inverse().adjoint(), _eye_like(a.multiply(b)))


@jit_function()
def inverse(a: GroupT) -> jax.Array:
    """Jacobian of ``a⁻¹`` w.r.t. ``a``: ``−Ad(a)``, ``(*batch, k, k)``."""
    return -a.adjoint()


@jit_function()
def between(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a⁻¹ @ b`` w.r.t. ``a`` and ``b``: ``(−Ad(b⁻¹ a), I)``, each
    ``(*batch, k, k)``, batch the broadcast of ``a``'s and ``b``'s."""
    return _broadcast(-b._between(a).adjoint(), _eye_like(a._between(b)))


@jit_function()
def rminus(a: GroupT, b: GroupT) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``τ = log(a⁻¹ @ b)`` (the pose-graph residual, ``manifold.rminus``)
    w.r.t. ``a`` and ``b``: ``(−J_l⁻¹(τ), J_r⁻¹(τ))``, each ``(*batch, k, k)``. SO3 at
    10^5 (float32, 2 cores): 42–50 ns/element through ``jac_left_inv``/``jac_right_inv``,
    17–22 through ``jlog`` and J_l⁻¹ = J_r⁻¹ᵀ."""
    G = type(a)
    e = a._between(b)
    J_r_inv = e.jlog()  # the log is principal: the groups' faster jlog applies
    if not isinstance(e, SEBase):  # rotation groups: J_l(τ) = J_r(τ)ᵀ
        return -jnp.swapaxes(J_r_inv, -1, -2), J_r_inv
    return -G.jac_left_inv(e.log()), J_r_inv


@jit_function()
def rplus(a: GroupT, delta: hints.Array) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``a @ exp(δ)`` w.r.t. ``a`` and ``δ`` (``(*batch, k)``):
    ``(Ad(exp(−δ)), J_r(δ))``, each ``(*batch, k, k)``, batch the broadcast of both."""
    G = type(a)
    delta = G._check_tangent(delta, "jacobians.rplus", like=a.parameters(), name="delta")
    check_batches("jacobians.rplus", "batch axes of the element and `delta`",
                  a.get_batch_axes(), delta.shape[:-1])
    J_a, J_d = _broadcast(G.exp(-delta).adjoint(), G.jac_right(delta))
    J_a, _ = _broadcast(J_a, _eye_like(a))  # the element's batch axes broadcast too
    return _broadcast(J_a, J_d)


@jit_function("G")
def exp(G: Type[MatrixLieGroup], tangent: hints.Array) -> jax.Array:
    """Jacobian of ``G.exp`` at ``tangent`` (``(*batch, k)``): the right Jacobian ``J_r``,
    ``(*batch, k, k)``."""
    return G.jac_right(tangent)


@jit_function()
def log(a: MatrixLieGroup) -> jax.Array:
    """Jacobian of ``a.log()`` w.r.t. ``a``: ``J_r⁻¹(log a)`` (= ``a.jlog()``),
    ``(*batch, k, k)``."""
    return a.jlog()


def _generators(G: Type[MatrixLieGroup]) -> onp.ndarray:
    """The generators hat(eᵢ) as a NumPy constant ``(k, n, n)`` (entries 0 and ±1)."""
    with jax.ensure_compile_time_eval():
        return onp.asarray(G.hat(onp.eye(G.tangent_dim)))


def _combine(coeffs: onp.ndarray, xs: Sequence[jax.Array]) -> jax.Array:
    """Σ_l coeffs[l] · xs[l] for a constant coefficient vector, skipping zeros."""
    terms = [c * x for c, x in zip(coeffs.tolist(), xs) if c != 0.0]
    if not terms:
        return jnp.zeros_like(xs[0])
    out = terms[0]
    for t in terms[1:]:
        out = out + t
    return out


def _matmul(A: jax.Array, B: jax.Array) -> jax.Array:
    """(..., m, n) @ (..., n, k) for small m, n, k, written out elementwise: a batched
    3×3 ``dot`` on XLA:CPU costs several times the fused multiply-adds."""
    n = A.shape[-1]
    rows = []
    for i in range(A.shape[-2]):
        row = []
        for j in range(B.shape[-1]):
            acc = A[..., i, 0] * B[..., 0, j]
            for m in range(1, n):
                acc = acc + A[..., i, m] * B[..., m, j]
            row.append(acc)
        rows.append(jnp.stack(row, axis=-1))
    return jnp.stack(rows, axis=-2)


@jit_function("G")
def generator_action(G: Type[MatrixLieGroup], points: hints.Array) -> jax.Array:
    """K(p): ``d (hat(δ) p̃)[:space_dim] / dδ``, shape ``(*batch, space_dim, tangent_dim)``
    (p̃ = (p, 1) for SE groups): e.g. ``[I, −p̂]`` for SE(3), ``−p̂`` for SO(3). Entry (i, j)
    is Σ_l hat(e_j)[i, l] p̃_l, written out from the constant generators."""
    n, d = G.matrix_dim, G.space_dim
    p = as_float_array(points, "points", (d,), "jacobians.generator_action")
    coords = [p[..., l] for l in range(d)]
    if n > d:  # homogeneous coordinates
        coords.append(jnp.ones_like(coords[0]))
    E = _generators(G)
    return jnp.stack(
        [jnp.stack([_combine(E[j, i], coords) for j in range(G.tangent_dim)], -1) for i in range(d)],
        axis=-2,
    )


_E0, _E1 = onp.array([[1.0], [0.0]]), onp.array([[0.0], [1.0]])
"""The columns e₀, e₁ as ``(2, 1)`` constants (SO(2)'s ``apply`` Jacobian)."""


@jit_function()
def apply(T: GroupT, points: hints.Array) -> Tuple[jax.Array, jax.Array]:
    """Jacobians of ``T @ p`` w.r.t. ``T`` (right perturbation) and ``p``:
    ``(R K(p), R)`` with R the rotation matrix; shapes ``(*batch, space_dim, tangent_dim)``
    and ``(*batch, space_dim, space_dim)``."""
    return _apply(T, points, "jacobians.apply")


def _apply(T: GroupT, points: hints.Array, where: str) -> Tuple[jax.Array, jax.Array]:
    """``apply``'s body; errors about ``points`` name ``where``."""
    T, p = aligned(T, T._check_points(points, where, "points"))
    R = T.rotation()._matrix_block() if isinstance(T, SEBase) else T.as_matrix()
    R = R.astype(jnp.result_type(R, p))
    batch = jnp.broadcast_shapes(R.shape[:-2], p.shape[:-1])
    R = jnp.broadcast_to(R, (*batch, *R.shape[-2:]))
    if isinstance(T, SO2):
        # R K(p) = R J p = J R p (plane rotations commute with J = hat(1)): one rotation of
        # p, read from (c, s), not from R, and written as a·e₀ + b·e₁ (scalars broadcast
        # onto constant columns) rather than a stack, which XLA:CPU writes more slowly.
        # benchmarks/jacobians.py, 10^5 elements, float32, 2-core VM, ratio to jacfwd: a
        # stack from R 0.90, from (c, s) 1.05–1.18, this form 1.55–2.06 with R stacked and
        # 1.99–3.04 with SO2.as_matrix's select (RESULTS.md).
        c, s = T.unit_complex[..., 0, None, None], T.unit_complex[..., 1, None, None]
        pp = p.astype(R.dtype)
        x, y = pp[..., 0, None, None], pp[..., 1, None, None]
        col = -(s * x + c * y) * constant(_E0, x) + (c * x - s * y) * constant(_E1, x)
        return jnp.broadcast_to(col, (*batch, 2, 1)), R
    K = generator_action(type(T), jnp.broadcast_to(p.astype(R.dtype), (*batch, p.shape[-1])))
    return _matmul(R, K), R


__all__ = ["compose", "inverse", "apply", "between", "rminus", "rplus", "exp", "log", "generator_action"]
