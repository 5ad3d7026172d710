"""Pose-graph optimisation in SE(2) and SE(3) with closed-form Jacobians.

A robot drives around and keeps two kinds of relative measurements between its poses
T_world_body[k] (the body frame at time k, expressed in the world frame):

- odometry, between consecutive poses k and k + 1, and
- loop closures, between poses far apart in time that see the same place.

Each measurement is a relative pose Z_ij ≈ T_world_bi⁻¹ T_world_bj = T_bi_bj, corrupted
by noise in the tangent space: Z_ij = T_bi_bj exp(n), n ~ N(0, Σ). Chaining the odometry
alone gives a trajectory that drifts; pose-graph optimisation finds the poses that agree
best with *all* measurements, the minimiser of

    F(T) = ½ Σ_edges ‖W r_ij‖²,   r_ij = log(Z_ij⁻¹ T_world_bi⁻¹ T_world_bj),   WᵀW = Σ⁻¹.

r_ij is the right-minus T_world_bj ⊖ (T_world_bi Z_ij): the error of the pose of j
predicted from i through the measurement, expressed in the predicted body frame. It is
``manifold.rminus(T_world_bi @ Z_ij, T_world_bj)``.

Gauss-Newton on a Lie group (right perturbations T ⊕ δ = T exp(δ), as in the whole
library) linearises every residual around the current estimate,

    r_ij(T_i ⊕ δ_i, T_j ⊕ δ_j) ≈ r_ij + J_i δ_i + J_j δ_j,

assembles the normal equations H δ = −g with H = Σ Jᵀ Wᵀ W J and g = Σ Jᵀ Wᵀ W r (one
dense (N·k) × (N·k) matrix, k = tangent dimension, scatter-added block by block in one
jitted call), solves them, and retracts T_i ← T_i ⊕ δ_i. Levenberg–Marquardt adds
λ·diag(H) to H and only accepts steps that lower F, so the printed cost never goes up.

The Jacobians are closed form (derived in ``edge_residual_and_jacobians``), from
``jaxlie_geo.jacobians``:

    J_j = J_r⁻¹(r),   J_i = −J_l⁻¹(r) Ad(Z_ij⁻¹)  (= −J_r⁻¹(r) Ad(T_world_bj⁻¹ T_world_bi)),

and the script checks them against ``jax.jacfwd`` through a right perturbation.

The data are synthetic and generated here: in 2D a "Manhattan" walk on a street grid
(one metre per step, random turns at crossings; loop closures to some of the older poses
within a metre), in 3D a sphere (the robot spirals up a sphere; a loop closure to the
pose one turn below). The first pose is known (the gauge): its block is removed from the
normal equations, and every error is measured against ground truth directly. At the
optimum, 2F should be a χ² sample with (E − N + 1)·k degrees of freedom (E edges, N
poses): the script prints that expectation next to the final cost.

Run: ``python examples/pose_graph.py [--quick] [--method lm|gn] [--out out/pose_graph.png]``;
prints the Jacobian check, the cost at every iteration and the errors before and after,
and draws the trajectories (ground truth, odometry, optimised) and the cost curves.

With ``--file FILE`` the script instead optimises a pose graph read from a g2o or TORO file
(2D or 3D; e.g. the public datasets w10000 and sphere2500) with the library's sparse
solver, ``jaxlie_geo.pose_graph``:

    python examples/pose_graph.py --file w10000.graph [--method lm|gn]
        [--linear-solver auto|cholesky|pcg] [--max-iterations 100]
        [--information-order g2o|toro] [--out out/pose_graph_w10000.png] [--write out.g2o]

It prints the size of the graph, the cost before, a progress line per iteration (on
stderr), the cost after, the iterations, the time and why the solver stopped, and draws
the graph before and after optimisation (edges between consecutive poses as the trajectory,
the others as thin lines) beside the cost per iteration.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import time
from pathlib import Path
from typing import Any, Dict, List, Tuple

import jax

jax.config.update("jax_enable_x64", True)  # Gauss-Newton on ~10³ poses: float64 is cheap

import jax.numpy as jnp  # noqa: E402
import jax.scipy.linalg as jsl  # noqa: E402
import numpy as onp  # noqa: E402

from jaxlie_geo import SE2, SE3, SO3, jacobians, manifold, pose_graph  # noqa: E402

# ---------------------------------------------------------------------------------------
# 1. The pose graph


@dataclasses.dataclass(frozen=True)
class PoseGraph:
    """Poses and relative-pose measurements (edges i → j).

    ``T_bi_bj_meas[e]`` is the measured pose of body frame j in body frame i for edge
    ``e = (edge_i[e], edge_j[e])``; ``sqrt_info`` is the diagonal of W (1/σ per tangent
    coordinate, the same for every edge). The first ``n_odometry`` edges are odometry.
    """

    name: str
    T_world_body_true: Any  # (N,) ground truth
    T_world_body_odom: Any  # (N,) chained odometry: the initial estimate
    edge_i: jax.Array  # (E,) int
    edge_j: jax.Array  # (E,) int
    T_bi_bj_meas: Any  # (E,)
    sqrt_info: jax.Array  # (k,)
    n_odometry: int

    @property
    def n_poses(self) -> int:
        return len(self.T_world_body_true)

    @property
    def n_edges(self) -> int:
        return int(self.edge_i.shape[0])


@jax.jit
def simulate_measurements(T_world_body_true, edge_i, edge_j, noise):
    """Measurements and the dead-reckoning initial estimate.

    Z_ij = T_bi_bj exp(n) with T_bi_bj = T_world_bi⁻¹ T_world_bj and n = ``noise[e]``
    (right-perturbation noise, drawn by the caller as σ ⊙ N(0, I)); the odometry edges
    are the first N − 1, (k, k + 1), and are chained from the known first pose:
    T_world_b(k+1) = T_world_bk Z_k,k+1.
    """
    T_bi_bj_true = T_world_body_true[edge_i].inverse() @ T_world_body_true[edge_j]
    T_bi_bj_meas = manifold.rplus(T_bi_bj_true, noise)
    n = T_world_body_true.parameters().shape[0]

    def step(T_world_bk, T_bk_bk1):
        T_world_bk1 = T_world_bk @ T_bk_bk1
        return T_world_bk1, T_world_bk1.parameters()

    T_world_b0 = T_world_body_true[0]
    _, rest = jax.lax.scan(step, T_world_b0, T_bi_bj_meas[: n - 1])
    T_world_body_odom = type(T_world_b0)(
        jnp.concatenate([T_world_b0.parameters()[None], rest], axis=0)
    )
    return T_bi_bj_meas, T_world_body_odom


def _build_graph(name, T_world_body_true, loop_i, loop_j, sigma, rng) -> PoseGraph:
    n = len(T_world_body_true)
    edge_i = onp.concatenate([onp.arange(n - 1), loop_i]).astype(onp.int32)
    edge_j = onp.concatenate([onp.arange(1, n), loop_j]).astype(onp.int32)
    noise = rng.normal(size=(len(edge_i), len(sigma))) * sigma
    Z, T_world_body_odom = simulate_measurements(
        T_world_body_true, jnp.asarray(edge_i), jnp.asarray(edge_j), jnp.asarray(noise)
    )
    return PoseGraph(
        name=name,
        T_world_body_true=T_world_body_true,
        T_world_body_odom=T_world_body_odom,
        edge_i=jnp.asarray(edge_i),
        edge_j=jnp.asarray(edge_j),
        T_bi_bj_meas=Z,
        sqrt_info=jnp.asarray(1.0 / onp.asarray(sigma)),
        n_odometry=n - 1,
    )


# Noise per edge: (vx, vy, θ) for SE(2), (v, ω) for SE(3); metres and radians.
SIGMA_SE2 = onp.array([0.05, 0.05, onp.deg2rad(1.0)])
SIGMA_SE3 = onp.array([0.05, 0.05, 0.05, *[onp.deg2rad(1.0)] * 3])


def make_manhattan_se2(
    n_poses: int, seed: int = 0, block: int = 3, blocks: int = 5, closure_prob: float = 0.25
) -> PoseGraph:
    """A walk on a Manhattan street grid of ``blocks × blocks`` blocks of ``block`` metres.

    One metre per step; at a crossing the robot goes straight (p = ½) or turns ±90°
    (p = ¼ each), never leaving the map and never turning back unless cornered. Pose k
    stands on grid point p_k facing the direction in which it leaves. When the robot comes
    within a metre (same or adjacent grid point) of a pose at least 4 steps older, the
    pair is a loop-closure candidate (a place recognised), kept with probability
    ``closure_prob``.
    """
    rng = onp.random.default_rng(seed)
    size = block * blocks
    heading_dirs = onp.array([[1, 0], [0, 1], [-1, 0], [0, -1]])  # E, N, W, S
    p, h = onp.array([0, 0]), 0
    positions, headings = [], []
    for _ in range(n_poses):
        if p[0] % block == 0 and p[1] % block == 0:  # at a crossing: choose a street
            options = [(h, 0.5), ((h + 1) % 4, 0.25), ((h + 3) % 4, 0.25)]
            options = [
                (d, w)
                for d, w in options
                if onp.all((0 <= p + heading_dirs[d]) & (p + heading_dirs[d] <= size))
            ]
            if not options:
                options = [((h + 2) % 4, 1.0)]
            w = onp.array([o[1] for o in options])
            h = options[rng.choice(len(options), p=w / w.sum())][0]
        positions.append(p.copy())
        headings.append(h)
        p = p + heading_dirs[h]
    positions = onp.array(positions, dtype=onp.float64)
    theta = onp.array(headings) * (onp.pi / 2)
    T_world_body_true = SE2.from_xy_theta(
        jnp.asarray(positions[:, 0]), jnp.asarray(positions[:, 1]), jnp.asarray(theta)
    )

    seen: Dict[Tuple[int, int], List[int]] = {}
    loop_i, loop_j = [], []
    for k, (x, y) in enumerate(positions.astype(int)):
        for dx, dy in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            for m in seen.get((x + dx, y + dy), []):
                if k - m >= 4 and rng.uniform() < closure_prob:
                    loop_i.append(m)
                    loop_j.append(k)
        seen.setdefault((x, y), []).append(k)
    return _build_graph(
        "SE(2) Manhattan walk",
        T_world_body_true,
        onp.array(loop_i),
        onp.array(loop_j),
        SIGMA_SE2,
        rng,
    )


def make_sphere_se3(turns: int, per_turn: int, seed: int = 0, radius: float = 5.0) -> PoseGraph:
    """A robot spiralling up a sphere of ``radius`` metres, ``per_turn`` poses a turn.

    Latitude rises linearly from −70° to +70°; the body x axis points along the motion and
    the z axis out of the sphere. Loop closures join each pose to the one a turn below.
    """
    rng = onp.random.default_rng(seed + 1)
    n = turns * per_turn
    s = onp.arange(n)
    lat = onp.deg2rad(-70.0 + 140.0 * s / (n - 1))
    lon = 2 * onp.pi * s / per_turn
    p = radius * onp.stack(
        [onp.cos(lat) * onp.cos(lon), onp.cos(lat) * onp.sin(lon), onp.sin(lat)], axis=-1
    )
    # Direction of motion: derivative of p with respect to s.
    dlat, dlon = onp.deg2rad(140.0) / (n - 1), 2 * onp.pi / per_turn
    tangent = radius * onp.stack(
        [
            -onp.sin(lat) * onp.cos(lon) * dlat - onp.cos(lat) * onp.sin(lon) * dlon,
            -onp.sin(lat) * onp.sin(lon) * dlat + onp.cos(lat) * onp.cos(lon) * dlon,
            onp.cos(lat) * dlat,
        ],
        axis=-1,
    )
    z_body = p / radius
    x_body = tangent - onp.sum(tangent * z_body, -1, keepdims=True) * z_body
    x_body /= onp.linalg.norm(x_body, axis=-1, keepdims=True)
    y_body = onp.cross(z_body, x_body)
    R_world_body = onp.stack([x_body, y_body, z_body], axis=-1)  # columns: body axes
    T_world_body_true = SE3.from_rotation_and_translation(
        SO3.from_matrix(jnp.asarray(R_world_body)), jnp.asarray(p)
    )
    loop_j = onp.arange(per_turn, n)
    return _build_graph(
        "SE(3) sphere", T_world_body_true, loop_j - per_turn, loop_j, SIGMA_SE3, rng
    )


# ---------------------------------------------------------------------------------------
# 2. Residuals and their Jacobians


def edge_residual(T_world_bi, T_world_bj, T_bi_bj_meas) -> jax.Array:
    """r_ij = log(Z_ij⁻¹ T_world_bi⁻¹ T_world_bj) = T_world_bj ⊖ (T_world_bi Z_ij)."""
    T_world_bj_pred = T_world_bi @ T_bi_bj_meas
    return manifold.rminus(T_world_bj_pred, T_world_bj)


def edge_residual_and_jacobians(T_world_bi, T_world_bj, T_bi_bj_meas):
    """r_ij and its Jacobians with respect to right perturbations of T_world_bi, T_world_bj.

    Let P = T_world_bi Z_ij (the pose of j predicted from i) and E = P⁻¹ T_world_bj =
    exp(r), and use the Jacobians of composition and of right-minus (Solà, Deray and
    Atchuthan, *A micro Lie theory for state estimation in robotics*, 2018, §III; the
    ``compose`` and ``rminus`` rows of the table in ``jaxlie_geo.jacobians``):

    - perturbing T_world_bj: log(E exp(δ_j)) ≈ r + J_r⁻¹(r) δ_j, so J_j = J_r⁻¹(r);
    - perturbing T_world_bi moves P by P exp(δ_i') with δ_i' = Ad(Z⁻¹) δ_i (compose:
      T exp(δ) Z = T Z exp(Ad(Z⁻¹) δ)), and log(exp(−δ') E) ≈ r − J_l⁻¹(r) δ' (right-minus
      w.r.t. its first argument), so J_i = −J_l⁻¹(r) Ad(Z⁻¹).

    Equivalently J_i = −J_r⁻¹(r) Ad(E⁻¹) Ad(Z⁻¹) = −J_r⁻¹(r) Ad(T_world_bj⁻¹ T_world_bi),
    the form often found in the SLAM literature. Shapes ``(*batch, k)``, ``(*batch, k, k)``.
    """
    T_world_bj_pred = T_world_bi @ T_bi_bj_meas
    r = manifold.rminus(T_world_bj_pred, T_world_bj)
    J_r_pred, J_r_j = jacobians.rminus(T_world_bj_pred, T_world_bj)  # −J_l⁻¹(r), J_r⁻¹(r)
    J_pred_i, _ = jacobians.compose(T_world_bi, T_bi_bj_meas)  # Ad(Z⁻¹)
    return r, J_r_pred @ J_pred_i, J_r_j


def edge_jacobians_autodiff(T_world_bi, T_world_bj, T_bi_bj_meas):
    """The same Jacobians by forward-mode autodiff of δ ↦ r(T_i ⊕ δ_i, T_j ⊕ δ_j) at 0
    (one edge; ``jax.vmap`` it for a batch)."""
    G = type(T_world_bi)
    zero = jnp.zeros(G.tangent_dim, T_world_bi.parameters().dtype)

    def r_of(delta_i, delta_j):
        return edge_residual(
            manifold.rplus(T_world_bi, delta_i), manifold.rplus(T_world_bj, delta_j), T_bi_bj_meas
        )

    return jax.jacfwd(r_of, argnums=(0, 1))(zero, zero)


@jax.jit
def linearise(T_world_body, edge_i, edge_j, T_bi_bj_meas):
    """r_ij, J_i, J_j of every edge at once (``edge_residual_and_jacobians`` on the
    batch of edges): shapes (E, k), (E, k, k), (E, k, k)."""
    return edge_residual_and_jacobians(T_world_body[edge_i], T_world_body[edge_j], T_bi_bj_meas)


@jax.jit
def linearise_autodiff(T_world_body, edge_i, edge_j, T_bi_bj_meas):
    """``edge_jacobians_autodiff`` on every edge (``jax.vmap``)."""
    return jax.vmap(edge_jacobians_autodiff)(
        T_world_body[edge_i], T_world_body[edge_j], T_bi_bj_meas
    )


def jacobian_check(T_world_body, edge_i, edge_j, T_bi_bj_meas) -> Tuple[float, float, float]:
    """max |analytic − jax.jacfwd| over every edge, for J_i and J_j, and the largest
    rotation angle among the residuals (how far from r = 0 the check reaches)."""
    r, J_i, J_j = linearise(T_world_body, edge_i, edge_j, T_bi_bj_meas)
    A_i, A_j = linearise_autodiff(T_world_body, edge_i, edge_j, T_bi_bj_meas)
    space_dim = type(T_world_body).space_dim
    max_angle = onp.max(onp.linalg.norm(onp.asarray(r)[:, space_dim:], axis=-1))  # θ or ω
    return (
        float(onp.max(onp.abs(onp.asarray(J_i - A_i)))),
        float(onp.max(onp.abs(onp.asarray(J_j - A_j)))),
        float(max_angle),
    )


# ---------------------------------------------------------------------------------------
# 3. Normal equations, Levenberg–Marquardt


@functools.partial(jax.jit, static_argnames="n_poses")
def normal_equations(r, J_i, J_j, edge_i, edge_j, sqrt_info, n_poses: int):
    """Dense H = Σ Jᵀ Wᵀ W J and g = Σ Jᵀ Wᵀ W r over all edges, and the cost F.

    The whitened Jacobian of edge (i, j) has two non-zero k×k blocks, A_i = W J_i and
    A_j = W J_j, so the edge adds A_iᵀA_i, A_iᵀA_j, A_jᵀA_i, A_jᵀA_j to the blocks
    (i,i), (i,j), (j,i), (j,j) of H and A_iᵀ W r, A_jᵀ W r to the blocks i, j of g: one
    batched scatter-add (``.at[].add``, repeated indices accumulate) per block kind.

    Gauge: F is invariant under T_world_body ← T_world T_world_body for any fixed
    T_world, so H is singular. Pose 0 is held at its known value by replacing its rows and
    columns with those of the identity and its gradient by 0 (δ_0 = 0): the same as
    deleting its block.
    """
    n, k = n_poses, r.shape[-1]
    w_r = r * sqrt_info
    A_i = sqrt_info[:, None] * J_i  # W J, (E, k, k)
    A_j = sqrt_info[:, None] * J_j
    AiT, AjT = jnp.swapaxes(A_i, -1, -2), jnp.swapaxes(A_j, -1, -2)

    H = jnp.zeros((n, n, k, k), r.dtype)  # block (a, b) is H[a, b]
    H = H.at[edge_i, edge_i].add(AiT @ A_i)
    H = H.at[edge_i, edge_j].add(AiT @ A_j)
    H = H.at[edge_j, edge_i].add(AjT @ A_i)
    H = H.at[edge_j, edge_j].add(AjT @ A_j)
    g = jnp.zeros((n, k), r.dtype)
    g = g.at[edge_i].add(jnp.einsum("eab,eb->ea", AiT, w_r))
    g = g.at[edge_j].add(jnp.einsum("eab,eb->ea", AjT, w_r))

    H = H.transpose(0, 2, 1, 3).reshape(n * k, n * k)
    g = g.reshape(n * k)
    H = H.at[:k, :].set(0.0).at[:, :k].set(0.0).at[:k, :k].set(jnp.eye(k, dtype=H.dtype))
    g = g.at[:k].set(0.0)
    return H, g, 0.5 * jnp.sum(w_r**2)


@jax.jit
def damped_step(T_world_body, H, g, lam):
    """Solve (H + λ diag(H)) δ = −g (Cholesky: H is symmetric positive definite once the
    gauge is fixed) and retract every pose, T_world_body ⊕ δ; also return max |δ|."""
    n, k = T_world_body.parameters().shape[0], type(T_world_body).tangent_dim
    H_damped = H + lam * jnp.diag(jnp.diag(H))
    delta = jsl.cho_solve(jsl.cho_factor(H_damped), -g).reshape(n, k)
    return manifold.rplus(T_world_body, delta), jnp.max(jnp.abs(delta))


@dataclasses.dataclass
class SolveResult:
    method: str
    T_world_body: Any
    costs: List[float]  # the cost after each iteration, costs[0] the initial one
    iterations: int
    rejected: int
    seconds: float


def optimise(
    graph: PoseGraph,
    method: str = "lm",
    max_iters: int = 30,
    rel_tol: float = 1e-9,
    verbose: bool = True,
) -> SolveResult:
    """Levenberg–Marquardt (``"lm"``: Marquardt's diagonal damping, λ ÷ 10 after a step
    that lowers the cost, λ × 10 and retry after one that does not) or plain Gauss–Newton
    (``"gn"``: λ = 0, every step taken). Stops when the relative decrease of the cost falls
    below ``rel_tol`` or after ``max_iters`` iterations.

    Every candidate is linearised right away: its residuals give the cost that decides
    acceptance, and its Jacobians the next normal equations.
    """
    edges = (graph.edge_i, graph.edge_j, graph.T_bi_bj_meas)
    n = graph.n_poses

    def normal_equations_at(T_world_body):
        r, J_i, J_j = linearise(T_world_body, *edges)
        return normal_equations(r, J_i, J_j, graph.edge_i, graph.edge_j, graph.sqrt_info, n_poses=n)

    T = graph.T_world_body_odom
    t0 = time.perf_counter()
    H, g, cost = normal_equations_at(T)
    cost = float(cost)
    costs, lam, rejected = [cost], (1e-4 if method == "lm" else 0.0), 0
    if verbose:
        print(f"    iter {0:3d}  cost {cost:.6e}  (odometry initialisation)")
    it = 0
    for it in range(1, max_iters + 1):
        ti = time.perf_counter()
        T_new, step = damped_step(T, H, g, lam)
        H_new, g_new, new_cost = normal_equations_at(T_new)
        new_cost, step = float(new_cost), float(step)
        accepted = method == "gn" or new_cost < cost
        if accepted:
            rel_decrease = (cost - new_cost) / max(cost, 1e-300)
            T, H, g, cost = T_new, H_new, g_new, new_cost
            lam = max(lam / 10.0, 1e-12) if method == "lm" else 0.0
        else:
            lam *= 10.0
            rejected += 1
        costs.append(cost)
        if verbose:
            status = "accepted" if accepted else f"rejected (trial cost {new_cost:.3e})"
            lam_text = f"  lambda {lam:.0e}" if method == "lm" else ""
            print(
                f"    iter {it:3d}  cost {cost:.6e}  max|delta| {step:.2e}{lam_text}  "
                f"{status}  ({1e3 * (time.perf_counter() - ti):.0f} ms)"
            )
        if accepted and (abs(rel_decrease) < rel_tol or step < 1e-12):
            break
    jax.block_until_ready(T.parameters())
    return SolveResult(method, T, costs, it, rejected, time.perf_counter() - t0)


# ---------------------------------------------------------------------------------------
# 4. Errors against ground truth


@jax.jit
def trajectory_errors(T_world_body_est, T_world_body_true) -> Tuple[jax.Array, jax.Array]:
    """Position RMSE [m] and rotation RMSE [deg] (angle of R_true⁻¹ R_est) over all poses.
    No alignment: both trajectories share the anchored first pose."""
    dp = T_world_body_est.translation() - T_world_body_true.translation()
    pos_rmse = jnp.sqrt(jnp.mean(jnp.sum(dp**2, axis=-1)))
    dR = (T_world_body_true.rotation().inverse() @ T_world_body_est.rotation()).log()
    rot_rmse = jnp.sqrt(jnp.mean(jnp.sum(dR**2, axis=-1)))
    return pos_rmse, jnp.rad2deg(rot_rmse)


def run_problem(graph: PoseGraph, method: str, max_iters: int) -> Dict[str, Any]:
    """Jacobian check, optimisation and errors for one graph, with the report printed."""
    n, k = graph.n_poses, type(graph.T_world_body_true).tangent_dim
    n_loops = graph.n_edges - graph.n_odometry
    print(f"{graph.name}: {n} poses, {graph.n_odometry} odometry edges + {n_loops} loop closures")
    *check, max_angle = jacobian_check(
        graph.T_world_body_odom, graph.edge_i, graph.edge_j, graph.T_bi_bj_meas
    )
    print(
        f"  Jacobian check at the odometry initialisation, all {graph.n_edges} residuals "
        f"(rotation part up to {onp.rad2deg(max_angle):.0f} deg):"
    )
    print(f"    max |analytic - jax.jacfwd|: dr/dT_i {check[0]:.1e}, dr/dT_j {check[1]:.1e}")
    name = {"lm": "Levenberg-Marquardt", "gn": "Gauss-Newton"}[method]
    print(f"  {name}, dense {n * k} x {n * k} normal equations, first pose anchored")
    result = optimise(graph, method, max_iters)
    # At the optimum, 2F is χ² with (E − N + 1)·k degrees of freedom (measurements minus
    # free parameters) if the noise model is right: F ≈ dof/2 ± sqrt(dof/2).
    dof = (graph.n_edges - n + 1) * k
    print(
        f"  {result.iterations} iterations ({result.rejected} rejected), "
        f"{result.seconds:.2f} s (incl. compilation)"
    )
    print(
        f"  cost {result.costs[0]:.4e} -> {result.costs[-1]:.4e}  "
        f"(expected at the optimum: {dof / 2:.0f} +- {onp.sqrt(dof / 2):.0f}, "
        f"half a chi-square with {dof} dof)"
    )
    before = [float(x) for x in trajectory_errors(graph.T_world_body_odom, graph.T_world_body_true)]
    after = [float(x) for x in trajectory_errors(result.T_world_body, graph.T_world_body_true)]
    print(
        f"  error vs ground truth, odometry : position RMSE {before[0]:8.4f} m, "
        f"rotation RMSE {before[1]:8.4f} deg"
    )
    print(
        f"  error vs ground truth, optimised: position RMSE {after[0]:8.4f} m, "
        f"rotation RMSE {after[1]:8.4f} deg"
    )
    return dict(
        graph=graph,
        result=result,
        check=check,
        max_angle=max_angle,
        dof=dof,
        before=before,
        after=after,
    )


# ---------------------------------------------------------------------------------------
# 5. Figure

C_TRUE, C_ODOM, C_OPT = "0.1", "#d95f02", "#1f63b4"


def _positions(T_world_body) -> onp.ndarray:
    """Translations as numpy, read from the parameters (x, y last for SE(2) and SE(3))."""
    return onp.asarray(T_world_body.parameters())[:, -type(T_world_body).space_dim :]


def _title(res: Dict[str, Any], tag: str) -> str:
    g, b, a = res["graph"], res["before"], res["after"]
    return (
        f"({tag}) {g.name}: {g.n_poses} poses, {g.n_edges - g.n_odometry} loop closures\n"
        f"RMSE vs truth: odometry {b[0]:.2f} m, {b[1]:.1f}°  →  "
        f"optimised {a[0]:.2f} m, {a[1]:.2f}°"
    )


def draw(path: Path, r2: Dict[str, Any], r3: Dict[str, Any]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fig = plt.figure(figsize=(17.0, 6.4), dpi=140)
    gs = fig.add_gridspec(
        1,
        3,
        width_ratios=[1.0, 1.05, 0.78],
        wspace=0.22,
        left=0.04,
        right=0.985,
        bottom=0.16,
        top=0.86,
    )
    style_odom = dict(color=C_ODOM, lw=1.0, ls="--")
    style_true = dict(color=C_TRUE, lw=3.4, alpha=0.22, solid_capstyle="round")
    style_opt = dict(color=C_OPT, lw=1.0)

    # (a) SE(2): top view, equal aspect.
    ax = fig.add_subplot(gs[0])
    g2 = r2["graph"]
    true, odom = _positions(g2.T_world_body_true), _positions(g2.T_world_body_odom)
    opt = _positions(r2["result"].T_world_body)
    ax.plot(*odom.T, **style_odom)
    ax.plot(*true.T, **style_true)
    ax.plot(*opt.T, **style_opt)
    ax.plot(*true[0], marker="o", ms=7, color="k", ls="none")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_title(_title(r2, "a"), fontsize=10.5)

    # (b) SE(3): equal scale on all three axes.
    ax = fig.add_subplot(gs[1], projection="3d", computed_zorder=False)
    g3 = r3["graph"]
    true, odom = _positions(g3.T_world_body_true), _positions(g3.T_world_body_odom)
    opt = _positions(r3["result"].T_world_body)
    ax.plot(*odom.T, zorder=1, **style_odom)
    ax.plot(*true.T, zorder=2, **style_true)
    ax.plot(*opt.T, zorder=3, **style_opt)
    ax.scatter(*true[0], color="k", s=36, depthshade=False, zorder=4)
    pts = onp.concatenate([true, odom, opt])
    lo, hi = pts.min(0), pts.max(0)
    mid, half = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set(
        xlim=(mid[0] - half, mid[0] + half),
        ylim=(mid[1] - half, mid[1] + half),
        zlim=(mid[2] - half, mid[2] + half),
    )
    ax.set_box_aspect((1, 1, 1), zoom=1.05)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.view_init(elev=16, azim=-58)
    # Axes3D titles sit lower than 2D ones; place it like the others, on the slot's top.
    ax.text2D(
        0.5, 1.0, _title(r3, "b"), transform=ax.transAxes, ha="center", va="bottom", fontsize=10.5
    )

    # (c) cost per iteration, and the expected minimum.
    ax = fig.add_subplot(gs[2])
    for res, color, marker in ((r2, "#1b9e77", "o"), (r3, "#7570b3", "s")):
        c = onp.asarray(res["result"].costs)
        ax.semilogy(
            onp.arange(len(c)),
            c,
            color=color,
            marker=marker,
            ms=4.5,
            lw=1.4,
            label=res["graph"].name,
        )
        ax.axhline(res["dof"] / 2, color=color, lw=0.9, ls=":")
    ax.plot([], [], color="0.35", lw=0.9, ls=":", label="expected minimum: ½χ² with (E−N+1)·k dof")
    ax.set_xlabel("iteration")
    ax.set_ylabel(r"cost $F = \frac{1}{2}\,\sum\, \|W\, r_{ij}\|^2$")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.grid(True, which="both", lw=0.4, alpha=0.5)
    method = "Levenberg–Marquardt" if r2["result"].method == "lm" else "Gauss–Newton"
    ax.set_title(f"(c) {method}: cost per iteration", fontsize=10.5)
    ax.legend(fontsize=8.5, loc="upper right", framealpha=0.92)

    handles = [
        Line2D([], [], **style_odom),
        Line2D([], [], **style_true),
        Line2D([], [], **style_opt),
        Line2D([], [], color="k", marker="o", ms=6, ls="none"),
    ]
    labels = [
        "initial estimate: chained odometry",
        "ground truth",
        "optimised",
        "first pose (anchored, known)",
    ]
    fig.legend(
        handles,
        labels,
        loc="lower center",
        bbox_to_anchor=(0.36, 0.0),
        ncol=4,
        fontsize=9.5,
        frameon=False,
    )
    fig.suptitle(
        "Pose-graph optimisation on SE(2) and SE(3) with closed-form Jacobians: "
        r"$r_{ij} = \log(Z_{ij}^{-1}\, T_i^{-1} T_j)$, "
        r"$J_i = -J_l^{-1}(r_{ij})\,\mathrm{Ad}(Z_{ij}^{-1})$, "
        r"$J_j = J_r^{-1}(r_{ij})$",
        fontsize=12.5,
        y=0.985,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------
# 6. A pose graph from a file (--file): the library's sparse solver


def optimise_file(args: argparse.Namespace) -> Dict[str, Any]:
    """Read a g2o or TORO file, solve it with ``jaxlie_geo.pose_graph.solve`` and report."""
    path = args.file
    graph = pose_graph.read(path, information_order=args.information_order)
    k = graph.group.tangent_dim
    consecutive = int(onp.sum(onp.abs(graph.edges[:, 0] - graph.edges[:, 1]) == 1))
    print(
        f"{path.name}: {graph.dim}D pose graph ({graph.group.__name__}), {graph.num_poses} poses, "
        f"{graph.num_edges} edges ({consecutive} between consecutive poses, "
        f"{graph.num_edges - consecutive} others)"
    )
    initial_cost = pose_graph.graph_cost(graph)
    print(f"  initial cost {initial_cost:.9e}")
    name = {"lm": "Levenberg-Marquardt", "gn": "Gauss-Newton"}[args.method]
    print(
        f"  {name}, linear solver {args.linear_solver}, at most {args.max_iterations} "
        f"iterations, on {jax.devices()[0].platform} (progress on stderr):",
        flush=True,
    )
    solution = pose_graph.solve(
        graph,
        method=args.method,
        linear_solver=args.linear_solver,
        max_iterations=args.max_iterations,
        progress=True,
    )
    print(
        f"  final cost {solution.costs[-1]:.9e} after {solution.iterations} iterations, "
        f"{solution.time:.2f} s (incl. compilation)"
    )
    print(f"  stopped: {solution.stop_reason} (converged: {solution.converged})")
    # If every information matrix is the inverse covariance of its measurement's noise,
    # 2F at the optimum is a chi-square sample with (E − N + 1)·k degrees of freedom.
    dof = (graph.num_edges - graph.num_poses + 1) * k
    if dof > 0:
        print(
            f"  for reference: with information = inverse noise covariance, 2F at the optimum "
            f"is chi-square with (E - N + 1)k = {dof} dof: F = {dof / 2:.0f} +- "
            f"{onp.sqrt(dof / 2):.0f}"
        )
    out = args.out or Path("out") / f"pose_graph_{path.stem}.png"
    draw_file(out, path.name, graph, solution, name)
    print(f"Wrote {out}")
    if args.write is not None:
        file_format = "toro" if args.write.suffix in (".graph", ".toro") else "g2o"
        args.write.parent.mkdir(parents=True, exist_ok=True)
        pose_graph.write(args.write, solution.graph, format=file_format)
        print(f"Wrote {args.write} (optimised poses, {file_format} format)")
    return dict(graph=graph, initial_cost=initial_cost, solution=solution, dof=dof)


C_ODOMETRY, C_OTHER = "#1f63b4", "#d95f02"


def _draw_graph(ax, graph: pose_graph.PoseGraph, title: str) -> None:
    """The poses' positions joined in their order by one line (the trajectory, along the
    edges between consecutive poses) and every other edge (loop closures) as a thin
    straight segment."""
    from matplotlib.collections import LineCollection
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    xyz = graph.poses[:, : graph.dim]  # vertex layout: (x, y, θ) or (x, y, z, q)
    i, j = graph.edges[:, 0], graph.edges[:, 1]
    other = onp.abs(i - j) != 1
    segments = onp.stack([xyz[i[other]], xyz[j[other]]], axis=1)  # (edges, 2, dim)
    # The more edges, the thinner and fainter (they pile up, in 2D more than in 3D);
    # rasterised, so that a PDF or SVG of a graph with thousands of them stays small.
    n = len(segments)
    alpha = float(onp.clip((300 if graph.dim == 2 else 1500) / max(n, 1), 0.06, 0.8))
    width = 0.25 if n > 1000 else 0.8
    style = dict(colors=C_OTHER, linewidths=width, alpha=alpha, rasterized=True, zorder=1)
    if graph.dim == 2:
        ax.add_collection(LineCollection(segments, **style))
        ax.plot(*xyz.T, color=C_ODOMETRY, lw=0.5, zorder=2, rasterized=True)
        ax.plot(*xyz[0], marker="o", ms=6, color="k", ls="none", zorder=3)
        ax.set_aspect("equal", adjustable="datalim")
        ax.autoscale_view()
        ax.grid(True, lw=0.4, alpha=0.5)
    else:
        ax.add_collection3d(Line3DCollection(segments, **style))
        ax.plot(*xyz.T, color=C_ODOMETRY, lw=0.5, zorder=2, rasterized=True)
        ax.scatter(*xyz[0], color="k", s=30, depthshade=False, zorder=3)
        # Equal scale on the three axes.
        mid, half = (xyz.min(0) + xyz.max(0)) / 2, (xyz.max(0) - xyz.min(0)).max() / 2
        ax.set(
            xlim=(mid[0] - half, mid[0] + half),
            ylim=(mid[1] - half, mid[1] + half),
            zlim=(mid[2] - half, mid[2] + half),
        )
        ax.set_box_aspect((1, 1, 1))
        ax.set_zlabel("z")
        ax.view_init(elev=20, azim=-60)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_title(title, fontsize=10.5)


def draw_file(
    path: Path, name: str, graph: pose_graph.PoseGraph, solution: pose_graph.Solution, method: str
) -> None:
    """Initial estimate (left), optimised graph (middle), cost per iteration (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fig = plt.figure(figsize=(13.0, 4.8), dpi=100)
    gs = fig.add_gridspec(
        1, 3, width_ratios=[1.0, 1.0, 0.8], wspace=0.3, left=0.05, right=0.98, bottom=0.17
    )
    projection = "3d" if graph.dim == 3 else None
    costs = solution.costs
    _draw_graph(
        fig.add_subplot(gs[0], projection=projection),
        graph,
        f"initial estimate: cost {costs[0]:.4g}",
    )
    _draw_graph(
        fig.add_subplot(gs[1], projection=projection),
        solution.graph,
        f"optimised: cost {costs[-1]:.6g}",
    )

    ax = fig.add_subplot(gs[2])
    ax.semilogy(onp.arange(len(costs)), costs, color="0.15", marker="o", ms=4, lw=1.2)
    ax.set_xlabel("iteration")
    ax.set_ylabel(r"cost $F = \frac{1}{2}\sum \|r_{ij}\|^2_{\Omega_{ij}}$")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.grid(True, which="both", lw=0.4, alpha=0.5)
    ax.set_title(f"{method}: cost per iteration", fontsize=10.5)
    ax.text(
        0.97,
        0.97,
        f"{costs[0]:.4g} → {costs[-1]:.6g}\n{solution.iterations} iterations, "
        f"{solution.time:.1f} s\n(incl. compilation)",
        transform=ax.transAxes,
        ha="right",
        va="top",
        fontsize=9.5,
        bbox=dict(facecolor="white", edgecolor="0.8", alpha=0.9),
    )

    handles = [
        Line2D([], [], color=C_ODOMETRY, lw=1.2),
        Line2D([], [], color=C_OTHER, lw=1.2, alpha=0.6),
        Line2D([], [], color="k", marker="o", ms=6, ls="none"),
    ]
    labels = [
        "edges between consecutive poses (odometry)",
        "other edges (loop closures)",
        "first pose (anchored)",
    ]
    fig.legend(handles, labels, loc="lower center", ncol=3, frameon=False, fontsize=9.5)
    fig.suptitle(
        f"{name}: {graph.dim}D pose graph, {graph.num_poses} poses, {graph.num_edges} edges",
        fontsize=12.5,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, facecolor="white", pil_kwargs=dict(optimize=True))
    plt.close(fig)


# ---------------------------------------------------------------------------------------


def main(argv=None) -> Dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="few poses, few iterations")
    parser.add_argument(
        "--method",
        choices=("lm", "gn"),
        default="lm",
        help="Levenberg-Marquardt (default) or plain Gauss-Newton",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="the picture (default out/pose_graph.png, with --file out/pose_graph_<name>.png)",
    )
    files = parser.add_argument_group(
        "a pose graph from a file (the synthetic demo runs without --file)"
    )
    files.add_argument("--file", type=Path, help="a g2o or TORO file, 2D or 3D")
    files.add_argument(
        "--information-order",
        choices=("g2o", "toro"),
        default=None,
        help="order of the 6 information entries of 2D edges (default: each tag's own)",
    )
    files.add_argument(
        "--linear-solver",
        choices=("auto", "cholesky", "cholmod", "qdldl", "pcg"),
        default="auto",
        help="sparse Cholesky on the host, conjugate gradients on the device, or auto",
    )
    files.add_argument("--max-iterations", type=int, default=100)
    files.add_argument(
        "--write",
        type=Path,
        default=None,
        help="write the optimised graph (TORO for .graph/.toro, g2o otherwise)",
    )
    args = parser.parse_args(argv)
    if args.file is not None:
        return optimise_file(args)
    out = args.out or Path("out/pose_graph.png")
    t0 = time.perf_counter()

    if args.quick:
        graph_2d = make_manhattan_se2(n_poses=250, seed=args.seed, blocks=3)
        graph_3d = make_sphere_se3(turns=4, per_turn=16, seed=args.seed)
        max_iters = 10
    else:
        graph_2d = make_manhattan_se2(n_poses=500, seed=args.seed)
        graph_3d = make_sphere_se3(turns=8, per_turn=32, seed=args.seed)
        max_iters = 30
    print(
        f"Pose-graph optimisation on {jax.devices()[0].platform}, float64, "
        f"method {args.method}, seed {args.seed}"
    )
    results = {
        "2d": run_problem(graph_2d, args.method, max_iters),
        "3d": run_problem(graph_3d, args.method, max_iters),
    }
    draw(out, results["2d"], results["3d"])
    print(f"Wrote {out}  (total {time.perf_counter() - t0:.1f} s)")
    return results


if __name__ == "__main__":
    main()
