"""Between factors, landmark observations and the anchor, as ``least_squares.Factor`` s
with closed-form Jacobians.

The residual of an edge (i, j) with measurement Z_ij is the right-minus

    r_ij = log(Z_ij⁻¹ T_i⁻¹ T_j),

zero when the measurement holds. With right perturbations T ⊕ δ = T exp(δ) its Jacobians
are closed form (Solà, Deray and Atchuthan, *A micro Lie theory for state estimation in
robotics*, 2018, §III, the compose and right-minus rows):

    ∂r/∂δ_j = J_r⁻¹(r),    ∂r/∂δ_i = −J_r⁻¹(r) Ad(T_j⁻¹ T_i).

Whitening by the upper-triangular square root W of the information (WᵀW = Ω) gives
e = W r and the blocks W ∂r/∂δ_i, W ∂r/∂δ_j. A robust kernel ρ turns the cost of an edge
into ½ ρ(‖e‖²); ``least_squares`` solves it in the iteratively reweighted form (Triggs,
McLauchlan, Hartley and Fitzgibbon, *Bundle adjustment — a modern synthesis*, 2000, §4.3,
without the second-order correction, as GTSAM does).

A landmark observation (i, m) of z, the position of landmark l (a point of ℝᵈ, d = 2 or
3) in the frame of pose T_i = (R, t), has the residual

    r = T_i⁻¹ l − z = Rᵀ(l − t) − z,

and, with T ⊕ δ = T exp(δ), δ = (v, ω), and l ⊕ ε = l + ε, the Jacobians (p = T_i⁻¹ l;
Solà, Deray and Atchuthan 2018, §III, the action row: T exp(δ) moves the point seen as p
by −v − ω × p)

    ∂r/∂v = −I,    ∂r/∂ω = [p]ₓ (SE3) or (p_y, −p_x)ᵀ (SE2),    ∂r/∂ε = Rᵀ,

whitened by the upper-triangular square root of the observation's information.

The anchor is a prior r_0 = log(P⁻¹ T_0) on the first pose, whitened by 1/σ, which fixes
the gauge (the graph's cost is invariant under T ↦ S T for any S).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple, Optional, Type, Union

import jax
import jax.numpy as jnp

from .. import least_squares
from .._se2 import SE2
from .._se3 import SE3
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

    @property
    def option(self) -> least_squares.Robust:
        """The kernel as ``least_squares.Factor``'s ``robust``."""
        return ("huber", float(self.threshold))

    def rho_and_weight(self, s: jax.Array) -> tuple[jax.Array, jax.Array]:
        """ρ(s) and ρ'(s) of the squared norm s = u²."""
        return least_squares._rho(self.option, s)


@dataclasses.dataclass(frozen=True)
class Cauchy:
    """Cauchy's (Lorentzian) kernel: ρ(s) = k² log(1 + s/k²) on the squared whitened norm
    s = ‖e‖², ρ'(s) = 1 / (1 + s/k²); the edge's cost is ½ρ."""

    threshold: float = 1.0

    def __post_init__(self) -> None:
        _check_threshold(self)

    @property
    def option(self) -> least_squares.Robust:
        """The kernel as ``least_squares.Factor``'s ``robust``."""
        return ("cauchy", float(self.threshold))

    def rho_and_weight(self, s: jax.Array) -> tuple[jax.Array, jax.Array]:
        """ρ(s) and ρ'(s) of the squared norm s."""
        return least_squares._rho(self.option, s)


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


class Observations(NamedTuple):
    """The device arrays of a graph's landmark observations (a pytree)."""

    pose: jax.Array  # (K,) int32
    landmark: jax.Array  # (K,) int32
    measurements: jax.Array  # (K, d)
    sqrt_information: jax.Array  # (K, d, d), upper triangular, WᵀW = Ω


def edge_residual(T_i: Any, T_j: Any, data: tuple[Any, jax.Array]) -> jax.Array:
    """e = W log(Z⁻¹ T_i⁻¹ T_j) of one edge, ``data = (Z, W)``."""
    Z, W = data
    return mv(W, Z._between(T_i._between(T_j)).log())


def edge_jacobian(T_i: Any, T_j: Any, data: tuple[Any, jax.Array]) -> tuple[jax.Array, jax.Array]:
    """e and W [∂r/∂δ_i, ∂r/∂δ_j] = W J_r⁻¹(r) [−Ad(T_j⁻¹ T_i), I], ``(k,)`` and ``(k, 2k)``."""
    Z, W = data
    E = Z._between(T_i._between(T_j))
    J_j = E.jlog()  # J_r⁻¹(r)
    J_i = -matmul(J_j, T_j._between(T_i).adjoint())
    return mv(W, E.log()), matmul(W, jnp.concatenate([J_i, J_j], axis=-1))


def observation_residual(T: Any, l: jax.Array, data: tuple[jax.Array, jax.Array]) -> jax.Array:
    """e = W (T⁻¹ l − z) of one observation, ``data = (z, W)``."""
    z, W = data
    return mv(W, T.inverse() @ l - z)


def observation_jacobian(
    T: Any, l: jax.Array, data: tuple[jax.Array, jax.Array]
) -> tuple[jax.Array, jax.Array]:
    """e and W [−I, ∂r/∂ω, Rᵀ], ``(d,)`` and ``(d, k + d)``."""
    z, W = data
    p = T.inverse() @ l
    if p.shape[-1] == 2:
        J_w = jnp.stack([p[1], -p[0]])[:, None]
    else:
        zero = jnp.zeros_like(p[0])
        J_w = jnp.stack(
            [
                jnp.stack([zero, -p[2], p[1]]),
                jnp.stack([p[2], zero, -p[0]]),
                jnp.stack([-p[1], p[0], zero]),
            ]
        )
    R_t = T.rotation().inverse().as_matrix()
    J = jnp.concatenate([-jnp.eye(p.shape[-1], dtype=p.dtype), J_w, R_t], axis=-1)
    return mv(W, p - z), matmul(W, J)


def anchor_residual(T_0: Any, data: tuple[Any, jax.Array]) -> jax.Array:
    """e_0 = log(P⁻¹ T_0)/σ, ``data = (P, 1/σ)``."""
    P, weight = data
    return P._between(T_0).log() * weight


def anchor_jacobian(T_0: Any, data: tuple[Any, jax.Array]) -> tuple[jax.Array, jax.Array]:
    """e_0 and J_r⁻¹(r_0)/σ."""
    P, weight = data
    E = P._between(T_0)
    return E.log() * weight, E.jlog() * weight


def factors(
    G: Type[Group],
    p: Problem,
    robust: Optional[RobustKernel],
    observations: Optional[Observations] = None,
) -> tuple[least_squares.Factor, ...]:
    """The edges as factors on (i, j) of variable set 0 (the poses), the anchor as one on
    pose 0, and the landmark observations (where given) on (i, m) of sets 0 and 1 (the
    landmarks, an array ``(M, d)``); the robust kernel on the edges and observations."""
    edges = least_squares.Factor(
        edge_residual,
        (0, 0),
        (p.edge_i, p.edge_j),
        (G(p.measurements), p.sqrt_information),
        None if robust is None else robust.option,
        jacobian=edge_jacobian,
    )
    anchor = least_squares.Factor(
        anchor_residual,
        (0,),
        (jnp.zeros((1,), p.edge_i.dtype),),
        (G(p.anchor[None]), p.anchor_weight[None]),
        jacobian=anchor_jacobian,
    )
    if observations is None:
        return edges, anchor
    seen = least_squares.Factor(
        observation_residual,
        (0, 1),
        (observations.pose, observations.landmark),
        (observations.measurements, observations.sqrt_information),
        None if robust is None else robust.option,
        jacobian=observation_jacobian,
    )
    return edges, anchor, seen


def mv(A: jax.Array, x: jax.Array) -> jax.Array:
    """A x for ``(..., m, n)`` and ``(..., n)``, at full precision."""
    return matmul(A, x[..., None])[..., 0]
