"""Between factors and the anchor, linearised in one batched, jit-compiled call.

The residual of an edge (i, j) with measurement Z_ij is the right-minus

    r_ij = log(Z_ij⁻¹ T_i⁻¹ T_j),

zero when the measurement holds. With right perturbations T ⊕ δ = T exp(δ) its Jacobians
are closed form (Solà, Deray and Atchuthan, *A micro Lie theory for state estimation in
robotics*, 2018, §III, the compose and right-minus rows):

    ∂r/∂δ_j = J_r⁻¹(r),    ∂r/∂δ_i = −J_r⁻¹(r) Ad(T_j⁻¹ T_i).

Whitening by the upper-triangular square root W of the information (WᵀW = Ω) gives
e = W r and the blocks A_i = W ∂r/∂δ_i, A_j = W ∂r/∂δ_j. A robust kernel ρ turns the
cost of an edge into ½ ρ(‖e‖²); Gauss–Newton on it uses the iteratively reweighted form
(Triggs, McLauchlan, Hartley and Fitzgibbon, *Bundle adjustment — a modern synthesis*,
2000, §4.3, without the second-order correction, as GTSAM does): e and the blocks scaled
by √ρ'(‖e‖²).

The anchor is a prior r_0 = log(P⁻¹ T_0) on the first pose, whitened by 1/σ, which fixes
the gauge (the graph's cost is invariant under T ↦ S T for any S).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple, Optional, Type, Union

import jax
import jax.numpy as jnp

from .. import manifold
from .._se2 import SE2
from .._se3 import SE3
from .._sparse import Factors
from .._xla import matmul

Group = Union[SE2, SE3]


@dataclasses.dataclass(frozen=True)
class Huber:
    """Huber's kernel on the whitened residual norm u = ‖e‖ (Huber, *Robust estimation of
    a location parameter*, 1964): ρ = u² for u ≤ k, 2ku − k² beyond; the edge's cost is
    ½ρ. GTSAM's default threshold is k = 1.345."""

    threshold: float = 1.345

    def __post_init__(self) -> None:
        _check_threshold(self)

    def rho_and_weight(self, s: jax.Array) -> tuple[jax.Array, jax.Array]:
        """ρ(s) and ρ'(s) of the squared norm s = u²."""
        k = jnp.asarray(self.threshold, s.dtype)
        u = jnp.sqrt(s)
        inside = u <= k
        rho = jnp.where(inside, s, 2.0 * k * u - k * k)
        weight = jnp.where(inside, 1.0, k / jnp.where(inside, 1.0, u))
        return rho, weight


@dataclasses.dataclass(frozen=True)
class Cauchy:
    """Cauchy's (Lorentzian) kernel: ρ(s) = k² log(1 + s/k²) on the squared whitened norm
    s = ‖e‖², ρ'(s) = 1 / (1 + s/k²); the edge's cost is ½ρ."""

    threshold: float = 1.0

    def __post_init__(self) -> None:
        _check_threshold(self)

    def rho_and_weight(self, s: jax.Array) -> tuple[jax.Array, jax.Array]:
        k2 = jnp.asarray(self.threshold, s.dtype) ** 2
        return k2 * jnp.log1p(s / k2), 1.0 / (1.0 + s / k2)


RobustKernel = Union[Huber, Cauchy]


def _check_threshold(kernel: RobustKernel) -> None:
    t = kernel.threshold
    if not (isinstance(t, (int, float)) and t > 0 and t < float("inf")):
        raise ValueError(f"{type(kernel).__name__}: threshold must be a positive number, got {t!r}")


class Problem(NamedTuple):
    """The device arrays of a graph (a pytree). E may include padding edges of zero
    weight so that it divides into the devices' shards."""

    edge_i: jax.Array  # (E,) int32
    edge_j: jax.Array  # (E,) int32
    measurements: jax.Array  # (E, P) group parameters
    sqrt_information: jax.Array  # (E, k, k), upper triangular, WᵀW = Ω
    anchor: jax.Array  # (P,) the prior's mean for pose 0
    anchor_weight: jax.Array  # () 1/σ


def tr(A: jax.Array) -> jax.Array:
    """Aᵀ over the last two axes."""
    return jnp.swapaxes(A, -1, -2)


def mv(A: jax.Array, x: jax.Array) -> jax.Array:
    """A x for stacks ``(..., m, n)`` and ``(..., n)``, at full precision."""
    return matmul(A, x[..., None])[..., 0]


def _edges(G: Type[Group], poses: jax.Array, p: Problem) -> tuple[Any, Any, Any]:
    T: Any = G(poses)
    return T[p.edge_i], T[p.edge_j], G(p.measurements)


def _costs(e: jax.Array, robust: Optional[RobustKernel]) -> tuple[jax.Array, jax.Array]:
    s = jnp.sum(e * e, axis=-1)
    if robust is None:
        return 0.5 * s, jnp.ones_like(s)
    rho, weight = robust.rho_and_weight(s)
    return 0.5 * rho, weight


def cost(G: Type[Group], poses: jax.Array, p: Problem, robust: Optional[RobustKernel]) -> jax.Array:
    """½ Σ ρ(‖W r_ij‖²) + ½ ‖r_0/σ‖², a scalar."""
    T_i, T_j, Z = _edges(G, poses, p)
    r = Z._between(T_i._between(T_j)).log()
    edge_costs, _ = _costs(mv(p.sqrt_information, r), robust)
    anchor: Any = G(p.anchor)
    r_0 = anchor._between(G(poses[0])).log() * p.anchor_weight
    return jnp.sum(edge_costs) + 0.5 * jnp.sum(r_0 * r_0)


def linearise(
    G: Type[Group], poses: jax.Array, p: Problem, robust: Optional[RobustKernel]
) -> tuple[jax.Array, tuple[Factors, Factors]]:
    """The cost, and the whitened (and reweighted) residuals and Jacobian blocks: the edges
    as factors on (i, j), the anchor as one on pose 0."""
    T_i, T_j, Z = _edges(G, poses, p)
    E = Z._between(T_i._between(T_j))
    r = E.log()
    J_j = E.jlog()  # J_r⁻¹(r)
    J_i = -matmul(J_j, T_j._between(T_i).adjoint())
    W = p.sqrt_information
    e = mv(W, r)
    edge_costs, weight = _costs(e, robust)
    scale = jnp.sqrt(weight)[:, None]
    A = matmul(W[:, None], jnp.stack([J_i, J_j], axis=1)) * scale[..., None, None]
    anchor: Any = G(p.anchor)
    E_0 = anchor._between(G(poses[0]))
    e_0 = E_0.log() * p.anchor_weight
    A_0 = E_0.jlog() * p.anchor_weight
    total = jnp.sum(edge_costs) + 0.5 * jnp.sum(e_0 * e_0)
    edges = Factors(jnp.stack([p.edge_i, p.edge_j], axis=-1), e * scale, A)
    first = Factors(jnp.zeros((1, 1), p.edge_i.dtype), e_0[None], A_0[None, None])
    return total, (edges, first)


def retract(G: Type[Group], poses: jax.Array, delta: jax.Array) -> jax.Array:
    """T_n ⊕ δ_n = T_n exp(δ_n) for every pose: parameters ``(N, P)``."""
    return manifold.rplus(G(poses), delta).parameters()
