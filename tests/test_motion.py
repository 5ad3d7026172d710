"""jaxlie_geo.motion: constant body velocity between poses (Zhang, *A Geometric Introduction
to Lie Theory* (2022), §5–§9; the time-scaled logarithm ln_τ R of SO(3)).

A body with constant body-frame velocity ξ follows T(t) = T₀ exp(t ξ), the solution of the
ODE dT/dt = T hat(ξ). ``velocity_between(a, b, T)`` = log(a⁻¹ b)/T and
``pose_at(a, ξ, t)`` = a exp(t ξ). We check, in float64:

* round trips for every group (batched, negative durations, numpy-style broadcasting of
  durations and times, as ``interpolate`` does);
* the time-scaled logarithm ln_τ R of SO(3) from the trace and the skew part, and the
  time-scaled Rodrigues formula exp(ŵ τ) it inverts;
* Zhang (2022), §5: the SE(2) arc both ways, with the chord corrected (AB = (R − I)·OA;
  the text has I − R), and the §5.4 worked example v = (π/4)(1, −1) at θ = π/2, t = (1, 0)
  (the text prints (π/4)(1, 1), a consequence of the same slip);
* the duck game (Zhang (2022), §6.5) against a direct RK4 integration of
  dT/dt = T hat(ξ) on the homogeneous matrix, for the SE groups, and rotations far beyond π
  for every group;
* geodesic == constant-velocity path;
* the library's SE(3) translation kernels (split along and across the axis) agree to a few
  ulp with the textbook forms of Barfoot (2017), eqs. 7.82 and 7.85;
* zero durations, type errors, and jit / vmap / grad.

Conventions: tangents follow jaxlie — SE2 ``(vx, vy, ω)``, SE3 ``(v, ω)`` — not the
rotation-first order of Eberly, *Lie Groups and Lie Algebras* (Geometric Tools, 2024).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import (
    LAYOUT,
    has_scale,
    has_translation,
    hat_ref,
    over_groups,
    over_se_groups,
    rotation_params,
)
from scipy.linalg import expm

import jaxlie_geo as jlg
from jaxlie_geo import SE2, SE3, SO2, SO3, _scalar, motion
from jaxlie_geo._se3 import exp_translation, log_translation
from jaxlie_geo._so3 import cross, exp_half_angle, log_quaternion_parts

ROOT = Path(__file__).resolve().parents[1]
EPS = np.finfo(np.float64).eps


# --- helpers ---------------------------------------------------------------------------


def _params(G, seed: int, batch=()) -> np.ndarray:
    """Random parameters, drawn in numpy (no compilation); SE translations of size ~3."""
    rng = np.random.default_rng(seed)
    if rotation_params(G) == 2:
        a = rng.uniform(-np.pi, np.pi, size=batch)
        rot = np.stack([np.cos(a), np.sin(a)], -1)
    else:
        q = rng.normal(size=(*batch, 4))
        rot = q / np.linalg.norm(q, axis=-1, keepdims=True)
    if not has_translation(G):
        return rot
    rest = rng.normal(scale=3.0, size=(*batch, G.parameters_dim - rotation_params(G)))
    if has_scale(G):  # the log-scale, last
        rest[..., -1] /= 6.0
    return np.concatenate([rot, rest], -1)


def _sample(G, seed: int, batch=()):
    return G(jnp.asarray(_params(G, seed, batch)))


def _mat(g) -> np.ndarray:
    """Homogeneous matrix of an element, written out in numpy (independent of the library)."""
    p = np.asarray(g.parameters(), dtype=np.float64)
    G = type(g)
    if rotation_params(G) == 2:
        R = _so2_mat(np.arctan2(p[..., 1], p[..., 0]))
    else:
        q = p[..., :4] / np.linalg.norm(p[..., :4], axis=-1, keepdims=True)
        w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
        R = np.stack(
            [
                np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
            ],
            -2,
        )
    if not has_translation(G):
        return R
    n, k, m = G.space_dim, rotation_params(G), G.matrix_dim
    M = np.broadcast_to(np.eye(m), (*p.shape[:-1], m, m)).copy()
    M[..., :n, :n] = R * (np.exp(p[..., -1])[..., None, None] if has_scale(G) else 1.0)
    for j in range(m - n):  # translation (and SE_2(3)'s velocity) columns, in storage order
        M[..., :n, n + j] = p[..., k + j * n : k + (j + 1) * n]
    return M


def _expm_path(G, M0: np.ndarray, xi: np.ndarray, t) -> np.ndarray:
    """Reference M0 · expm(t hat(ξ)) (scipy), broadcasting M0, ξ and t."""
    t = np.asarray(t, dtype=np.float64)
    X = hat_ref(G, np.asarray(xi, dtype=np.float64))
    X = t[..., None, None] * X
    shape = np.broadcast_shapes(M0.shape[:-2], X.shape[:-2])
    X = np.broadcast_to(X, (*shape, *X.shape[-2:])).reshape(-1, *X.shape[-2:])
    E = np.stack([expm(x) for x in X]).reshape(*shape, *X.shape[-2:])
    return M0 @ E


def _assert_same_pose(a, b, atol=1e-12, rtol=0.0):
    """Compare as homogeneous matrices (quaternion sign and angle wrapping don't matter);
    ``a`` and ``b`` are group elements or matrices."""
    ma = a if isinstance(a, np.ndarray) else _mat(a)
    mb = b if isinstance(b, np.ndarray) else _mat(b)
    np.testing.assert_allclose(ma, mb, atol=atol, rtol=rtol)


def _rot(G) -> slice:
    """The rotational part of a tangent."""
    return LAYOUT[G][0]


def _rng_velocity(G, rng, n, max_angle_rate=None):
    """Random tangents; with ``max_angle_rate``, ‖ω‖ drawn in [0.05, 1]·max_angle_rate."""
    xi = rng.normal(size=(n, G.tangent_dim))
    if max_angle_rate is not None:
        w = xi[:, _rot(G)]
        target = rng.uniform(0.05, 1.0, size=(n, 1)) * max_angle_rate
        xi[:, _rot(G)] = w / np.linalg.norm(w, axis=1, keepdims=True) * target
    return xi


def _rk4(M0: np.ndarray, Xi: np.ndarray, h: float, n_steps: int, record: list) -> dict:
    """Classical RK4 for dM/dt = M Ξ (M homogeneous, Ξ constant), batch over leading axes.

    Returns {step: M(step · h)} for the steps in ``record``."""
    f = lambda M: M @ Xi  # noqa: E731
    M = M0.copy()
    out = {0: M.copy()} if 0 in record else {}
    want = set(record)
    for k in range(1, n_steps + 1):
        k1 = f(M)
        k2 = f(M + 0.5 * h * k1)
        k3 = f(M + 0.5 * h * k2)
        k4 = f(M + h * k3)
        M = M + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        if k in want:
            out[k] = M.copy()
    return out


def _so2_mat(angle) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


# --- round trips -----------------------------------------------------------------------


N = 8  # batch size used throughout (one compilation per shape)


@over_groups
def test_round_trip_batched(G):
    """pose_at(a, velocity_between(a, b, T), T) == b for a batch with negative durations and for
    a scalar duration; along the way the path is a · expm(t hat(ξ)) (scipy)."""
    a, b = _sample(G, 1, (N,)), _sample(G, 2, (N,))
    T = np.random.default_rng(3).uniform(0.2, 5.0, size=N) * np.where(np.arange(N) % 2, -1, 1)
    xi = motion.velocity_between(a, b, jnp.asarray(T))  # half of the durations negative
    assert xi.shape == (N, G.tangent_dim) and xi.dtype == jnp.float64
    _assert_same_pose(motion.pose_at(a, xi, jnp.asarray(T)), b, atol=1e-11)
    # The path is a exp(t ξ): compare with scipy's matrix exponential along the way.
    for t in (0.4, -1.3):
        _assert_same_pose(
            motion.pose_at(a, xi, t), _expm_path(G, _mat(a), np.asarray(xi), t), atol=1e-11
        )
    # A scalar duration; at t = 0 the body is at the start.
    xi2 = motion.velocity_between(a, b, 2.5)
    _assert_same_pose(motion.pose_at(a, xi2, 2.5), b, atol=1e-11)
    _assert_same_pose(motion.pose_at(a, xi2, 0.0), a, atol=1e-15)


@over_groups
def test_negative_duration_runs_backwards(G):
    """A negative duration negates the velocity, and running a velocity backwards in time
    retraces the same path (pose_at(a, ξ, −t) == pose_at(a, −ξ, t))."""
    a, b = _sample(G, 4, (N,)), _sample(G, 5, (N,))
    xi = motion.velocity_between(a, b, 3.0)
    np.testing.assert_array_equal(np.asarray(motion.velocity_between(a, b, -3.0)), -np.asarray(xi))
    # Running the forward velocity back in time from b returns to a ...
    _assert_same_pose(motion.pose_at(b, xi, -3.0), a, atol=1e-11)
    # ... and pose_at(a, ξ, −t) == pose_at(a, −ξ, t) all along the path.
    for t in (0.5, 4.0):
        _assert_same_pose(motion.pose_at(a, xi, -t), motion.pose_at(a, -xi, t), atol=1e-12)
    # From b back to a over the same time: the same path, run backwards.
    back = motion.velocity_between(b, a, 3.0)
    for t in (0.0, 2.2):
        _assert_same_pose(motion.pose_at(b, back, t), motion.pose_at(a, xi, 3.0 - t), atol=1e-11)


@over_groups
def test_broadcasting_like_interpolate_and_geodesic(G):
    """Times broadcast numpy-style against the batch axes exactly as in ``interpolate``, and
    the geodesic is the constant-velocity path: a.interpolate(b, t) ==
    pose_at(a, velocity_between(a, b, 1), t) (the same expression: agreement to rounding),
    for t inside and outside [0, 1]; both equal a · expm(t hat(ξ))."""
    a, b = _sample(G, 6, (N,)), _sample(G, 7, (N,))
    Ma = _mat(a)
    ts = np.linspace(-0.7, 2.3, N)
    ulp = dict(atol=16 * EPS, rtol=4 * EPS)  # translations ~3: a few ulp

    def check(start, end, t, shape):
        xi = motion.velocity_between(start, end, 1.0)
        got = motion.pose_at(start, xi, t)
        ref = start.interpolate(end, t)
        assert got.get_batch_axes() == shape == ref.get_batch_axes()
        np.testing.assert_allclose(
            np.asarray(got.parameters()), np.asarray(ref.parameters()), **ulp
        )
        ref_m = _expm_path(G, _mat(start), np.asarray(xi), np.asarray(t))
        _assert_same_pose(got, ref_m, atol=1e-11)
        return xi

    # A batch of times on one body: unbatched endpoints, t of shape (K,) -> K poses.
    check(a[2], b[2], jnp.asarray(ts), (N,))
    # Elementwise: batch (N,) with t of shape (N,) (a scalar t: test_round_trip_batched).
    xi = check(a, b, jnp.asarray(ts), (N,))
    # Outer product: t[:, None] against batch (N,) -> (K, N).
    check(a, b, jnp.asarray(ts[:4, None]), (4, N))
    _assert_same_pose(a.interpolate(b, 1.0), b, atol=1e-11)
    # The Geodesic object: its tangent is the velocity over unit time (1/T otherwise).
    geo = jlg.geodesic(a, b)
    via_motion = motion.pose_at(a, xi, jnp.asarray(ts))
    np.testing.assert_allclose(
        np.asarray(geo(jnp.asarray(ts)).parameters()), np.asarray(via_motion.parameters()), **ulp
    )
    np.testing.assert_allclose(
        np.asarray(geo.tangent) / 4.0, np.asarray(motion.velocity_between(a, b, 4.0)), rtol=1e-15
    )
    # Unbatched start, batched velocities.
    fan = motion.pose_at(G.identity(), xi, 1.0)
    assert fan.get_batch_axes() == (N,)
    _assert_same_pose(fan, _expm_path(G, np.eye(Ma.shape[-1]), np.asarray(xi), 1.0), atol=1e-12)
    # Durations broadcast too: one pair, K durations -> (K, tangent_dim).
    xik = motion.velocity_between(a[0], b[0], jnp.asarray(ts + 3.0))
    assert xik.shape == (N, G.tangent_dim)
    np.testing.assert_allclose(
        np.asarray(xik) * (ts + 3.0)[:, None],
        np.broadcast_to(np.asarray(xi)[0], (N, G.tangent_dim)),
        rtol=1e-14,
        atol=1e-15,
    )
    # Endpoints broadcast: one start, a batch of ends.
    xib = motion.velocity_between(a[0], b, 1.0)
    assert xib.shape == (N, G.tangent_dim)
    _assert_same_pose(motion.pose_at(a[0], xib, 1.0), b, atol=1e-11)
    # Integer durations and times are promoted to float.
    _assert_same_pose(motion.pose_at(a, motion.velocity_between(a, b, 2), 2), b, atol=1e-11)


# --- the time-scaled logarithm of SO(3) -----------------------------------------------------


def _ln_tau(R: np.ndarray, tau: float) -> np.ndarray:
    """The time-scaled logarithm ln_τ R from the trace and the skew part: σ = arccos((tr R −
    1)/2)/τ, n = vee(R − Rᵀ)/(2 sin στ), ω = σ n (the notes it comes from write ω = τ n)."""
    sigma = np.arccos((np.trace(R) - 1.0) / 2.0) / tau
    S = R - R.T
    n = np.array([S[2, 1], S[0, 2], S[1, 0]]) / (2.0 * np.sin(sigma * tau))
    return sigma * n


def _rodrigues(w: np.ndarray, tau: float) -> np.ndarray:
    """The time-scaled Rodrigues formula e^{ŵτ} = I + ŵ/‖w‖ sin(‖w‖τ) + ŵ²/‖w‖² (1 −
    cos(‖w‖τ)) (ŵ² in the last term; the notes it comes from print ŵ)."""
    W = hat_ref(SO3, w)
    s = np.linalg.norm(w)
    return np.eye(3) + W / s * np.sin(s * tau) + W @ W / s**2 * (1.0 - np.cos(s * tau))


def test_velocity_between_is_the_time_scaled_log():
    """velocity_between(I, R, τ) is ln_τ R (trace and skew part) for R = e^{ŵτ} (time-scaled
    Rodrigues), and pose_at inverts it; the SO(2) analogue recovers ω from exp(ωτ)."""
    rng = np.random.default_rng(10)
    I = SO3.identity()
    for _ in range(25):
        tau = rng.uniform(0.1, 4.0)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.uniform(0.05, 3.0)  # ‖ω‖ τ < π: the principal branch
        w = axis * angle / tau
        R = _rodrigues(w, tau)
        got = np.asarray(motion.velocity_between(I, SO3.from_matrix(jnp.asarray(R)), tau))
        np.testing.assert_allclose(got, w, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(got, _ln_tau(R, tau), rtol=1e-9, atol=1e-12)
        # e^{(ln_τ R) τ} = R, via pose_at.
        np.testing.assert_allclose(_mat(motion.pose_at(I, got, tau)), R, atol=1e-14)
    # SO(2) analogue: R = exp(ω τ) -> ω for |ω τ| < π.
    for w, tau in [(0.3, 2.0), (-1.4, 2.1), (2.0, 1.5), (-0.001, 7.0)]:
        got = motion.velocity_between(SO2.identity(), SO2.from_radians(w * tau), tau)
        np.testing.assert_allclose(np.asarray(got), [w], rtol=1e-13)


# --- Zhang (2022), §5: arcs in SE(2) ---------------------------------------------------------


def test_zhang_5_4_worked_example():
    """Zhang (2022), §5.4: θ = π/2, t = (1, 0), T = 1 gives v = (π/4)(1, −1), ω = π/2 (the
    text prints (π/4)(1, 1), a consequence of its (I − R) chord slip in §5.1)."""
    target = SE2.from_xy_theta(1.0, 0.0, math.pi / 2)
    xi = np.asarray(motion.velocity_between(SE2.identity(), target, 1.0))
    np.testing.assert_allclose(xi, [math.pi / 4, -math.pi / 4, math.pi / 2], rtol=1e-15, atol=1e-16)
    assert not np.allclose(xi[:2], [math.pi / 4, math.pi / 4])  # the text's slip
    # Twice the time, half the velocity.
    xi2 = np.asarray(motion.velocity_between(SE2.identity(), target, 2.0))
    np.testing.assert_allclose(xi2, xi / 2, rtol=1e-15)
    # The arc: centre J v/ω = (1/2, 1/2), radius |v|/ω = (π/4)√2/(π/2) = 1/√2.
    arc = motion.arc(SE2.identity(), jnp.asarray(xi))
    np.testing.assert_allclose(float(arc.radius), 1 / math.sqrt(2), rtol=1e-14)
    np.testing.assert_allclose(np.asarray(arc.centre), [0.5, 0.5], atol=1e-15)


def test_zhang_5_3_geometric_pose_to_velocity():
    """Zhang (2022), §5.3's geometric answer (correct as printed):
    v = θ/(2T) ((t_y, −t_x) + cot(θ/2) (t_x, t_y)), ω = θ/T."""
    rng = np.random.default_rng(11)
    for _ in range(30):
        theta = rng.uniform(-3.1, 3.1)
        t = rng.normal(scale=2.0, size=2)
        T = rng.uniform(0.3, 5.0)
        v = theta / (2 * T) * (np.array([t[1], -t[0]]) + t / np.tan(theta / 2))
        got = motion.velocity_between(SE2.identity(), SE2.from_xy_theta(t[0], t[1], theta), T)
        np.testing.assert_allclose(np.asarray(got), [*v, theta / T], rtol=1e-12, atol=1e-13)


def test_zhang_5_1_chord_corrected():
    """Zhang (2022), §5.1 with the chord corrected (the text has I − R): from the identity,
    AB = (R(Tω) − I)·OA with OA = (1/ω)(v_y, −v_x) (centre to start), heading Tω."""
    rng = np.random.default_rng(12)
    for _ in range(30):
        vx, vy = rng.normal(size=2)
        w = rng.uniform(0.1, 2.0) * rng.choice([-1.0, 1.0])
        T = rng.uniform(-6.0, 9.0)
        OA = np.array([vy, -vx]) / w
        AB = (_so2_mat(T * w) - np.eye(2)) @ OA
        g = motion.pose_at(SE2.identity(), jnp.array([vx, vy, w]), T)
        np.testing.assert_allclose(np.asarray(g.translation()), AB, atol=1e-12)
        np.testing.assert_allclose(
            np.asarray(g.rotation().as_matrix()), _so2_mat(T * w), atol=1e-14
        )


def test_arc_velocity_to_pose():
    """The pose at t from the circle geometry — position c + R(ωt)(p₀ − c), heading
    θ₀ + ωt — equals pose_at, for a batch of starts and velocities and times beyond a turn."""
    rng = np.random.default_rng(13)
    n = 12
    start = _sample(SE2, 14, (n,))
    xi = rng.normal(size=(n, 3))
    xi[:, 2] = rng.uniform(0.2, 1.5, n) * rng.choice([-1.0, 1.0], n)
    arc = motion.arc(start, jnp.asarray(xi))
    c, p0 = np.asarray(arc.centre), np.asarray(start.translation())
    theta0 = np.asarray(start.rotation().as_radians())
    w = xi[:, 2]
    # Radius, curvature, heading, speed.
    np.testing.assert_allclose(np.linalg.norm(p0 - c, axis=1), np.asarray(arc.radius), rtol=1e-13)
    np.testing.assert_allclose(
        np.asarray(arc.radius), np.linalg.norm(xi[:, :2], axis=1) / abs(w), rtol=1e-14
    )
    np.testing.assert_allclose(
        np.asarray(arc.curvature), w / np.linalg.norm(xi[:, :2], axis=1), rtol=1e-14
    )
    u = np.einsum("nij,nj->ni", _so2_mat(theta0), xi[:, :2])  # world-frame velocity
    np.testing.assert_allclose(np.asarray(arc.heading), np.arctan2(u[:, 1], u[:, 0]), atol=1e-14)
    np.testing.assert_allclose(np.asarray(arc.speed), np.linalg.norm(u, axis=1), rtol=1e-14)
    # The velocity is tangent to the circle: perpendicular to the radius.
    np.testing.assert_allclose(np.sum(u * (p0 - c), axis=1), 0.0, atol=1e-12)
    for t in (-2.0, 0.3, 1.0, 5.0, 17.0):  # 17 s at 1.5 rad/s: four turns
        g = motion.pose_at(start, jnp.asarray(xi), t)
        pos = c + np.einsum("nij,nj->ni", _so2_mat(w * t), p0 - c)
        np.testing.assert_allclose(np.asarray(g.translation()), pos, atol=1e-11)
        np.testing.assert_allclose(
            np.asarray(g.rotation().as_matrix()), _so2_mat(theta0 + w * t), atol=1e-13
        )


@pytest.mark.parametrize("turn", [1.0, -1.0], ids=["ccw", "cw"])
def test_arc_pose_to_velocity(turn):
    """Two poses on a known circle (centre c, radius r, turning direction, and a constant
    slip angle α between heading and direction of travel): velocity_between recovers
    ω = Δ/T, speed rΔ/T, the circle's centre and signed curvature."""
    rng = np.random.default_rng(15 if turn > 0 else 16)
    for _ in range(20):
        c = rng.normal(scale=5.0, size=2)
        r = rng.uniform(0.2, 10.0)
        alpha = rng.uniform(-1.0, 1.0)  # slip: heading = direction of travel + α
        phi0 = rng.uniform(-np.pi, np.pi)
        delta = turn * rng.uniform(0.05, 3.0)  # swept angle, |Δ| < π
        T = rng.uniform(0.2, 8.0)

        def pose(phi, c=c, r=r, alpha=alpha):
            p = c + r * np.array([np.cos(phi), np.sin(phi)])
            travel = turn * np.array([-np.sin(phi), np.cos(phi)])
            return SE2.from_xy_theta(p[0], p[1], np.arctan2(travel[1], travel[0]) + alpha)

        A, B = pose(phi0), pose(phi0 + delta)
        xi = np.asarray(motion.velocity_between(A, B, T))
        speed = r * abs(delta) / T
        np.testing.assert_allclose(
            xi, [speed * np.cos(-alpha), speed * np.sin(-alpha), delta / T], rtol=1e-10, atol=1e-11
        )
        arc = motion.arc(A, jnp.asarray(xi))
        np.testing.assert_allclose(np.asarray(arc.centre), c, atol=1e-10 * (1 + r))
        np.testing.assert_allclose(float(arc.radius), r, rtol=1e-11)
        np.testing.assert_allclose(float(arc.curvature), turn / r, rtol=1e-11)
        travel0 = turn * np.array([-np.sin(phi0), np.cos(phi0)])
        np.testing.assert_allclose(
            np.cos(float(arc.heading) - np.arctan2(travel0[1], travel0[0])), 1.0, atol=1e-12
        )
        # Negative duration: the reversed velocity describes the same circle.
        arc_back = motion.arc(A, motion.velocity_between(A, B, -T))
        np.testing.assert_allclose(np.asarray(arc_back.centre), c, atol=1e-10 * (1 + r))
        np.testing.assert_allclose(float(arc_back.curvature), -turn / r, rtol=1e-11)
        # Midway in time is midway on the circle.
        mid = motion.pose_at(A, jnp.asarray(xi), T / 2)
        phi_mid = phi0 + delta / 2
        np.testing.assert_allclose(
            np.asarray(mid.translation()),
            c + r * np.array([np.cos(phi_mid), np.sin(phi_mid)]),
            atol=1e-10 * (1 + r),
        )


def test_arc_straight_line_and_turning_on_the_spot():
    """The documented limits of ``motion.arc``: a straight line (curvature 0, radius inf), turning
    on the spot (curvature ±inf, radius 0), standing still; zero gradients where the speed is
    0, and no NaN from the guards in a batch that mixes the cases."""
    start = SE2.from_xy_theta(1.0, -2.0, 0.7)
    R0 = _so2_mat(0.7)
    # Straight line (ω = 0): documented curvature 0, radius inf, centre = start.
    d = np.array([3.0, -1.0])  # body-frame displacement (forward and sideways)
    end = start @ SE2.from_xy_theta(d[0], d[1], 0.0)
    xi = np.asarray(motion.velocity_between(start, end, 2.0))
    np.testing.assert_allclose(xi, [1.5, -0.5, 0.0], atol=1e-15)
    # start⁻¹ end rounds (ω comes out ~1e-17, not 0, and the centre of that "circle" is
    # ~1e17 away), so the documented values are checked on the exact velocity.
    xi = np.array([1.5, -0.5, 0.0])
    arc = motion.arc(start, jnp.asarray(xi))
    assert float(arc.curvature) == 0.0
    assert float(arc.radius) == np.inf
    np.testing.assert_array_equal(np.asarray(arc.centre), [1.0, -2.0])
    u = R0 @ xi[:2]
    assert float(arc.heading) == pytest.approx(np.arctan2(u[1], u[0]), abs=1e-15)
    for t in (-1.0, 0.5, 3.0):
        g = motion.pose_at(start, jnp.asarray(xi), t)
        np.testing.assert_allclose(np.asarray(g.translation()), [1.0, -2.0] + u * t, atol=1e-14)
        assert float(g.rotation().as_radians()) == pytest.approx(0.7, abs=1e-15)
    # Turning on the spot (|v| = 0): curvature ±inf (sign of ω), radius 0, centre = start,
    # heading 0.
    for w in (1.3, -0.4):
        end = start @ SE2.from_xy_theta(0.0, 0.0, w * 2.0)
        xi = np.asarray(motion.velocity_between(start, end, 2.0))
        np.testing.assert_allclose(xi, [0.0, 0.0, w], atol=1e-15)
        xi = np.array([0.0, 0.0, w])
        arc = motion.arc(start, jnp.asarray(xi))
        assert float(arc.curvature) == math.copysign(math.inf, w)
        assert float(arc.radius) == 0.0
        assert float(arc.speed) == 0.0 and float(arc.heading) == 0.0
        np.testing.assert_array_equal(np.asarray(arc.centre), [1.0, -2.0])
        g = motion.pose_at(start, jnp.asarray(xi), 5.0)
        np.testing.assert_allclose(np.asarray(g.translation()), [1.0, -2.0], atol=1e-15)
    # Standing still: curvature 0, radius inf (1/|curvature|; it was 0/0 = NaN), centre =
    # start, heading 0.
    arc = motion.arc(start, jnp.zeros(3))
    assert float(arc.curvature) == 0.0 and float(arc.heading) == 0.0
    assert float(arc.radius) == np.inf
    np.testing.assert_array_equal(np.asarray(arc.centre), [1.0, -2.0])
    # Gradients at zero speed are 0 (the subgradient), not NaN from √0 and atan2(0, 0).
    for v in (jnp.zeros(3), jnp.array([0.0, 0.0, 0.7])):
        for field in ("speed", "heading", "curvature"):
            g = jax.grad(lambda v, field=field: getattr(motion.arc(start, v), field))(v)
            np.testing.assert_array_equal(np.asarray(g), 0.0)
    g = jax.grad(lambda v: motion.arc(start, v).speed)(jnp.array([0.3, 0.4, 0.0]))
    np.testing.assert_allclose(np.asarray(g), [0.6, 0.8, 0.0], atol=1e-15)
    # Batched, mixed cases in one call (the where-guards must not leak NaN).
    xis = jnp.array([[1.0, 0.0, 0.0], [0.0, 0.0, 2.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    arcs = motion.arc(start, xis)
    assert arcs.centre.shape == (4, 2)
    assert np.all(np.isfinite(np.asarray(arcs.centre)))
    np.testing.assert_allclose(np.asarray(arcs.curvature), [0.0, np.inf, 1 / np.sqrt(2), 0.0])
    np.testing.assert_allclose(np.asarray(arcs.radius), [np.inf, 0.0, np.sqrt(2), np.inf])


def test_arc_rejects_other_groups():
    """``motion.arc`` is for SE2 alone: another group raises TypeError."""
    with pytest.raises(TypeError):
        motion.arc(SE3.identity(), jnp.zeros(6))


# --- the duck game vs a directly integrated path -------------------------------------------


@over_se_groups
def test_duck_game_against_rk4(G):
    """Zhang (2022), §6.5, a game of poses: the duck leaves G₀ at constant body velocity;
    from G₀ and the (RK4-integrated) G₈ we recover the velocity and the pose at t = 3."""
    rng = np.random.default_rng(20 if G is SE2 else 21)
    n = 6
    # ‖ω‖ · 8 < π: the turn over the game is on the principal branch.
    xi = _rng_velocity(G, rng, n, max_angle_rate=0.37)
    g0 = _sample(G, 22, (n,))
    h = 1e-3
    path = _rk4(_mat(g0), hat_ref(G, xi), h, 8000, [3000, 8000])
    g8 = G.from_matrix(jnp.asarray(path[8000]))
    xi_hat = np.asarray(motion.velocity_between(g0, g8, 8.0))
    np.testing.assert_allclose(xi_hat, xi, atol=1e-11)
    g3 = motion.pose_at(g0, jnp.asarray(xi_hat), 3.0)
    np.testing.assert_allclose(_mat(g3), path[3000], atol=1e-9, rtol=1e-10)
    np.testing.assert_allclose(
        _mat(motion.pose_at(g0, jnp.asarray(xi), 8.0)), path[8000], atol=1e-9, rtol=1e-10
    )


@over_groups
def test_long_motion_beyond_pi_against_rk4(G):
    """Rotation angles far beyond π (an SE(3) helix of several turns, a long duration):
    pose_at follows the turns, and agrees with RK4 all along the path."""
    rng = np.random.default_rng(30)
    n = 4
    xi = _rng_velocity(G, rng, n)
    rot = _rot(G)
    xi[:, rot] *= 2.0 / np.linalg.norm(xi[:, rot], axis=1, keepdims=True)  # ‖ω‖ = 2 rad/s
    if G is SE3:
        xi[0] = [1.0, 0.0, 0.3, 0.0, 0.0, 2.0]  # a clean helix: radius 1/2, climbing
    g0 = _sample(G, 31, (n,))
    h, T = 1e-3, 24.0  # 48 rad ≈ 7.6 turns
    steps = [3000, 7000, 12000, 24000]
    path = _rk4(_mat(g0), hat_ref(G, xi), h, 24000, steps)
    for k in steps:
        g = motion.pose_at(g0, jnp.asarray(xi), k * h)
        np.testing.assert_allclose(_mat(g), path[k], atol=1e-9, rtol=1e-10)
    if G is SE3:
        # The helix climbs 0.3 m/s along its axis (z in the body frame of the start).
        p = np.asarray(
            (g0[0].inverse() @ motion.pose_at(g0[0], jnp.asarray(xi[0]), T)).translation()
        )
        assert p[2] == pytest.approx(0.3 * T, abs=1e-12)
        assert np.hypot(p[0], p[1] - 0.5) == pytest.approx(0.5, abs=1e-12)
    # With a probe after 1 s (turn 2 rad < π), velocity_between recovers the velocity and
    # pose_at then follows all 24 s.
    g1 = G.from_matrix(jnp.asarray(_rk4(_mat(g0), hat_ref(G, xi), h, 1000, [1000])[1000]))
    xi_hat = motion.velocity_between(g0, g1, 1.0)
    np.testing.assert_allclose(np.asarray(xi_hat), xi, atol=1e-11)
    np.testing.assert_allclose(
        _mat(motion.pose_at(g0, xi_hat, T)), path[24000], atol=1e-9, rtol=1e-10
    )
    # From the two end poses alone the principal log sees less than half a turn.
    short = np.asarray(motion.velocity_between(g0, G.from_matrix(jnp.asarray(path[24000])), T))
    assert np.all(np.linalg.norm(short[:, rot], axis=1) * T <= np.pi + 1e-9)


# --- the two SE(3) translation kernels ---------------------------------------------------------


def _textbook_exp_translation(v, w):
    """t = v + F1 (ω × v) + F2 ω × (ω × v) (Barfoot 2017, eq. 7.82; Eberly 2024, eq. 36)."""
    c, k = exp_half_angle(w)
    f1, f2 = (0.5 * k * k)[..., None], _scalar.F2(jnp.sum(w * w, axis=-1), c * k)[..., None]
    wxv = cross(w, v)
    return v + f1 * wxv + f2 * cross(w, wxv)


def _textbook_log_translation(t, u, s):
    """v = t − ½ ω × t + G ω × (ω × t), ω = s·u (Barfoot 2017, eq. 7.85)."""
    w = s[..., None] * u
    g = _scalar.G_principal(jnp.sum(w * w, axis=-1))[..., None]
    wxt = cross(w, t)
    return t - 0.5 * wxt + g * cross(w, wxt)


@pytest.mark.parametrize("dtype", [np.float64])  # float32 accuracy: test_accuracy.py
@pytest.mark.parametrize("theta", [0.0, 1e-8, 1e-3, 1.0, 3.1, 9.0])
def test_se3_exp_translation_forms_agree(theta, dtype):
    """t = V(ω) v: the textbook form and the library's axis-split form agree to a few ulp of
    |v| (the size of the terms; the textbook form cancels to the shorter t beyond π)."""
    rng = np.random.default_rng(50)
    n = 500
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    w = (axis * theta).astype(dtype)
    v = (rng.normal(size=(n, 3)) * rng.choice([1e-3, 1.0, 1e3], size=(n, 1))).astype(dtype)
    a = np.asarray(_textbook_exp_translation(jnp.asarray(v), jnp.asarray(w)))
    b = np.asarray(exp_translation(jnp.asarray(v), jnp.asarray(w)))
    assert a.dtype == b.dtype == dtype
    eps = np.finfo(dtype).eps
    diff = a.astype(np.float64) - b
    err = np.linalg.norm(diff, axis=1) / np.linalg.norm(v.astype(np.float64), axis=1)
    assert np.max(err) / eps <= 4.0, np.max(err) / eps


@pytest.mark.parametrize("dtype", [np.float64])  # float32 accuracy: test_accuracy.py
@pytest.mark.parametrize("theta", [0.0, 1e-8, 1e-3, 1.0, 3.1, np.pi - 1e-6, np.pi])
def test_se3_log_translation_forms_agree(theta, dtype):
    """v = V(ω)⁻¹ t for the principal log (θ ≤ π): the forms agree to a few ulp of
    max(|t|, |v|): the textbook form against the library's axis-split form."""
    rng = np.random.default_rng(51)
    n = 500
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    if theta == np.pi:
        q = np.concatenate([np.zeros((n, 1)), axis], axis=1)  # w = 0 exactly
    else:
        q = np.concatenate([np.full((n, 1), np.cos(theta / 2)), np.sin(theta / 2) * axis], axis=1)
    q = q.astype(dtype)
    t = (rng.normal(size=(n, 3)) * rng.choice([1e-3, 1.0, 1e3], size=(n, 1))).astype(dtype)
    u, s, hh = log_quaternion_parts(jnp.asarray(q))
    a = np.asarray(_textbook_log_translation(jnp.asarray(t), u, s)).astype(np.float64)
    b = np.asarray(log_translation(jnp.asarray(t), u, s, hh)).astype(np.float64)
    eps = np.finfo(dtype).eps
    scale = np.maximum(np.linalg.norm(t.astype(np.float64), axis=1), np.linalg.norm(b, axis=1))
    err = np.linalg.norm(a - b, axis=1) / scale
    assert np.max(err) / eps <= 4.0, np.max(err) / eps


# --- errors ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "zero",
    [0.0, 0, -0.0, np.float32(0.0), jnp.array([1.0, 0.0, 2.0])],
    ids=["float", "int", "negzero", "f32", "array-with-zero"],
)
def test_zero_duration_raises(zero):
    """A zero duration (any type, or one zero in an array) raises ValueError eagerly."""
    a, b = _sample(SE3, 60, (3,)), _sample(SE3, 61, (3,))
    with pytest.raises(ValueError, match="non-zero"):
        motion.velocity_between(a, b, zero)


def test_traced_zero_duration_gives_non_finite():
    """Under jit a zero duration cannot be checked: the velocity is not finite."""
    a, b = _sample(SE2, 62), _sample(SE2, 63)
    xi = jax.jit(motion.velocity_between)(a, b, 0.0)
    assert not np.all(np.isfinite(np.asarray(xi)))


def test_mismatched_groups_and_shapes_raise():
    """Endpoints of different groups raise TypeError; a velocity of the wrong size ValueError."""
    with pytest.raises(TypeError):
        motion.velocity_between(SE2.identity(), SO2.identity(), 1.0)
    with pytest.raises(ValueError):
        motion.pose_at(SE2.identity(), jnp.zeros(6), 1.0)


# --- transformations -------------------------------------------------------------------------


@over_groups
def test_jit_vmap_grad(G):
    """jit(vmap(...)) of velocity_between + pose_at equals the eager batched result; the
    gradients through both (w.r.t. endpoints, duration and time) are finite, also where
    start == end (zero velocity); and the derivatives are the expected ones."""
    a, b = _sample(G, 70, (N,)), _sample(G, 71, (N,))
    b = G(b.parameters().at[0].set(a.parameters()[0]))  # pair 0: start == end
    T = jnp.asarray(np.linspace(-2.0, 3.0, N) + 0.25)
    t = jnp.asarray(np.linspace(0.1, 1.6, N))

    def forward(pa, pb, dur, tt):
        """ξ, the pose at tt, and the forward-mode derivatives d/dT ξ and d/dt pose."""
        ga, gb = G(pa), G(pb)
        v, dv = jax.jvp(lambda d: motion.velocity_between(ga, gb, d), (dur,), (1.0,))
        p, dM = jax.jvp(lambda s: motion.pose_at(ga, v, s).as_matrix(), (tt,), (1.0,))
        return v, p, dv, dM

    def loss(pa, pb, dur, tt):
        ga, gb = G(pa), G(pb)
        v = motion.velocity_between(ga, gb, dur)
        return jnp.sum(motion.pose_at(ga, v, tt).parameters()) + jnp.sum(v)

    pa, pb = a.parameters(), b.parameters()
    ga, gb = G(pa), G(pb)
    v_e = motion.velocity_between(ga, gb, T)  # eager, batched
    p_e = motion.pose_at(ga, v_e, t)
    v, p, dv, dM = jax.jit(jax.vmap(forward))(pa, pb, T, t)
    np.testing.assert_allclose(np.asarray(v), np.asarray(v_e), rtol=1e-13, atol=1e-14)
    _assert_same_pose(np.asarray(p), p_e, atol=1e-13)
    np.testing.assert_allclose(np.asarray(v_e)[0], 0.0, atol=1e-15)  # a⁻¹a rounds
    # d/dT (log/T) = −ξ/T, and d/dt a exp(tξ) = a exp(tξ) hat(ξ) (the body-velocity ODE).
    np.testing.assert_allclose(
        np.asarray(dv), -np.asarray(v) / np.asarray(T)[:, None], rtol=1e-13, atol=1e-15
    )
    expected = _expm_path(G, _mat(a), np.asarray(v), np.asarray(t)) @ hat_ref(G, np.asarray(v))
    np.testing.assert_allclose(np.asarray(dM), expected, atol=1e-11)

    # Reverse mode, w.r.t. both endpoints, the duration and the time (the batch elements are
    # independent, so the gradient of the sum is the per-pair gradient).
    grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2, 3)))(pa, pb, T, t)
    for g in grads:
        assert g.shape in (pa.shape, T.shape)
        assert np.all(np.isfinite(np.asarray(g)))


# --- the example ---------------------------------------------------------------------------


def test_duck_game_example_runs(tmp_path):
    """``examples/duck_game.py`` runs, prints the pose at t = 3 and the body velocity, and
    writes both PNGs."""
    env = dict(os.environ, MPLBACKEND="Agg", JAX_PLATFORMS="cpu")
    proc = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "duck_game.py"), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
        env=env,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("duck_game.png", "duck_game_3d.png"):
        png = tmp_path / name
        assert png.exists(), name
        data = png.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert "pose at t = 3" in proc.stdout and "body velocity" in proc.stdout
