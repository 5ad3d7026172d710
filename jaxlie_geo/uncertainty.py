"""Uncertain poses: covariances in the right tangent space, first-order propagation,
sampling, and the mean of a set of poses.

Convention: an uncertain element is ``T̄ @ exp(δ)``, ``δ ~ N(0, Σ)``, with Σ of shape
``(*batch, k, k)`` in the tangent's own order — ``(v, ω)`` for SE(3), ``(vx, vy, θ)`` for
SE(2). GTSAM orders SE(3) covariances ``(ω, v)``: permute blocks when exchanging them.
Propagation is first order through the Jacobians of ``jaxlie_geo.jacobians``
(Barfoot and Furgale, *Associating uncertainty with three-dimensional poses for use in
estimation problems*, 2014, §III; Solà et al. 2018, §IV-C). Barfoot and Furgale perturb on
the left, ``exp(δ) @ T̄``; their covariances map to these by δ_left = Ad(T̄) δ_right.
"""

from __future__ import annotations

from typing import Any, Optional, Tuple

import jax
import jax.numpy as jnp

from . import hints, jacobians
from ._base import GroupT, MatrixLieGroup
from ._checks import as_float_array, check_batches, resolve_dtype
from ._jit import jit_function
from ._xla import matmul


def _sandwich(J: jax.Array, cov: jax.Array) -> jax.Array:
    return matmul(matmul(J, cov), jnp.swapaxes(J, -1, -2))


def _check_cov(T: MatrixLieGroup, cov: hints.Array, name: str, where: str) -> jax.Array:
    """``cov`` as a float array of shape ``(*batch, k, k)``, integers promoted to ``T``'s
    dtype."""
    k = T.tangent_dim
    return as_float_array(cov, name, (k, k), where, like=T.parameters())


def _check_broadcast(where: str, *items: Any) -> Tuple[int, ...]:
    """The broadcast of the elements' batch axes and the matrices' leading axes (``None``
    items skipped), else a ``ValueError`` naming ``where`` (not matmul's "Incompatible
    types")."""
    shapes = [
        x.get_batch_axes() if isinstance(x, MatrixLieGroup) else x.shape[:-2]
        for x in items
        if x is not None
    ]
    return check_batches(where, "batch axes of the elements and covariances", *shapes)


@jit_function()
def propagate_compose(
    a: GroupT,
    cov_a: hints.Array,
    b: GroupT,
    cov_b: hints.Array,
    cov_ab: Optional[hints.Array] = None,
) -> jax.Array:
    """Covariance of ``a @ b``, to first order:
    ``J_a Σ_a J_aᵀ + J_b Σ_b J_bᵀ + J_a Σ_ab J_bᵀ + (J_a Σ_ab J_bᵀ)ᵀ`` with
    ``J_a = Ad(b⁻¹)``, ``J_b = I`` (``jacobians.compose``).

    Args:
        a: element of any group.
        cov_a: Σ_a, ``(*batch, k, k)``, the covariance of ``a``'s right perturbation.
        b: element of the same group.
        cov_b: Σ_b, ``(*batch, k, k)``.
        cov_ab: Σ_ab = E[δ_a δ_bᵀ], ``(*batch, k, k)``, for correlated operands (default:
            independent). All batch axes broadcast with the elements'.

    Returns:
        ``(*batch, k, k)``: the covariance of the right perturbation of ``a @ b``.
    """
    cov_a = _check_cov(a, cov_a, "cov_a", "propagate_compose")
    cov_b = _check_cov(b, cov_b, "cov_b", "propagate_compose")
    if cov_ab is not None:
        cov_ab = _check_cov(a, cov_ab, "cov_ab", "propagate_compose")
    _check_broadcast("propagate_compose", a, b, cov_a, cov_b, cov_ab)
    J_a, J_b = jacobians.compose(a, b)
    out = _sandwich(J_a, cov_a) + _sandwich(J_b, cov_b)
    if cov_ab is not None:
        cross = matmul(matmul(J_a, cov_ab), jnp.swapaxes(J_b, -1, -2))
        out = out + cross + jnp.swapaxes(cross, -1, -2)
    return out


@jit_function()
def propagate_inverse(a: GroupT, cov_a: hints.Array) -> jax.Array:
    """Covariance of ``a⁻¹``, to first order: ``Ad(a) Σ Ad(a)ᵀ``.

    Args:
        a: element of any group.
        cov_a: Σ, ``(*batch, k, k)``, batch axes broadcasting with ``a``'s.

    Returns:
        ``(*batch, k, k)``.
    """
    cov_a = _check_cov(a, cov_a, "cov_a", "propagate_inverse")
    _check_broadcast("propagate_inverse", a, cov_a)
    return _sandwich(jacobians.inverse(a), cov_a)


@jit_function()
def propagate_apply(
    T: GroupT, cov_T: hints.Array, points: hints.Array, cov_points: Optional[hints.Array] = None
) -> jax.Array:
    """Covariance of the point ``T @ p``, to first order: ``J_T Σ_T J_Tᵀ + R Σ_p Rᵀ`` with
    ``(J_T, R) = jacobians.apply(T, p)``.

    Args:
        T: element of any group.
        cov_T: Σ_T, ``(*batch, k, k)``, the covariance of ``T``'s right perturbation.
        points: ``(*batch, space_dim)``.
        cov_points: Σ_p, ``(*batch, space_dim, space_dim)``, the points' own (additive)
            covariance (default: exact points). All batch axes broadcast.

    Returns:
        ``(*batch, space_dim, space_dim)``: the additive covariance of the transformed
        points.
    """
    cov_T = _check_cov(T, cov_T, "cov_T", "propagate_apply")
    if cov_points is not None:
        d = T.space_dim
        cov_points = as_float_array(
            cov_points, "cov_points", (d, d), "propagate_apply", like=T.parameters()
        )
    J_T, J_p = jacobians._apply(T, points, "propagate_apply")
    _check_broadcast("propagate_apply", J_T, cov_T, cov_points)
    out = _sandwich(J_T, cov_T)
    if cov_points is not None:
        out = out + _sandwich(J_p, cov_points)
    return out


def sample(
    key: jax.Array,
    mean: GroupT,
    cov: hints.Array,
    batch_axes: Tuple[int, ...] = (),
) -> GroupT:
    """Draw ``mean @ exp(L z)``, ``z ~ N(0, I)``, ``L Lᵀ = Σ`` (Cholesky).

    Args:
        key: PRNG key.
        mean: element, batch axes ``batch``.
        cov: Σ, ``(*batch', k, k)``, symmetric positive definite (otherwise the factor, and
            so the samples, are NaN).
        batch_axes: leading axes of independent draws.

    Returns:
        Elements of batch shape ``(*batch_axes, *broadcast(batch, batch'))``.
    """
    return _sample(key, mean, cov, tuple(batch_axes))


@jit_function("batch_axes")
def _sample(
    key: jax.Array,
    mean: GroupT,
    cov: hints.Array,
    batch_axes: Tuple[int, ...] = (),
) -> GroupT:
    cov = _check_cov(mean, cov, "cov", "sample")
    G = type(mean)
    dtype = jnp.result_type(mean.parameters(), cov)
    batch = _check_broadcast("sample", mean, cov)
    # XLA has no half-precision Cholesky: factor in float32
    L = jnp.linalg.cholesky(cov.astype(jnp.promote_types(dtype, jnp.float32))).astype(dtype)
    z = jax.random.normal(key, (*batch_axes, *batch, G.tangent_dim), dtype=resolve_dtype(dtype))
    return mean.multiply(G.exp(matmul(L, z[..., None])[..., 0]))


def _mean_residual(mu: MatrixLieGroup, poses: MatrixLieGroup, w: jax.Array) -> jax.Array:
    """Σ wᵢ log(μ⁻¹ xᵢ) over the first batch axis of ``poses``: the update of ``mean``'s
    iteration, zero at the mean. ``w`` has shape ``(N,)``, ``μ`` batch ``rest``."""
    r = mu[None]._between(poses).log()  # (N, *rest, k)
    w = w.reshape(w.shape + (1,) * (r.ndim - 1))
    return jnp.sum(w * r, axis=0)


@jax.custom_jvp
def _mean_offset(base: MatrixLieGroup, poses: MatrixLieGroup, w: jax.Array) -> jax.Array:
    """δ*(poses, w), the root of δ ↦ _mean_residual(base ⊕ δ, poses, w), given that
    ``base`` is the root (δ* = 0 in value). Its derivatives are the implicit function
    theorem's, δ̇* = −(∂F/∂δ)⁻¹ ∂F/∂(poses, w)·(ẋ, ẇ) at δ*, to every order: the rule calls
    this function again. ``base`` is held constant (its tangent is ignored)."""
    return jnp.zeros((*base.get_batch_axes(), base.tangent_dim), w.dtype)


@_mean_offset.defjvp
def _mean_offset_jvp(primals: Any, tangents: Any) -> Tuple[jax.Array, jax.Array]:
    base, poses, w = primals
    _, poses_dot, w_dot = tangents
    G = type(base)
    delta = _mean_offset(base, poses, w)
    mu = base.multiply(G.exp(delta))
    # ∂F/∂(poses, w) along the tangents, at δ*
    rhs = jax.jvp(lambda x, ww: _mean_residual(mu, x, ww), (poses, w), (poses_dot, w_dot))[1]
    # ∂F/∂δ in closed form: exp(−δ − ε) = exp(−J_r(δ) ε) exp(−δ) to first order, and
    # log(exp(−η) Z) = log Z − J_l⁻¹(log Z) η, so ∂F/∂δ = −Σ wᵢ J_l⁻¹(sᵢ) J_r(δ) with
    # sᵢ = log(μ⁻¹ xᵢ), μ = base ⊕ δ (first-order BCH, as in Solà et al. 2018). At the
    # root, J_r⁻¹ in place of J_l⁻¹ gives the same matrix: they differ by ad(sᵢ), and
    # Σ wᵢ ad(sᵢ) = ad(F) = 0.
    s = mu[None]._between(poses).log()
    wj = w.reshape(w.shape + (1,) * s.ndim)
    A = -matmul(jnp.sum(wj * G.jac_left_inv(s), axis=0), G.jac_right(delta))
    return delta, -jnp.linalg.solve(A, rhs[..., None])[..., 0]


@jax.custom_jvp
def _retract_zero(base: GroupT, delta: jax.Array) -> GroupT:
    """``base ⊕ delta`` for a ``delta`` that is zero in value: ``base`` itself, with the
    derivatives of ``base @ exp(delta)``."""
    return base


@_retract_zero.defjvp
def _retract_zero_jvp(primals: Any, tangents: Any) -> Tuple[Any, Any]:
    return jax.jvp(lambda b, d: b.multiply(type(b).exp(d)), primals, tangents)


@jit_function("tol", "max_iters")
def mean(
    poses: GroupT,
    weights: Optional[hints.Array] = None,
    *,
    init: Optional[GroupT] = None,
    tol: Optional[float] = None,
    max_iters: int = 50,
) -> GroupT:
    """Weighted mean of a batch of elements along their first batch axis, by the fixed-point
    iteration ``μ ← μ @ exp(Σ wᵢ log(μ⁻¹ xᵢ))`` (the right-invariant-residual mean, well
    defined on SE(3), which has no bi-invariant metric).

    Args:
        poses: elements with batch ``(N, *rest)``; the mean is taken over the N axis.
        weights: shape ``(N,)``, normalised to sum 1 (default: uniform); their sum must not
            be zero (it gives NaN). Negative weights give the affine combination.
        init: starting point, batch broadcasting to ``rest``, cast to the poses' dtype
            (default: ``poses[0]``).
        tol: stop once every element's update is below it, largest component (default:
            10·eps of the dtype); a positive Python number. Elements whose update is NaN
            (NaN among their poses) do not hold the others back; their mean is NaN.
        max_iters: cap on the iterations (jit-able ``lax.while_loop``).
    Returns:
        The mean, batch ``rest``. Meaningful when the poses lie within a ball where
        ``log`` is unique (rotations less than π apart).

    Derivatives with respect to ``poses`` and ``weights`` (``jax.grad``, ``jacfwd``,
    ``jacrev``, ``hessian``) are those of the exact mean, by the implicit function theorem
    at the returned point, not the derivative of the iterations: with F(μ) = Σ wᵢ
    log(μ⁻¹ xᵢ) = 0, ``μ̇ = μ ⊕ δ̇``, ``δ̇ = −(∂F/∂δ)⁻¹ ∂F/∂(x, w)·(ẋ, ẇ)``, ∂F/∂δ =
    −Σ wᵢ J_l⁻¹(log(μ⁻¹ xᵢ)) in closed form, one k×k solve per mean. They cost one
    linearisation of F, not of the loop, and are exact only as far as the iteration
    converged (not after ``max_iters`` stopped it early). ``init``, ``tol`` and
    ``max_iters`` get no derivative.
    """
    G = type(poses)
    n = poses.get_batch_axes()[0] if poses.get_batch_axes() else None
    if n is None:
        raise ValueError("mean: `poses` must have at least one batch axis (the one averaged).")
    if n == 0:
        raise ValueError("mean: `poses` is empty along its first batch axis.")
    dtype = poses.parameters().dtype
    if weights is None:
        w = jnp.full((n,), 1.0 / n, dtype)
    else:
        w = as_float_array(weights, "weights", (), "mean").astype(dtype)
        if w.shape != (n,):
            raise ValueError(f"mean: `weights` must have shape ({n},), got {w.shape}.")
        w = w / jnp.sum(w)
    tol_ = float(10 * jnp.finfo(dtype).eps) if tol is None else float(tol)
    if not tol_ > 0 or tol_ == float("inf"):
        raise ValueError(f"mean: `tol` must be a positive finite number, got {tol}.")
    if init is None:
        mu0 = poses[0]
    else:
        rest = poses.get_batch_axes()[1:]
        both = check_batches(
            "mean", "batch axes of `init` and of the poses' rest", init.get_batch_axes(), rest
        )
        if tuple(both) != tuple(rest):
            raise ValueError(
                f"mean: `init` batch axes {init.get_batch_axes()} must broadcast to the poses' "
                f"rest {rest}."
            )
        mu0 = G(jnp.broadcast_to(init.parameters().astype(dtype), (*rest, G.parameters_dim)))
    # The loop is not differentiated (see the end): its inputs carry no tangents.
    fixed_poses, fixed_w = jax.lax.stop_gradient((poses, w))

    def step(mu: GroupT) -> Tuple[GroupT, jax.Array]:
        delta = _mean_residual(mu, fixed_poses, fixed_w)
        # NaN updates are left out of the stopping test (a NaN compares false, and one
        # element's NaN would otherwise stop every other element after one step).
        size = jnp.where(jnp.isnan(delta), 0.0, jnp.abs(delta))
        return mu.multiply(G.exp(delta)), jnp.max(size)

    def cond(state: Tuple[Any, jax.Array, jax.Array]) -> jax.Array:
        _, size, i = state
        return (size > tol_) & (i < max_iters)

    def body(state: Tuple[Any, jax.Array, jax.Array]) -> Tuple[Any, jax.Array, jax.Array]:
        mu, _, i = state
        mu, size = step(mu)
        return mu, size, i + 1

    mu, _, _ = jax.lax.while_loop(
        cond, body, (jax.lax.stop_gradient(mu0), jnp.asarray(jnp.inf, dtype), jnp.asarray(0))
    )
    # Derivatives by the implicit function theorem, not through the loop: near the root
    # the mean is μ ⊕ δ*(poses, w), μ the loop's result held constant and δ* the root of
    # δ ↦ Σ wᵢ log((μ ⊕ δ)⁻¹ xᵢ). δ* is 0 in value, so the value is the loop's, bit for bit.
    return _retract_zero(mu, _mean_offset(mu, poses, w))


__all__ = ["propagate_compose", "propagate_inverse", "propagate_apply", "sample", "mean"]
