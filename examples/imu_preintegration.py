"""IMU preintegration as a product of SE_2(3) increments, with its covariance.

An inertial measurement unit (IMU) samples, in the body frame, the angular velocity ω (gyroscope)
and the specific force a = Rᵀ(a_world − g) (accelerometer; g is gravity in the world frame,
(0, 0, −9.81) m/s² here). Between two instants i and j, Forster, Carlone, Dellaert and
Scaramuzza (*On-Manifold Preintegration for Real-Time Visual-Inertial Odometry*, IEEE T-RO
2017, §V–VI) summarise the samples by the preintegrated rotation, velocity and position

    ΔR_ij = R_iᵀ R_j,
    Δv_ij = R_iᵀ (v_j − v_i − g Δt_ij),
    Δp_ij = R_iᵀ (p_j − p_i − v_i Δt_ij − ½ g Δt_ij²),

which depend on the IMU samples alone — not on the state at i, nor on gravity — so they are
computed once per pair of keyframes. With τ the time since t_i, they solve

    dΔR/dτ = ΔR ω̂,   dΔv/dτ = ΔR a,   dΔp/dτ = Δv,   (ΔR, Δv, Δp)(0) = (I, 0, 0),

and with samples ω_k, a_k (bias-free) held over steps of length dt, Forster et al. integrate
them as

    ΔR_{k+1} = ΔR_k Exp(ω_k dt),   Δv_{k+1} = Δv_k + ΔR_k a_k dt,
    Δp_{k+1} = Δp_k + Δv_k dt + ½ ΔR_k a_k dt².

**The discrete step as a group product.** The three quantities form one extended pose
ΔX = [[ΔR, Δp, Δv], [0, 1, 0], [0, 0, 1]], an element of SE_2(3) (``jaxlie_geo.SE23``, whose
parameters are (R, p, v) and tangent (ρ, ω, ν)). Barrau and Bonnabel (*The invariant extended
Kalman filter as a stable observer*, IEEE TAC 2017, §III; *A mathematical framework for IMU
error propagation with applications to preintegration*, ICRA 2020, arXiv:2003.03908) observe
that the navigation dynamics are group affine, and that their flow over a time t factors as

    X(t) = Γ_t · Φ_t(X(0)) · Υ_t,                                            (1)

* Φ_t(R, p, v) = (R, p + v t, v), the "time shift": a group automorphism, Φ_t(XY) = Φ_t(X)Φ_t(Y)
  (it is the conjugation X ↦ e^{−Nt} X e^{Nt} by the 5×5 matrix N whose only entry is
  N[4, 3] = 1);
* Γ_t = (I, ½ g t², g t), the free fall, on the left;
* Υ_t, on the right: the flow of the body-frame inputs started at the identity, i.e. the
  preintegrated quantity itself.

Preintegration is (1) with no gravity and X(0) = I, step by step:

    ΔX_{k+1} = Φ_dt(ΔX_k) · Υ_k,                                             (2)

a linear "time shift" (Δp += Δv dt) followed by a right product with the increment Υ_k. The
state at j is then X_j = Γ_{Δt} Φ_{Δt}(X_i) ΔX_ij (``predict``).

*Which increment.* With ω_k and a_k constant over the step (a zero-order hold, the assumption of
every IMU driver), the body rotates during the step, ΔR(τ) = ΔR_k Exp(ω_k τ), and integrating
dΔv/dτ = ΔR a and dΔp/dτ = Δv exactly gives

    Υ_k = (Exp(φ), Γ₂(φ) a_k dt², Γ₁(φ) a_k dt),   φ = ω_k dt,               (3)
    Γ₁(φ) = ∫₀¹ Exp(sφ) ds = J_l(φ)                   (SO(3)'s left Jacobian, SE(3)'s V),
    Γ₂(φ) = ∫₀¹ (1 − s) Exp(sφ) ds = ½ I + (θ − sin θ)/θ³ φ̂ + (θ²/2 + cos θ − 1)/θ⁴ φ̂²,

θ = ‖φ‖. Forster's step above is (2) with Υ_k^F = (Exp(φ), ½ a_k dt², a_k dt): Γ₁ and Γ₂
truncated to their constant terms, which is exact only if ΔR a were constant over the step. Its
error per step is O(‖ω‖‖a‖ dt²), so O(dt) over a window, whatever the sampling; (3) has no error
of its own, and with samples taken mid-step the whole scheme becomes second order. This script
uses (3) by default and Υ^F where it is compared with GTSAM, which implements Forster's step.
(2) with (3) is checked against the 5×5 matrix exponential of the flow, which obeys
dX/dτ = X (Û + N) − N X with Û = hat(0, ω, a), so that X(τ₀ + dt) = e^{−N dt} X(τ₀) e^{(Û + N) dt}.

In the library, Υ_k = exp((P, 0, V)) · exp(ξ_E) with ξ_E = (0, φ, ν): for (3), P = Γ₂(φ) a dt²,
V = 0 and ν = a dt (SE23's exponential of (0, φ, a dt) is exactly (Exp φ, 0, Γ₁(φ) a dt)); for
Υ^F, P = ½ a dt², V = a dt and ν = 0.

**Covariance, for the right perturbation ΔX̃ = ΔX ⊕ δ = ΔX · exp(δ)** (the library's
convention, δ = (δρ, δω, δν) ∈ R⁹). Φ_dt acts on the Lie algebra as the linear map
F = [[I, 0, dt I], [0, I, 0], [0, 0, I]] (ρ += ν dt), so Φ_dt(ΔX exp δ) = Φ_dt(ΔX) exp(F δ) and

    Φ_dt(ΔX exp δ) Υ_k = Φ_dt(ΔX) Υ_k · exp(Ad(Υ_k⁻¹) F δ),   A_k = Ad(Υ_k⁻¹) F,

exactly, not only to first order (Barrau and Bonnabel's log-linearity). Noise n = (n_ω, n_a) on
the samples perturbs the increment: Υ(u + n) = Υ(u) exp(B_k n + O(‖n‖²)) with, from the
factorisation above and exp(ξ + dξ) ≈ exp(ξ) exp(J_r(ξ) dξ),

    B_k = Ad(E⁻¹) ∂(P, 0, V)/∂u + J_r(ξ_E) ∂ξ_E/∂u,     E = exp(ξ_E),  u = (ω, a),

where ∂ξ_E/∂u is dt on the (ω, ω) block (and on (ν, a) for (3)), ∂V/∂a = dt I for Υ^F, and for
(3) ∂P/∂a = Γ₂(φ) dt² and ∂P/∂ω = dt³ ∂(Γ₂(φ) a)/∂φ (``gamma2_jacobian``). The covariance then
follows

    Σ_{k+1} = A_k Σ_k A_kᵀ + B_k Q B_kᵀ,   Σ_0 = 0,   Q = diag(σ_g² I, σ_a² I) / dt,

for white gyro and accelerometer noise of densities σ_g [rad/s/√Hz] and σ_a [m/s²/√Hz] (the
variance of one sample of a rate-1/dt IMU is σ²/dt). To first order δω is Forster's δφ, and
ΔR δρ and ΔR δν are his δp and δv (his covariance is this one conjugated by diag(ΔR, I, ΔR)).
GTSAM's NavState chart, (R Exp δθ, p + R δp, v + R δv), agrees with the right perturbation to
first order, so for Υ^F this Σ, reordered to (rotation, position, velocity), is the
``preintMeasCov`` of GTSAM's Forster integration.

What the script does and prints (everything in float64):

1. a helix with a rotating, banking body frame, whose states and IMU readings (gravity
   included) are known in closed form: the product of increments against the matrix
   exponential of the flow; the A_k and B_k of the scan against ``jax.jacfwd`` of the step
   through right perturbations; the preintegrated ΔR, Δv and Δp against the analytic ones, at
   the IMU rate and at a 10× finer step, with samples held from the start of each step (first
   order: the errors shrink 10×) and taken mid-step (second order for (3), 100×; still first
   order in Δv and Δp for Υ^F);
2. the covariance against a Monte Carlo of noisy runs (``jax.vmap`` over the runs): the ratio
   of empirical to predicted variance per block (position, rotation, velocity) with its
   standard error, the NEES (normalised estimation error squared, 9 on average) and the
   fraction of errors inside the ±3σ bounds;
3. GTSAM's ``imuAndGPSdata.csv`` (the IMU stream of its ImuFactorsExample: 200 Hz, no gravity
   in the readings, a ramp of forward acceleration, no rotation): the whole file preintegrated
   and propagated from its initial state against the file's GPS positions; where ``gtsam`` is
   installed, a window of it against ``gtsam.PreintegratedImuMeasurements``, and the helix
   (with rotation and gravity, ``PreintegrationParams.MakeSharedU``) against
   ``PreintegratedImuMeasurementsManifold`` (Forster's step) and against the default class,
   which integrates the rotation in its exponential coordinates instead (an Euler step of
   dθ/dτ = J_r⁻¹(θ) ω, so it departs from Π Exp(ω_k dt) at first order in dt), and GTSAM's
   ``predict`` against ``predict`` here;
4. a picture (``--out``): the trajectory, preintegrated and true, and the ±3σ bounds of the
   position and rotation errors against the Monte Carlo errors.

Run: ``python examples/imu_preintegration.py`` (8 s of data at 100 Hz, 1000 Monte Carlo runs;
about 30 s on two CPU cores, nearly all of it compiling); ``--quick`` or ``--small`` (2 s,
300 runs) is the tests' run; ``--imu-csv PATH`` reads the CSV where gtsam is not installed;
``--out`` moves the picture (default ``docs/gallery/imu_preintegration.png``).
"""

from __future__ import annotations

import argparse
import math
import time
from functools import partial
from pathlib import Path
from typing import Dict, NamedTuple, Optional, Tuple

import jax
import jax.numpy as jnp
import numpy as onp

from jaxlie_geo import SE23, SO3

GRAVITY = onp.array([0.0, 0.0, -9.81])  # world frame, z up [m/s²]
SIGMA_GYRO = 2e-3  # gyroscope white-noise density [rad/s/√Hz]
SIGMA_ACCEL = 2e-2  # accelerometer white-noise density [m/s²/√Hz]


# ---------------------------------------------------------------------------------------
# 1. The increment Υ_k, its Jacobians and the preintegration scan.


def _skew(w: jax.Array) -> jax.Array:
    zero = jnp.zeros_like(w[..., 0])
    return jnp.stack(
        [
            jnp.stack([zero, -w[..., 2], w[..., 1]], -1),
            jnp.stack([w[..., 2], zero, -w[..., 0]], -1),
            jnp.stack([-w[..., 1], w[..., 0], zero], -1),
        ],
        -2,
    )


_TAYLOR_BELOW = 0.1  # θ² under which the Γ₂ coefficients are taken from their series
_TAYLOR_TERMS = 8


def _gamma2_coefficients(theta_sq: jax.Array) -> Tuple[jax.Array, ...]:
    """α = (θ − sin θ)/θ³, β = (θ²/2 + cos θ − 1)/θ⁴ and their derivatives divided by θ,
    α'/θ and β'/θ, as functions of θ². Below θ² = 0.1 from their Taylor series (α = Σ (−θ²)ⁿ
    / (2n + 3)!, β = Σ (−θ²)ⁿ / (2n + 4)!; eight terms, truncation < 1e-20 relative), where
    the closed forms cancel; above it the closed forms lose at most ~1e-13 relative."""
    small = theta_sq < _TAYLOR_BELOW
    s = jnp.where(small, theta_sq, 0.0)  # the series' argument, kept small on both branches
    series = [jnp.zeros_like(theta_sq) for _ in range(4)]
    for n in range(_TAYLOR_TERMS):
        a_n = (-1.0) ** n / math.factorial(2 * n + 3)
        b_n = (-1.0) ** n / math.factorial(2 * n + 4)
        series[0] = series[0] + a_n * s**n
        series[1] = series[1] + b_n * s**n
        if n >= 1:  # d/dθ (c sⁿ) / θ = 2 n c sⁿ⁻¹
            series[2] = series[2] + 2 * n * a_n * s ** (n - 1)
            series[3] = series[3] + 2 * n * b_n * s ** (n - 1)
    # The closed forms, at a θ² that is never small (both branches are differentiated).
    t2 = jnp.where(small, 1.0, theta_sq)
    t = jnp.sqrt(t2)
    c, sn = jnp.cos(t), jnp.sin(t)
    alpha = (t - sn) / (t * t2)
    beta = (t2 / 2 + c - 1) / (t2 * t2)
    dalpha = (1 - c) / (t2 * t2) - 3 * (t - sn) / (t2 * t2 * t)
    dbeta = (t - sn) / (t2 * t2 * t) - 4 * (t2 / 2 + c - 1) / (t2 * t2 * t2)
    closed = (alpha, beta, dalpha, dbeta)
    return tuple(jnp.where(small, ser, clo) for ser, clo in zip(series, closed))


def gamma2(phi: jax.Array) -> jax.Array:
    """Γ₂(φ) = ∫₀¹ (1 − s) Exp(sφ) ds = ½ I + α φ̂ + β φ̂², ``(3,) -> (3, 3)``."""
    alpha, beta, _, _ = _gamma2_coefficients(jnp.sum(phi * phi, -1))
    W = _skew(phi)
    return 0.5 * jnp.eye(3, dtype=phi.dtype) + alpha * W + beta * (W @ W)


def gamma2_jacobian(phi: jax.Array, a: jax.Array) -> jax.Array:
    """∂(Γ₂(φ) a)/∂φ in closed form, ``(3,), (3,) -> (3, 3)``: with Γ₂ a = ½ a + α φ×a +
    β φ×(φ×a) and ∇α = (α'/θ) φ, ∇β = (β'/θ) φ,

        (α'/θ) (φ×a) φᵀ − α â + (β'/θ) (φ×(φ×a)) φᵀ − β ((φ×a)^ + φ̂ â)."""
    alpha, beta, dalpha, dbeta = _gamma2_coefficients(jnp.sum(phi * phi, -1))
    pa = jnp.cross(phi, a)
    ppa = jnp.cross(phi, pa)
    return (
        dalpha * jnp.outer(pa, phi)
        - alpha * _skew(a)
        + dbeta * jnp.outer(ppa, phi)
        - beta * (_skew(pa) + _skew(phi) @ _skew(a))
    )


def _blocks(rows) -> jax.Array:
    return jnp.concatenate([jnp.concatenate(r, axis=1) for r in rows], axis=0)


def _factors(omega: jax.Array, acc: jax.Array, dt: jax.Array, exact: bool):
    """(P, V, ξ_E) with Υ = exp((P, 0, V)) · exp(ξ_E), ξ_E = (0, φ, ν)."""
    phi, zero = omega * dt, jnp.zeros_like(omega)
    if exact:  # (Exp φ, Γ₂ a dt², Γ₁ a dt) = (I, Γ₂ a dt², 0) · exp((0, φ, a dt))
        return gamma2(phi) @ acc * dt**2, zero, jnp.concatenate([zero, phi, acc * dt])
    # Forster's (Exp φ, ½ a dt², a dt) = (I, ½ a dt², a dt) · exp((0, φ, 0))
    return 0.5 * acc * dt**2, acc * dt, jnp.concatenate([zero, phi, zero])


def increment(omega: jax.Array, acc: jax.Array, dt: jax.Array, exact: bool = True) -> SE23:
    """Υ_k for one sample (ω, a) held over dt: the zero-order-hold flow (3) if ``exact``, else
    Forster's (Exp(ω dt), ½ a dt², a dt)."""
    P, V, xi_E = _factors(omega, acc, dt, exact)
    return SE23.exp(jnp.concatenate([P, jnp.zeros_like(P), V])) @ SE23.exp(xi_E)


def noise_jacobian(omega: jax.Array, acc: jax.Array, dt: jax.Array, exact: bool = True):
    """B_k = ∂ log(Υ(u)⁻¹ Υ(u + n))/∂n at n = 0, ``(9, 6)``, n = (n_ω, n_a):
    Ad(E⁻¹) ∂(P, 0, V)/∂u + J_r(ξ_E) ∂ξ_E/∂u."""
    _, _, xi_E = _factors(omega, acc, dt, exact)
    Z, I = jnp.zeros((3, 3), omega.dtype), jnp.eye(3, dtype=omega.dtype)
    if exact:
        phi = omega * dt
        dT = _blocks([[gamma2_jacobian(phi, acc) * dt**3, gamma2(phi) * dt**2], [Z, Z], [Z, Z]])
        dxi = _blocks([[Z, Z], [I * dt, Z], [Z, I * dt]])
    else:
        dT = _blocks([[Z, I * (0.5 * dt**2)], [Z, Z], [Z, I * dt]])
        dxi = _blocks([[Z, Z], [I * dt, Z], [Z, Z]])
    return SE23.exp(xi_E).inverse().adjoint() @ dT + SE23.jac_right(xi_E) @ dxi


def time_shift(X: SE23, dt: jax.Array) -> SE23:
    """Φ_dt(R, p, v) = (R, p + v dt, v)."""
    return SE23.from_rotation_translation_and_velocity(
        X.rotation(), X.translation() + dt * X.velocity(), X.velocity()
    )


def time_shift_jacobian(dt: jax.Array, dtype=jnp.float64) -> jax.Array:
    """F: Φ_dt(X exp δ) = Φ_dt(X) exp(F δ), ``(9, 9)`` (ρ += ν dt)."""
    return jnp.eye(9, dtype=dtype).at[0:3, 6:9].set(dt * jnp.eye(3, dtype=dtype))


def step(X: SE23, omega: jax.Array, acc: jax.Array, dt: jax.Array, exact: bool = True) -> SE23:
    """One step of (2): X ↦ Φ_dt(X) Υ_k."""
    return time_shift(X, dt) @ increment(omega, acc, dt, exact)


def step_jacobians(
    upsilon: SE23, omega: jax.Array, acc: jax.Array, dt: jax.Array, exact: bool = True
) -> Tuple[jax.Array, jax.Array]:
    """A_k = Ad(Υ_k⁻¹) F and B_k of the step with increment ``upsilon``."""
    A = upsilon.inverse().adjoint() @ time_shift_jacobian(dt, omega.dtype)
    return A, noise_jacobian(omega, acc, dt, exact)


def noise_covariance(dt: jax.Array, sigma_gyro: float, sigma_accel: float, dtype=jnp.float64):
    """Q = diag(σ_g² I, σ_a² I) / dt, the covariance of one sample's noise (n_ω, n_a)."""
    var = jnp.asarray([sigma_gyro**2] * 3 + [sigma_accel**2] * 3, dtype=dtype)
    return jnp.diag(var) / dt


@partial(jax.jit, static_argnames=("exact",))
def preintegrate(
    omega: jax.Array,
    acc: jax.Array,
    dt: jax.Array,
    sigma_gyro: float = 0.0,
    sigma_accel: float = 0.0,
    exact: bool = True,
) -> Tuple[SE23, jax.Array, jax.Array, jax.Array]:
    """One ``lax.scan`` over the samples ``omega, acc`` ``(K, 3)``: the preintegrated
    ΔX_{0k}, an ``SE23`` of batch shape ``(K + 1,)`` (ΔX_{00} = identity), its covariance
    ``(K + 1, 9, 9)`` for right perturbations, and the Jacobians A_k ``(K, 9, 9)`` and B_k
    ``(K, 9, 6)`` of each step."""
    Q = noise_covariance(dt, sigma_gyro, sigma_accel, omega.dtype)

    def body(carry, u):
        X, S = carry
        upsilon = increment(u[:3], u[3:], dt, exact)
        A, B = step_jacobians(upsilon, u[:3], u[3:], dt, exact)
        X = time_shift(X, dt) @ upsilon
        S = A @ S @ A.T + B @ Q @ B.T
        return (X, S), (X, S, A, B)

    X0 = SE23.identity(dtype=omega.dtype)
    S0 = jnp.zeros((9, 9), omega.dtype)
    _, (Xs, Ss, As, Bs) = jax.lax.scan(body, (X0, S0), jnp.concatenate([omega, acc], -1))
    params = jnp.concatenate([X0.parameters()[None], Xs.parameters()])
    return SE23(params), jnp.concatenate([S0[None], Ss]), As, Bs


def _states(omega: jax.Array, acc: jax.Array, dt: jax.Array, exact: bool) -> SE23:
    """ΔX_{0k} for k = 0 … K without the covariance (inside the Monte Carlo's vmap)."""

    def body(X, u):
        X = step(X, u[:3], u[3:], dt, exact)
        return X, X

    X0 = SE23.identity(dtype=omega.dtype)
    _, Xs = jax.lax.scan(body, X0, jnp.concatenate([omega, acc], -1))
    return SE23(jnp.concatenate([X0.parameters()[None], Xs.parameters()]))


_states_jit = jax.jit(_states, static_argnames="exact")


@jax.jit
def predict(X_i: SE23, delta: SE23, dt_ij: jax.Array, gravity: jax.Array) -> SE23:
    """X_j = Γ_Δt Φ_Δt(X_i) ΔX_ij, Γ_Δt = (I, ½ g Δt², g Δt) (batch axes broadcast)."""
    dt = jnp.asarray(dt_ij)[..., None]
    gravity = jnp.broadcast_to(jnp.asarray(gravity, delta.parameters().dtype), (3,))
    rot = SO3.identity(dtype=delta.parameters().dtype)
    fall = SE23.from_rotation_translation_and_velocity(rot, 0.5 * gravity * dt**2, gravity * dt)
    return fall @ time_shift(X_i, dt) @ delta


# ---------------------------------------------------------------------------------------
# 2. Checks of the step: exactness (matrix exponential of the flow) and Jacobians (jacfwd).


def flow_by_expm(omega, acc, dt: float) -> onp.ndarray:
    """The exact flow for inputs held over each step, as a 5×5 matrix, in NumPy/SciPy and
    independent of SE23 and of (3): X ← e^{−N dt} X e^{(Û + N) dt}, Û = hat(0, ω, a),
    N[4, 3] = 1, from X = I."""
    import scipy.linalg

    N = onp.zeros((5, 5))
    N[4, 3] = 1.0
    shift_back = scipy.linalg.expm(-N * dt)
    M = onp.eye(5)
    for w, a in zip(onp.asarray(omega), onp.asarray(acc)):
        U = N.copy()
        U[:3, :3] = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
        U[:3, 4] = a
        M = shift_back @ M @ scipy.linalg.expm(U * dt)
    return M


def _local(M: jax.Array) -> jax.Array:
    """vee(M − I) for a 5×5 M near the identity, log's first-order term: differentiated at
    M = I it gives the derivative of log (and costs far less to compile)."""
    return jnp.concatenate([M[:3, 3], jnp.stack([M[2, 1], M[0, 2], M[1, 0]]), M[:3, 4]])


@partial(jax.jit, static_argnames=("exact",))
def jacobian_check(params, omega, acc, dt, A, B, exact: bool = True):
    """max |A_k − jacfwd| and max |B_k − jacfwd|, relative to the largest entry, over a batch
    of steps: states ΔX_k (parameters, ``(n, 10)``), samples ``(n, 3)``, the step ``dt`` and
    the A_k ``(n, 9, 9)`` and B_k ``(n, 9, 6)`` that ``preintegrate`` used. The reference is
    ``jax.jacfwd`` of one step through right perturbations, at 0: δ ↦ log(X₁⁻¹ step(X exp δ))
    and n ↦ log(X₁⁻¹ step(X; ω + n_ω, a + n_a)), X₁ = step(X)."""

    def one(p, w, a, A, B):
        X = SE23(p)
        upsilon, shifted = increment(w, a, dt, exact), time_shift(X, dt)
        X1_inv = (shifted @ upsilon).inverse()

        def through_state(delta):  # step(X exp δ) = Φ_dt(X exp δ) Υ
            return _local((X1_inv @ time_shift(X @ SE23.exp(delta), dt) @ upsilon).as_matrix())

        def through_input(n):  # step(X; u + n) = Φ_dt(X) Υ(u + n)
            return _local(
                (X1_inv @ shifted @ increment(w + n[:3], a + n[3:], dt, exact)).as_matrix()
            )

        A_ad = jax.jacfwd(through_state)(jnp.zeros(9, p.dtype))
        B_ad = jax.jacfwd(through_input)(jnp.zeros(6, p.dtype))
        relative = lambda J, J_ad: jnp.max(jnp.abs(J - J_ad)) / jnp.max(jnp.abs(J_ad))
        return relative(A, A_ad), relative(B, B_ad)

    err_A, err_B = jax.vmap(one)(params, omega, acc, A, B)
    return jnp.max(err_A), jnp.max(err_B)


def jacobian_errors(helix: "Helix", K: int, rate: float) -> Tuple[float, float]:
    """``jacobian_check`` at three steps of K helix samples at ``rate`` (θ = ‖ω‖ dt < 0.01 at
    100 Hz: Γ₂ from its series) and at 1 Hz (θ from 0.6 to 0.9: its closed form), both
    increments."""
    errors = []
    ks = onp.array([0, 7, K // 2 + 3])
    for step_rate in (rate, 1.0):
        omega, acc, dt = helix_samples(helix, K / step_rate, step_rate, midpoint=False)
        for exact in (True, False):
            X, _, A, B = preintegrate(omega, acc, dt, SIGMA_GYRO, SIGMA_ACCEL, exact=exact)
            got = jacobian_check(X.parameters()[ks], omega[ks], acc[ks], dt, A[ks], B[ks], exact)
            errors.append([float(e) for e in got])
    return max(e[0] for e in errors), max(e[1] for e in errors)


# ---------------------------------------------------------------------------------------
# 3. A helix with an analytic ground truth.


def _quat_matrix(q: onp.ndarray) -> onp.ndarray:
    """Rotation matrices of unit quaternions (w, x, y, z), NumPy, ``(…, 4) -> (…, 3, 3)``."""
    w, x, y, z = onp.moveaxis(q, -1, 0)
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return onp.stack([onp.stack(r, -1) for r in rows], -2)


def _quat_multiply(a: onp.ndarray, b: onp.ndarray) -> onp.ndarray:
    aw, ax, ay, az = onp.moveaxis(a, -1, 0)
    bw, bx, by, bz = onp.moveaxis(b, -1, 0)
    return onp.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def _quat_axis(angle: onp.ndarray, axis: int) -> onp.ndarray:
    q = onp.zeros((*onp.shape(angle), 4))
    q[..., 0] = onp.cos(angle / 2)
    q[..., 1 + axis] = onp.sin(angle / 2)
    return q


def matrices(X: SE23) -> onp.ndarray:
    """The 5×5 matrices of extended poses, computed in NumPy from the parameters."""
    x = onp.asarray(X.parameters())
    M = onp.zeros((*x.shape[:-1], 5, 5))
    M[..., :3, :3] = _quat_matrix(x[..., :4])
    M[..., :3, 3], M[..., :3, 4] = x[..., 4:7], x[..., 7:10]
    M[..., 3, 3] = M[..., 4, 4] = 1.0
    return M


def rotation_angle(R: onp.ndarray) -> onp.ndarray:
    """The angle of rotation matrices, from the skew part and the trace (accurate near 0)."""
    skew = onp.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0]], -1)
    skew = onp.concatenate([skew, (R[..., 1, 0] - R[..., 0, 1])[..., None]], -1)
    return onp.arctan2(
        onp.linalg.norm(skew, axis=-1) / 2, (onp.trace(R, axis1=-2, axis2=-1) - 1) / 2
    )


class Helix(NamedTuple):
    """A helical climb around the z axis, bobbing up and down, with the body banking and
    pitching as it turns: position, velocity, acceleration, attitude and body rates in closed
    form."""

    radius: float = 4.0  # [m]
    period: float = 10.0  # one turn [s]
    climb: float = 0.5  # [m/s]
    bob: float = 0.3  # vertical oscillation at twice the turn rate [m]
    roll: float = 0.3  # banking amplitude, at three times the turn rate [rad]
    pitch: float = 0.2  # pitch amplitude, at twice the turn rate [rad]

    def state(self, t) -> Dict[str, onp.ndarray]:
        """At times t: attitude R (…, 3, 3) and q (w, x, y, z), position p, velocity v, world
        acceleration a and body angular velocity ω (…, 3). R = R_z(ψ) R_y(θ) R_x(φ) with yaw
        ψ = Ωt + π/2 (along the circle), pitch θ = θ₀ sin 2Ωt and roll φ = φ₀ sin 3Ωt; ω are the
        body rates of these Z-Y-X Euler angles."""
        t = onp.asarray(t, dtype=onp.float64)
        W = 2 * onp.pi / self.period
        r, c, h = self.radius, self.climb, self.bob
        cw, sw = onp.cos(W * t), onp.sin(W * t)
        p = onp.stack([r * cw, r * sw, c * t + h * onp.sin(2 * W * t)], -1)
        v = onp.stack([-r * W * sw, r * W * cw, c + 2 * h * W * onp.cos(2 * W * t)], -1)
        a = onp.stack([-r * W**2 * cw, -r * W**2 * sw, -4 * h * W**2 * onp.sin(2 * W * t)], -1)
        yaw, dyaw = W * t + onp.pi / 2, W + 0 * t
        pitch, dpitch = self.pitch * onp.sin(2 * W * t), 2 * W * self.pitch * onp.cos(2 * W * t)
        roll, droll = self.roll * onp.sin(3 * W * t), 3 * W * self.roll * onp.cos(3 * W * t)
        q = _quat_multiply(
            _quat_multiply(_quat_axis(yaw, 2), _quat_axis(pitch, 1)), _quat_axis(roll, 0)
        )
        omega = onp.stack(
            [
                droll - dyaw * onp.sin(pitch),
                dpitch * onp.cos(roll) + dyaw * onp.cos(pitch) * onp.sin(roll),
                -dpitch * onp.sin(roll) + dyaw * onp.cos(pitch) * onp.cos(roll),
            ],
            -1,
        )
        return {"R": _quat_matrix(q), "q": q, "p": p, "v": v, "a": a, "omega": omega}

    def imu(self, t, gravity: onp.ndarray = GRAVITY) -> Tuple[onp.ndarray, onp.ndarray]:
        """Noise-free gyroscope and accelerometer readings at times t: ω and Rᵀ(a − g)."""
        s = self.state(t)
        return s["omega"], onp.einsum("...ji,...j->...i", s["R"], s["a"] - gravity)

    def extended_pose(self, t) -> SE23:
        """The true state (R, p, v) at times t as an ``SE23``."""
        s = self.state(t)
        return SE23(jnp.asarray(onp.concatenate([s["q"], s["p"], s["v"]], -1)))


def analytic_delta(helix: Helix, t_i: float, t_j: float, gravity=GRAVITY):
    """The preintegrated (ΔR, Δv, Δp) between the true states at t_i and t_j."""
    s_i, s_j, dt = helix.state(t_i), helix.state(t_j), t_j - t_i
    Ri = s_i["R"]
    dv = Ri.T @ (s_j["v"] - s_i["v"] - gravity * dt)
    dp = Ri.T @ (s_j["p"] - s_i["p"] - s_i["v"] * dt - 0.5 * gravity * dt**2)
    return Ri.T @ s_j["R"], dv, dp


def delta_errors(M: onp.ndarray, want) -> onp.ndarray:
    """(angle of ΔR_wantᵀ ΔR, |Δv − Δv_want|, |Δp − Δp_want|) of a 5×5 ΔX."""
    dR, dv, dp = want
    return onp.array(
        [
            rotation_angle(dR.T @ M[:3, :3]),
            onp.linalg.norm(M[:3, 4] - dv),
            onp.linalg.norm(M[:3, 3] - dp),
        ]
    )


def helix_samples(helix: Helix, duration: float, rate: float, midpoint: bool):
    """(ω, a) at K = duration·rate instants, held over steps of dt = 1/rate: taken at the start
    of each step (an IMU's zero-order hold) or mid-step."""
    K = int(round(duration * rate))
    dt = 1.0 / rate
    omega, acc = helix.imu((onp.arange(K) + (0.5 if midpoint else 0.0)) * dt)
    return jnp.asarray(omega), jnp.asarray(acc), jnp.asarray(dt)


_final_states = jax.jit(
    lambda omega, acc, dt, exact: _states(omega, acc, dt, exact)[-1], static_argnames="exact"
)


def convergence_table(helix: Helix, duration: float, rate: float) -> Dict[Tuple, onp.ndarray]:
    """Errors of (ΔR, Δv, Δp) over [0, duration] against the analytic values, keyed by
    (exact, midpoint, factor): the exact increment with start-of-step and mid-step samples and
    Forster's with mid-step samples, at the IMU rate (factor 1) and 10× finer (factor 10)."""
    want = analytic_delta(helix, 0.0, duration)
    table = {}
    for exact, midpoint in ((True, False), (True, True), (False, True)):
        omega, acc, dt = helix_samples(helix, duration, rate, midpoint)
        X = preintegrate(omega, acc, dt, SIGMA_GYRO, SIGMA_ACCEL, exact=exact)[0][-1]
        table[exact, midpoint, 1] = delta_errors(matrices(X), want)
        omega, acc, dt = helix_samples(helix, duration, 10 * rate, midpoint)
        X = _final_states(omega, acc, dt, exact)
        table[exact, midpoint, 10] = delta_errors(matrices(X), want)
    return table


# ---------------------------------------------------------------------------------------
# 4. Monte Carlo.


@partial(jax.jit, static_argnames=("runs", "exact"))
def monte_carlo(
    key, nominal: SE23, omega, acc, dt, sigma_gyro, sigma_accel, runs: int, exact: bool = True
):
    """``runs`` noisy preintegrations (white noise of the given densities on every sample),
    one ``jax.vmap`` over the runs: their right-perturbation errors δ_k = log(ΔX_k⁻¹ ΔX̃_k)
    from the noise-free ``nominal`` ΔX_k, ``(runs, K + 1, 9)``, and the noisy ΔX̃ of the
    first three runs."""
    K = omega.shape[0]
    scale = jnp.asarray([sigma_gyro] * 3 + [sigma_accel] * 3) / jnp.sqrt(dt)
    noise = jax.random.normal(key, (runs, K, 6), omega.dtype) * scale
    noisy = jax.vmap(lambda n: _states(omega + n[:, :3], acc + n[:, 3:], dt, exact))(noise)
    return (nominal.inverse() @ noisy).log(), noisy[:3]


BLOCKS = {"position": slice(0, 3), "rotation": slice(3, 6), "velocity": slice(6, 9)}


def variance_ratios(errors: onp.ndarray, Sigma: onp.ndarray) -> Dict[str, Tuple[float, float]]:
    """Per block b: tr(S_b)/tr(Σ_b), S = mean δδᵀ over the runs (the mean is known: zero),
    and its standard error sqrt(2 tr(Σ_b²)/N)/tr(Σ_b) for Gaussian δ."""
    N = errors.shape[0]
    out = {}
    for name, b in BLOCKS.items():
        Sb = Sigma[b, b]
        ratio = onp.mean(onp.sum(errors[:, b] ** 2, -1)) / onp.trace(Sb)
        out[name] = (float(ratio), float(onp.sqrt(2 * onp.trace(Sb @ Sb) / N) / onp.trace(Sb)))
    return out


# ---------------------------------------------------------------------------------------
# 5. GTSAM's imuAndGPSdata.csv and the comparison with gtsam.


def _gtsam():
    try:
        import gtsam
    except ImportError:
        return None
    return gtsam


def read_imu_csv(path: Path) -> Dict[str, onp.ndarray]:
    """GTSAM's ImuFactorsExample format. The first row, ``i,…``, is the initial state
    (N, E, D, v_N, v_E, v_D, q_x, q_y, q_z, q_w) — the only reading of its ten numbers in which
    the quaternion is a unit one; rows ``0,…`` are IMU samples (a_x, a_y, a_z, ω_x, ω_y, ω_z),
    body frame, one every 5 ms; rows ``1,…`` are GPS fixes (N, E, D, q_x, q_y, q_z, q_w) taken
    after the IMU rows above them."""
    imu, gps, gps_index, initial = [], [], [], None
    for line in Path(path).read_text().splitlines():
        fields = line.strip().split(",")
        if fields[0] == "i":
            initial = onp.array(fields[1:], dtype=onp.float64)
        elif fields[0] == "0":
            imu.append(onp.array(fields[1:], dtype=onp.float64))
        elif fields[0] == "1":
            gps.append(onp.array(fields[1:], dtype=onp.float64))
            gps_index.append(len(imu))
    if initial is None or initial.shape != (10,) or abs(onp.linalg.norm(initial[6:]) - 1) > 1e-9:
        raise ValueError(f"{path}: no initial state row 'i,…' with a unit quaternion")
    return {
        "imu": onp.stack(imu),
        "gps": onp.stack(gps),
        "gps_index": onp.array(gps_index),
        "x0": onp.concatenate([initial[9:10], initial[6:9], initial[0:3], initial[3:6]]),
        "dt": 0.005,
    }


def gtsam_preintegrate(gtsam, omega, acc, dt, sigma_gyro, sigma_accel, gravity, variant=""):
    """``gtsam.PreintegratedImuMeasurements{variant}`` over the samples, zero bias, noise of
    the given densities (GTSAM takes continuous-time covariances and divides them by dt), no
    integration noise. ``MakeSharedU(g)``: z up, navigation-frame gravity (0, 0, −g)."""
    if gravity[0] != 0.0 or gravity[1] != 0.0 or gravity[2] > 0.0:
        raise ValueError(f"gravity {gravity} is not (0, 0, -g)")
    params = gtsam.PreintegrationParams.MakeSharedU(float(-gravity[2]))
    params.setGyroscopeCovariance(sigma_gyro**2 * onp.eye(3))
    params.setAccelerometerCovariance(sigma_accel**2 * onp.eye(3))
    params.setIntegrationCovariance(onp.zeros((3, 3)))
    pim = getattr(gtsam, "PreintegratedImuMeasurements" + variant)(
        params, gtsam.imuBias.ConstantBias()
    )
    for w, a in zip(onp.asarray(omega), onp.asarray(acc)):
        pim.integrateMeasurement(a, w, float(dt))  # (measuredAcc, measuredOmega, dt)
    return pim


def compare_with_gtsam(pim, M: onp.ndarray, Sigma: Optional[onp.ndarray] = None) -> onp.ndarray:
    """max |ours − GTSAM| of ΔR (as matrices), Δv and Δp, for a 5×5 ΔX, and given Σ, of the
    covariance relative to its largest entry (GTSAM's order: rotation, position, velocity)."""
    out = [
        onp.max(onp.abs(M[:3, :3] - pim.deltaRij().matrix())),
        onp.max(onp.abs(M[:3, 4] - pim.deltaVij())),
        onp.max(onp.abs(M[:3, 3] - pim.deltaPij())),
    ]
    if Sigma is not None:
        order = onp.r_[3:6, 0:3, 6:9]
        ours = Sigma[onp.ix_(order, order)]
        out.append(onp.max(onp.abs(ours - pim.preintMeasCov())) / onp.max(onp.abs(ours)))
    return onp.array(out)


def run_csv(path: Path, window: Tuple[int, int], gtsam) -> Dict[str, object]:
    """The whole file preintegrated, X_j = Γ Φ(X_0) ΔX_0j from its initial state with zero
    gravity (the file's accelerometer readings have none; its ImuFactorsExample uses
    MakeSharedD(0.0)), against its GPS positions; and, with gtsam, a window of samples against
    ``gtsam.PreintegratedImuMeasurements``, with Forster's increment."""
    data = read_imu_csv(path)
    dt = jnp.asarray(data["dt"])
    acc, omega = jnp.asarray(data["imu"][:, :3]), jnp.asarray(data["imu"][:, 3:])
    idx = data["gps_index"]
    deltas = _states_jit(omega, acc, dt, True)[idx]
    states = predict(SE23(jnp.asarray(data["x0"])), deltas, jnp.asarray(idx * data["dt"]), 0.0)
    gps_error = onp.max(onp.abs(matrices(states)[:, :3, 3] - data["gps"][:, :3]))
    out: Dict[str, object] = {
        "samples": data["imu"].shape[0],
        "fixes": idx.shape[0],
        "gps_error": float(gps_error),
        "distance": float(onp.linalg.norm(data["gps"][-1, :3] - data["gps"][0, :3])),
        "max_gyro": float(onp.max(onp.abs(data["imu"][:, 3:]))),
        "dt": data["dt"],
    }
    if gtsam is not None:
        a, b = window
        X, Sigma, _, _ = preintegrate(
            omega[a:b], acc[a:b], dt, SIGMA_GYRO, SIGMA_ACCEL, exact=False
        )
        pim = gtsam_preintegrate(
            gtsam, omega[a:b], acc[a:b], data["dt"], SIGMA_GYRO, SIGMA_ACCEL, onp.zeros(3)
        )
        out["gtsam"] = compare_with_gtsam(pim, matrices(X[-1]), onp.asarray(Sigma[-1]))
    return out


def gtsam_helix(gtsam, helix: Helix, duration: float, omega, acc, dt, runs) -> Dict:
    """The helix (rotation and gravity) against GTSAM: Forster's increment against GTSAM's
    Forster integration (``…Manifold``, where the installed gtsam has it) and against the
    default class (which integrates the rotation in its tangent space instead); GTSAM's
    ``predict`` from the true state at 0 against ours (``predict``, from the same ΔX) and the
    analytic state at ``duration``. ``runs``: our (exact, Forster) ΔX and Σ."""
    (X, *_), (X_forster, Sigma_forster, *_) = runs
    kw = dict(sigma_gyro=SIGMA_GYRO, sigma_accel=SIGMA_ACCEL, gravity=GRAVITY)
    M, M_forster = matrices(X[-1]), matrices(X_forster[-1])
    out = {}
    pim = gtsam_preintegrate(gtsam, omega, acc, dt, **kw)
    out["forster_vs_default"] = compare_with_gtsam(pim, M_forster)
    out["exact_vs_default"] = compare_with_gtsam(pim, M)
    out["predict_class"] = "PreintegratedImuMeasurements"
    if hasattr(gtsam, "PreintegratedImuMeasurementsManifold"):
        pim = gtsam_preintegrate(gtsam, omega, acc, dt, variant="Manifold", **kw)
        Sigma = onp.asarray(Sigma_forster[-1])
        out["forster_vs_manifold"] = compare_with_gtsam(pim, M_forster, Sigma)
        out["predict_class"] += "Manifold"
    s0, s1 = helix.state(0.0), helix.state(duration)
    nav = pim.predict(
        gtsam.NavState(gtsam.Rot3(s0["R"]), s0["p"], s0["v"]), gtsam.imuBias.ConstantBias()
    )
    ours = matrices(predict(helix.extended_pose(0.0), X_forster[-1], duration, GRAVITY))
    R_nav = nav.attitude().matrix()
    out["predict_vs_ours"] = onp.array(
        [
            onp.max(onp.abs(R_nav - ours[:3, :3])),
            onp.max(onp.abs(nav.velocity() - ours[:3, 4])),
            onp.max(onp.abs(nav.position() - ours[:3, 3])),
        ]
    )
    out["predict_vs_truth"] = onp.array(
        [
            rotation_angle(s1["R"].T @ R_nav),
            onp.linalg.norm(nav.velocity() - s1["v"]),
            onp.linalg.norm(nav.position() - s1["p"]),
        ]
    )
    return out


# ---------------------------------------------------------------------------------------
# 6. The picture.


def draw(
    path: Path,
    helix: Helix,
    world: onp.ndarray,
    t: onp.ndarray,
    Sigma: onp.ndarray,
    errors: onp.ndarray,
    ratios: Dict[str, Tuple[float, float]],
    n_runs_drawn: int = 40,
) -> None:
    """``world``: 5×5 matrices (runs, K + 1, 5, 5), the noise-free run first."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(14, 7.2), dpi=130)
    gs = fig.add_gridspec(
        1, 2, width_ratios=[1.0, 1.4], wspace=0.2, left=0.01, right=0.985, top=0.84, bottom=0.08
    )
    ax = fig.add_subplot(gs[0, 0], projection="3d")
    dense = helix.state(onp.linspace(t[0], t[-1], 600))["p"]
    ax.plot(*dense.T, color="0.1", lw=1.0, ls=(0, (4, 2)), label="ground truth", zorder=3)
    p = world[0, :, :3, 3]
    dt_ms = 1e3 * (t[1] - t[0])
    label = f"preintegrated, noise-free samples held over {dt_ms:g} ms steps"
    ax.plot(*p.T, color="#2166ac", lw=2.0, alpha=0.85, label=label)
    for r in range(1, world.shape[0]):
        label = "preintegrated, noisy samples (three runs)" if r == 1 else None
        ax.plot(*world[r, :, :3, 3].T, color="#e6873c", lw=0.8, alpha=0.8, label=label)
    step = max(1, len(t) // 8)
    length = 0.12 * float(onp.max(dense.max(0) - dense.min(0)))
    for k in range(0, len(t), step):
        for axis, rgb in enumerate(("#d62728", "#2ca02c", "#1f3fbf")):
            tip = p[k] + length * world[0, k, :3, axis]
            ax.plot(*onp.stack([p[k], tip]).T, color=rgb, lw=1.6)
    lo, hi = dense.min(0) - 1.0, dense.max(0) + 1.0
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
    ax.set_box_aspect(hi - lo)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.view_init(elev=28, azim=-58)
    ax.legend(loc="upper left", fontsize=8.5, framealpha=0.9)
    ax.set_title(
        r"$X_k = \Gamma_{t_k}\,\Phi_{t_k}(X_0)\,\Delta X_{0k}$ (body axes: red x, green y, blue z)",
        fontsize=10,
    )

    grid = gs[0, 1].subgridspec(2, 3, hspace=0.28, wspace=0.32)
    sigma = onp.sqrt(onp.maximum(onp.diagonal(Sigma, axis1=-2, axis2=-1), 0.0))
    shown = min(n_runs_drawn, errors.shape[0])
    rows = ((0, 100.0, "cm", r"\delta\rho"), (3, onp.rad2deg(1.0), "deg", r"\delta\omega"))
    for row, (start, scale, unit, sym) in enumerate(rows):
        for c in range(3):
            axe = fig.add_subplot(grid[row, c])
            i = start + c
            for r in range(shown):
                axe.plot(t, scale * errors[r, :, i], color="0.55", lw=0.5, alpha=0.6)
            axe.plot(t, 3 * scale * sigma[:, i], color="#b2182b", lw=1.8)
            axe.plot(t, -3 * scale * sigma[:, i], color="#b2182b", lw=1.8)
            axe.set_title(rf"${sym}_{'xyz'[c]}$ [{unit}]", fontsize=9.5)
            axe.grid(True, lw=0.4, alpha=0.5)
            if row == 1:
                axe.set_xlabel("t [s]")
    listed = ", ".join(f"{k} {v:.2f} ± {s:.2f}" for k, (v, s) in ratios.items())
    fig.suptitle(
        r"IMU preintegration as a product of SE$_2$(3) increments, "
        r"$\Delta X_{k+1} = \Phi_{dt}(\Delta X_k)\,\Upsilon_k$"
        "\n"
        f"right: errors δ (ΔX̃ = ΔX exp δ) of {shown} of {errors.shape[0]} Monte Carlo runs "
        f"(grey) and ±3σ of the propagated covariance (red)\n"
        f"empirical / predicted variance at t = {t[-1]:g} s: {listed}",
        fontsize=10.5,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------


def _row(label: str, e: onp.ndarray) -> str:
    return f"  {label:<44} {e[0]:9.2e} {e[1]:9.2e} {e[2]:9.2e}"


def main(argv=None) -> None:
    jax.config.update("jax_enable_x64", True)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", "--small", dest="small", action="store_true", help="2 s, 300 Monte Carlo runs"
    )
    parser.add_argument("--duration", type=float, default=None, help="window [s] (default 8)")
    parser.add_argument("--rate", type=float, default=100.0, help="IMU rate [Hz]")
    parser.add_argument("--runs", type=int, default=None, help="Monte Carlo runs (default 1000)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--imu-csv", type=Path, default=None, help="imuAndGPSdata.csv")
    parser.add_argument("--out", type=Path, default=Path("docs/gallery/imu_preintegration.png"))
    args = parser.parse_args(argv)
    duration = args.duration or (2.0 if args.small else 8.0)
    runs = args.runs or (300 if args.small else 1000)
    helix = Helix()
    start = time.perf_counter()

    # -- 1. The helix: exactness, Jacobians, agreement with the analytic values. -------------
    omega, acc, dt = helix_samples(helix, duration, args.rate, midpoint=False)
    K = omega.shape[0]
    print(
        f"Helix: {duration:g} s at {args.rate:g} Hz ({K} IMU samples), gravity "
        f"{-GRAVITY[2]:g} m/s² in the accelerometer readings"
    )
    ours = [preintegrate(omega, acc, dt, SIGMA_GYRO, SIGMA_ACCEL, exact=e) for e in (True, False)]
    X, Sigma = ours[0][0], onp.asarray(ours[0][1])
    flow = flow_by_expm(omega, acc, float(dt))
    gap = [onp.max(onp.abs(matrices(Y[-1]) - flow)) for Y, *_ in ours]
    print(
        f"Product of increments vs the matrix exponential of the flow, max |5x5 difference| "
        f"after {K} steps: exact increment {gap[0]:.1e}, Forster's {gap[1]:.1e}"
    )
    jac_A, jac_B = jacobian_errors(helix, K, args.rate)
    print(
        f"Step Jacobians (3 steps at {args.rate:g} Hz, 3 at 1 Hz, both increments) vs jax.jacfwd "
        f"through X ⊕ δ: max |A_k - jacfwd| {jac_A:.1e}, "
        f"max |B_k - jacfwd| {jac_B:.1e} (relative to the largest entry)"
    )
    table = convergence_table(helix, duration, args.rate)
    print(
        f"Preintegrated vs analytic over [0, {duration:g}] s:{'':<13}|ΔR| rad  |Δv| m/s    |Δp| m"
    )
    names = {
        (True, False): "exact increment, samples at step start",
        (True, True): "exact increment, samples mid-step",
        (False, True): "Forster's increment, samples mid-step",
    }
    ms = 1e3 / args.rate
    for key, name in names.items():
        e1, e10 = table[(*key, 1)], table[(*key, 10)]
        ratio = e1 / e10
        print(f" {name}:")
        print(_row(f"dt = {ms:g} ms", e1))
        print(_row(f"dt = {ms / 10:g} ms", e10))
        print(f"  {'ratio (10x finer step)':<44} {ratio[0]:9.1f} {ratio[1]:9.1f} {ratio[2]:9.1f}")

    # -- 2. Covariance against a Monte Carlo. ------------------------------------------------
    key = jax.random.key(args.seed)
    errors, noisy = monte_carlo(key, X, omega, acc, dt, SIGMA_GYRO, SIGMA_ACCEL, runs)
    errors = onp.asarray(errors)
    ratios = variance_ratios(errors[:, -1], Sigma[-1])
    whitened = onp.linalg.solve(Sigma[-1], errors[:, -1].T).T
    nees = float(onp.mean(onp.sum(errors[:, -1] * whitened, -1)))
    sigma = onp.sqrt(onp.diagonal(Sigma[1:], axis1=-2, axis2=-1))
    inside = float(onp.mean(onp.abs(errors[:, 1:]) <= 3 * sigma))
    print(
        f"Monte Carlo, {runs} runs, white noise {SIGMA_GYRO:g} rad/s/√Hz (gyro), "
        f"{SIGMA_ACCEL:g} m/s²/√Hz (accel):"
    )
    listed = ", ".join(f"{k} {v:.3f} ± {s:.3f}" for k, (v, s) in ratios.items())
    print(f"  empirical / predicted variance at t = {duration:g} s: {listed}")
    print(f"  NEES {nees:.2f} (expected 9 ± {math.sqrt(18 / runs):.2f})")
    print(f"  errors inside ±3σ: {100 * inside:.2f}% of components, all steps (Gaussian: 99.73%)")

    # -- 3. GTSAM's IMU data, and GTSAM itself. -------------------------------------------
    gtsam = _gtsam()
    csv = args.imu_csv
    if csv is None and gtsam is not None:
        csv = Path(gtsam.findExampleDataFile("imuAndGPSdata.csv"))
    if csv is None:
        print("no imuAndGPSdata.csv: gtsam is not installed (pip install gtsam) and no --imu-csv")
    else:
        window = (2000, 2000 + K)  # K samples from t = 10 s
        r = run_csv(csv, window, gtsam)
        print(
            f"imuAndGPSdata.csv: {r['samples']} IMU samples at {1 / r['dt']:g} Hz "
            f"(max |gyro| {r['max_gyro']:g} rad/s), {r['fixes']} GPS fixes over "
            f"{r['distance']:.0f} m"
        )
        print(
            f"  whole file preintegrated, X_j = Γ Φ(X_0) ΔX_0j: max |position - GPS| over the "
            f"fixes {r['gps_error']:.1e} m (the file has 6 decimals)"
        )
        if gtsam is not None:
            g = r["gtsam"]
            print(
                f"  samples {window[0]}-{window[1]}, Forster's increment vs "
                f"gtsam.PreintegratedImuMeasurements: max |ΔR| {g[0]:.1e}, |Δv| {g[1]:.1e} m/s, "
                f"|Δp| {g[2]:.1e} m; covariance {g[3]:.1e} (relative)"
            )
    if gtsam is None:
        print(
            "gtsam not installed: skipping the comparison with gtsam.PreintegratedImuMeasurements"
        )
    else:
        h = gtsam_helix(gtsam, helix, duration, omega, acc, dt, ours)
        print(f"Helix vs gtsam (MakeSharedU({-GRAVITY[2]:g})), max |difference| of ΔR, Δv, Δp:")
        if "forster_vs_manifold" in h:
            g = h["forster_vs_manifold"]
            print(
                f"  Forster's increment vs PreintegratedImuMeasurementsManifold: {g[0]:.1e}, "
                f"{g[1]:.1e}, {g[2]:.1e}; covariance {g[3]:.1e} (relative)"
            )
        for key, name in (("forster_vs_default", "Forster's"), ("exact_vs_default", "exact")):
            g = h[key]
            print(
                f"  {name} increment vs PreintegratedImuMeasurements (tangent-space rotation): "
                f"{g[0]:.1e}, {g[1]:.1e}, {g[2]:.1e}"
            )
        g, t = h["predict_vs_ours"], h["predict_vs_truth"]
        print(
            f"  {h['predict_class']}.predict() from the true state at 0 vs ours: "
            f"{g[0]:.1e}, {g[1]:.1e}, {g[2]:.1e}; "
            f"vs the analytic state: R {t[0]:.1e} rad, v {t[1]:.1e} m/s, p {t[2]:.1e} m"
        )

    # -- 4. Picture: the noise-free run and three noisy ones, in the world frame. ---------------
    t = onp.arange(K + 1) * float(dt)
    runs4 = SE23(jnp.concatenate([X.parameters()[None], noisy.parameters()]))
    world = matrices(predict(helix.extended_pose(0.0), runs4, t, GRAVITY))
    draw(args.out, helix, world, t, Sigma, errors, ratios)
    print(f"Wrote {args.out} ({time.perf_counter() - start:.1f} s in all)")


if __name__ == "__main__":
    main()
