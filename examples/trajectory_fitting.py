"""Fitting a smooth SE(3) trajectory to noisy, partly missing pose measurements.

A drone flies a figure-eight, banking as it goes. A tracker reports its pose (position and
orientation, ``T_world_body``) at K instants, but every report is noisy and about 30% of
them never arrive: some drop out at random, and one whole stretch is lost. We want the
trajectory back — at every instant, including the ones with no report.

We estimate all K poses at once by minimising, over the poses ``T_i`` (one batched ``SE3``
of batch shape ``(K,)``),

    L(T) =   Σ_{i observed}  ‖ log(Z_i⁻¹ T_i) ‖²_W                   (data: stay near the reports)
           + λ Σ_i           ‖ ξ_{i+1} − ξ_i ‖²_S,   ξ_i = log(T_i⁻¹ T_{i+1})    (smoothness)

``Z_i`` are the reported poses and ``‖r‖²_W = rᵀ W r`` with diagonal weights, ``W`` the
inverse of the measurement noise covariance, ``S`` the inverse of the covariance of the change
of body velocity per step. ``ξ_i`` is the body-frame displacement (the "body velocity" per time
step) that carries pose i to pose i + 1, so ``ξ_{i+1} − ξ_i`` is a second difference on the
manifold: it vanishes exactly on constant-velocity screw motions ``T_0 exp(i ξ)`` — the SE(3)
analogue of a straight line — and the prior bends the fit away from them only where the data
ask for it. Through a gap, the prior alone decides, and it draws the smoothest curve that
joins the poses on both sides.

How the optimisation works on the manifold: a pose is not a vector, so we do not add a step
to its parameters (that would leave the unit quaternions). Instead every pose is perturbed on
the right, ``T ⊕ δ = T @ exp(δ)``, with δ ∈ R⁶ = (v, ω) a small motion in the body frame, and

1. ``jaxlie_geo.manifold.value_and_grad`` returns ``∂L(T ⊕ δ)/∂δ`` at δ = 0, one 6-vector per
   pose: the gradient in the tangent space, which has exactly as many coordinates as the pose
   has degrees of freedom (6, not the 7 parameters), and whose every direction is a rigid
   motion;
2. ``optax.adam`` turns that gradient into a step δ, as it would for any array;
3. ``jaxlie_geo.manifold.rplus`` applies it, ``T ← T @ exp(δ)``, which is a valid pose by
   construction (we renormalise the quaternions against float32 round-off drift).

(Adam keeps moment estimates per tangent coordinate. The tangent spaces move with the poses,
so strictly the moments should be transported between them; the steps are small and the body
frames barely turn from one step to the next, so we — like most practical code — don't.)

The script prints, against the ground truth (which it generated itself), the position and
rotation RMSE of the raw reports and of the fit at the observed instants, and of the fit and of
the naive gap filler (geodesic interpolation between the nearest reports, also the fit's
starting point) at the missing ones. It draws the three trajectories in 3D, the per-pose errors
and the loss curve to ``out/trajectory_fitting.png``.

Run: ``python examples/trajectory_fitting.py`` (K = 150 poses, 5000 iterations: about 20 s
on two shared CPU cores, mostly start-up and compiling the step, then 0.3 ms per iteration);
``--quick`` (K = 80, 800 iterations) is the tests' smoke run; ``--out`` changes the picture path.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import NamedTuple, Tuple

import jax
import jax.numpy as jnp
import numpy as onp
import optax
from tqdm.auto import tqdm

from jaxlie_geo import SE3, SO3, manifold, uncertainty

# ---------------------------------------------------------------------------------------
# 0. Problem settings. Tangent order is jaxlie's, (vx, vy, vz, ωx, ωy, ωz).

SIGMA_POS = 0.10  # measurement noise, each translation coordinate [m]
SIGMA_ROT = onp.deg2rad(6.0)  # measurement noise, each rotation coordinate [rad]
# Prior on the change of body displacement per step, ξ_{i+1} − ξ_i (an "acceleration").
# Smaller = stiffer. Chosen a little above what the true trajectory needs at K = 150.
SIGMA_ACC_POS = 0.004  # [m per step per step]
SIGMA_ACC_ROT = 0.006  # [rad per step per step]
MISSING_RANDOM = 0.22  # fraction of reports dropped at random ...
MISSING_BURST = 0.10  # ... plus one contiguous outage of this fraction of K


class Problem(NamedTuple):
    """Everything the loss needs besides the poses being estimated."""

    Z_world_body: SE3  # (K,) reported poses (entries where ``observed`` is False are unused)
    observed: jax.Array  # (K,) float, 1.0 where a report arrived, 0.0 where it is missing
    w_data: jax.Array  # (6,) diagonal of W = Σ_meas⁻¹
    w_smooth: jax.Array  # (6,) diagonal of λ S


# ---------------------------------------------------------------------------------------
# 1. Ground truth: a banked figure-eight.


def ground_truth(K: int) -> SE3:
    """K poses ``T_world_body`` along one loop of a figure-eight, x ∈ [−3, 3] m,
    y ∈ [−1.5, 1.5] m, with a gentle climb and dive. The body x axis points along the
    velocity (yaw and pitch from the direction of travel) and the drone banks ±35° into the
    turns (roll), so the orientation changes in all three axes."""
    s = onp.linspace(0.0, 2.0 * onp.pi, K, endpoint=False)
    p_world = onp.stack([3.0 * onp.sin(s), 1.5 * onp.sin(2 * s), 0.5 * onp.sin(3 * s)], -1)
    v_world = onp.stack([3.0 * onp.cos(s), 3.0 * onp.cos(2 * s), 1.5 * onp.cos(3 * s)], -1)
    yaw = onp.arctan2(v_world[:, 1], v_world[:, 0])
    pitch = -onp.arcsin(v_world[:, 2] / onp.linalg.norm(v_world, axis=-1))  # nose up = −pitch
    roll = onp.deg2rad(35.0) * onp.sin(s)  # banks one way on one lobe, the other on the other
    f32 = lambda x: jnp.asarray(x, dtype=jnp.float32)  # noqa: E731
    R_world_body = SO3.from_rpy_radians(f32(roll), f32(pitch), f32(yaw))
    return SE3.from_rotation_and_translation(R_world_body, f32(p_world))


def missing_mask(key: jax.Array, K: int) -> onp.ndarray:
    """Boolean (K,), True where the report is missing: random drop-outs plus one outage."""
    k_drop, k_burst = jax.random.split(key)
    missing = onp.array(jax.random.uniform(k_drop, (K,)) < MISSING_RANDOM)  # a writable copy
    n_burst = max(2, int(round(MISSING_BURST * K)))
    start = int(jax.random.randint(k_burst, (), K // 4, (3 * K) // 4 - n_burst))
    missing[start : start + n_burst] = True
    return missing


@jax.jit  # one compilation instead of one per operation inside ``sample``
def observe(key: jax.Array, T_world_body: SE3) -> SE3:
    """Noisy reports ``Z = T ⊕ n = T @ exp(n)``, ``n ~ N(0, Σ_meas)`` in the body frame."""
    cov = jnp.diag(jnp.asarray([SIGMA_POS**2] * 3 + [SIGMA_ROT**2] * 3, dtype=jnp.float32))
    return uncertainty.sample(key, T_world_body, cov)


def fill_gaps(Z_world_body: SE3, observed: onp.ndarray) -> SE3:
    """The naive estimate: the report where there is one; in a gap, the geodesic between the
    reports on either side (``a.interpolate(b, t)``), at the fraction of the gap elapsed;
    before the first / after the last report, the nearest report."""
    K = observed.shape[0]
    idx = onp.arange(K)
    obs_idx = idx[observed]
    # The last report at or before i and the first at or after i. Clipping makes both the
    # first report before it, and both the last report after the last one.
    last = len(obs_idx) - 1
    prv = obs_idx[onp.clip(onp.searchsorted(obs_idx, idx, side="right") - 1, 0, last)]
    nxt = obs_idx[onp.clip(onp.searchsorted(obs_idx, idx, side="left"), 0, last)]
    t = onp.where(nxt > prv, (idx - prv) / onp.maximum(nxt - prv, 1), 0.0)
    t = jnp.asarray(t, dtype=Z_world_body.parameters().dtype)
    return Z_world_body[prv].interpolate(Z_world_body[nxt], t)


# ---------------------------------------------------------------------------------------
# 2. The objective.


def body_steps(T_world_body: SE3) -> jax.Array:
    """ξ_i = log(T_i⁻¹ T_{i+1}), shape (K − 1, 6): the motion from pose i to pose i + 1,
    expressed in body frame i (``manifold.rminus(a, b) = log(a⁻¹ b)``)."""
    return manifold.rminus(T_world_body[:-1], T_world_body[1:])


def _concat(a: SE3, b: SE3) -> SE3:
    """Two batches of poses, one after the other along the batch axis."""
    return SE3(jnp.concatenate([a.parameters(), b.parameters()], axis=0))


def loss_terms(T_world_body: SE3, problem: Problem) -> Tuple[jax.Array, jax.Array]:
    """(data term, smoothness term) of the objective; the loss is their sum.

    Both terms are built from logs of relative poses, ``manifold.rminus(a, b) = log(a⁻¹ b)``:
    K data residuals ``log(Z_i⁻¹ T_i)`` and K − 1 steps ``log(T_i⁻¹ T_{i+1})``. They go through
    one batched ``log`` of 2K − 1 poses rather than two calls: the result is the same, and the
    gradient compiles in about half the time (compilation dominates this script's start-up).
    """
    K = problem.observed.shape[0]
    r_all = manifold.rminus(
        _concat(problem.Z_world_body, T_world_body[:-1]),
        _concat(T_world_body, T_world_body[1:]),
    )  # (2K − 1, 6)
    # Data: r_i = log(Z_i⁻¹ T_i) is the body-frame motion from the report to the estimate.
    # (log(X⁻¹) = −log(X), so ‖log(Z⁻¹T)‖ = ‖log(T⁻¹Z)‖ = the size of the noise that the
    # estimate attributes to report i.) Missing reports are masked out.
    r = r_all[:K]
    data = jnp.sum(problem.observed * jnp.sum(problem.w_data * r**2, axis=-1))
    # Smoothness: second difference of the body steps ξ_i = log(T_i⁻¹ T_{i+1}) (see
    # ``body_steps``). Each ξ_i is expressed in its own body frame i, so on a constant-velocity
    # screw motion T_0 exp(i ξ) all of them equal ξ and the term is exactly 0.
    xi = r_all[K:]
    smooth = jnp.sum(problem.w_smooth * (xi[1:] - xi[:-1]) ** 2)
    return data, smooth


def loss(T_world_body: SE3, problem: Problem) -> jax.Array:
    data, smooth = loss_terms(T_world_body, problem)
    return data + smooth


def _loss_and_terms(T_world_body: SE3, problem: Problem):
    """The loss, and (data, smoothness) as an auxiliary output for the loss curves."""
    data, smooth = loss_terms(T_world_body, problem)
    return data + smooth, jnp.stack([data, smooth])


# ``manifold.value_and_grad`` (``manifold.grad`` that also returns the value) differentiates
# δ ↦ loss(T @ exp(δ)) at δ = 0: for a batched SE3 of shape (K,) the gradient is a (K, 6) array
# of body-frame tangents, one per pose. Plain ``jax.grad`` would instead differentiate with
# respect to the 7 raw parameters (quaternion + translation): a step along that gradient
# leaves the unit quaternions, and the direction that only rescales a quaternion is a
# meaningless 7th coordinate mixed into the update.
tangent_value_and_grad = manifold.value_and_grad(_loss_and_terms, has_aux=True)


@jax.jit
def evaluate(T_world_body: SE3, problem: Problem) -> jax.Array:
    """(loss, data term, smoothness term), compiled once (eagerly, every group method would
    be compiled on its own)."""
    value, terms = _loss_and_terms(T_world_body, problem)
    return jnp.concatenate([value[None], terms])


def make_step(optimizer: optax.GradientTransformation):
    """One jitted iteration: tangent gradient → Adam step δ → T ← T ⊕ δ."""

    @jax.jit
    def step(T_world_body: SE3, opt_state, problem: Problem):
        (value, terms), grad = tangent_value_and_grad(T_world_body, problem)  # grad: (K, 6)
        delta, opt_state = optimizer.update(grad, opt_state)  # a tangent step, (K, 6)
        T_world_body = manifold.rplus(T_world_body, delta)  # T_i ← T_i @ exp(δ_i)
        # exp(δ) is a unit quaternion, but thousands of float32 products drift off the unit
        # sphere; renormalising costs nothing.
        return T_world_body.normalize(), opt_state, jnp.concatenate([value[None], terms])

    return step


def fit(T_init: SE3, problem: Problem, iters: int, lr: float, progress: bool):
    """Adam on the tangent space, learning rate decaying exponentially from ``lr`` to
    ``lr / 20``. Returns the fit, the history of (loss, data, smoothness) before each step and
    after the last one, shape (iters + 1, 3), and the times of the first call (tracing and
    compilation included) and of the remaining iterations."""
    schedule = optax.exponential_decay(lr, transition_steps=iters, decay_rate=0.05)
    optimizer = optax.adam(schedule)
    step = make_step(optimizer)
    T, opt_state = T_init, optimizer.init(manifold.zero_tangents(T_init))
    history = []
    bar = tqdm(
        range(iters),
        desc="fitting",
        unit="it",
        disable=not progress,
        file=sys.stderr,
        dynamic_ncols=True,
    )
    start = time.perf_counter()
    for i in bar:
        T, opt_state, values = step(T, opt_state, problem)
        history.append(values)
        if i == 0:
            jax.block_until_ready(values)
            first = time.perf_counter() - start
        if progress and i % 100 == 0:
            bar.set_postfix(loss=f"{float(values[0]):.1f}")
    jax.block_until_ready(T)
    rest = time.perf_counter() - start - first
    bar.close()
    history.append(evaluate(T, problem))
    # To the host one by one (jnp.stack would compile a 5001-operand concatenation).
    return T, onp.stack(jax.device_get(history)), first, rest


# ---------------------------------------------------------------------------------------
# 3. Errors against the ground truth.


@jax.jit
def _pose_errors(T_est: SE3, T_true: SE3) -> Tuple[jax.Array, jax.Array]:
    pos = jnp.linalg.norm(T_est.translation() - T_true.translation(), axis=-1)
    rot = jnp.linalg.norm((T_true.rotation().inverse() @ T_est.rotation()).log(), axis=-1)
    return pos, rot


def pose_errors(T_est: SE3, T_true: SE3) -> Tuple[onp.ndarray, onp.ndarray]:
    """Per pose: position error [m] and rotation error [deg] (angle of R_true⁻¹ R_est)."""
    pos, rot = _pose_errors(T_est, T_true)
    return onp.asarray(pos), onp.rad2deg(onp.asarray(rot))


def rmse(x: onp.ndarray) -> float:
    return float(onp.sqrt(onp.mean(onp.square(x))))


# ---------------------------------------------------------------------------------------
# 4. The picture.

C_TRUE, C_OBS, C_FIT, C_GAP, C_NAIVE = "0.1", "#e6873c", "#2166ac", "#b2182b", "0.45"
C_AXES = ("#d62728", "#2ca02c", "#1f3fbf")  # body x, y, z


def draw(
    path: Path,
    T_true: SE3,
    Z: SE3,
    T_fit: SE3,
    T_naive: SE3,
    observed: onp.ndarray,
    history: onp.ndarray,
    loss_true: float,
    n_frames: int = 9,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.lines import Line2D

    K = observed.shape[0]
    missing = ~observed
    p_true, p_obs, p_fit = (onp.asarray(T.translation()) for T in (T_true, Z, T_fit))
    errors = {
        name: pose_errors(T, T_true)
        for name, T in (("reports", Z), ("naive", T_naive), ("fit", T_fit))
    }

    fig = plt.figure(figsize=(14, 7.6), dpi=130)
    gs = fig.add_gridspec(
        1, 2, width_ratios=[1.3, 1.0], wspace=0.2, left=0.0, right=0.985, top=0.885, bottom=0.075
    )
    gs_right = gs[0, 1].subgridspec(2, 1, height_ratios=[2.0, 1.1], hspace=0.3)
    gs_err = gs_right[0].subgridspec(2, 1, hspace=0.08)

    # -- 3D view: truth, reports, fit; orientation frames of truth and fit. --------------
    ax = fig.add_subplot(gs[0, 0], projection="3d")
    ax.plot(*p_true.T, color=C_TRUE, lw=1.0, ls=(0, (4, 2)), label="ground truth")
    ax.scatter(
        *p_obs[observed].T,
        s=9,
        color=C_OBS,
        alpha=0.85,
        depthshade=False,
        label=f"noisy reports ({observed.sum()} of {K} poses)",
    )
    ax.plot(*p_fit.T, color=C_FIT, lw=2.0, label="fit")
    ax.scatter(
        *p_fit[missing].T,
        s=16,
        marker="o",
        facecolors="none",
        edgecolors=C_GAP,
        linewidths=0.9,
        depthshade=False,
        label=f"fit where the report is missing ({missing.sum()})",
    )
    length = 0.42
    for i in onp.linspace(0, K, n_frames, endpoint=False).astype(int) + K // (2 * n_frames):
        for T, lw, alpha in ((T_true, 1.2, 0.4), (T_fit, 2.2, 1.0)):
            M = onp.asarray(T[int(i)].as_matrix())  # columns: body axes in the world frame
            for axis, rgb in enumerate(C_AXES):
                tip = M[:3, 3] + length * M[:3, axis]
                ax.plot(*onp.stack([M[:3, 3], tip]).T, color=rgb, lw=lw, alpha=alpha)
    lo, hi = p_true.min(0) - 0.5, p_true.max(0) + 0.5
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
    ax.set_box_aspect(hi - lo, zoom=1.12)  # equal scale on all axes: frames look orthogonal
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]", labelpad=-2)
    ax.set_zticks([-0.5, 0.0, 0.5])
    ax.view_init(elev=30, azim=-62)
    handles, labels = ax.get_legend_handles_labels()
    handles.append(tuple(Line2D([], [], color=c, lw=2.2) for c in C_AXES))
    labels.append("body x, y, z axes (fit bold, truth faint)")
    ax.legend(
        handles,
        labels,
        loc="upper left",
        fontsize=8.5,
        framealpha=0.9,
        handler_map={tuple: HandlerTuple(ndivide=None)},
        bbox_to_anchor=(0.03, 1.0),
    )

    # -- Per-pose errors, position and rotation. -----------------------------------------
    idx = onp.arange(K)
    ax_pos = fig.add_subplot(gs_err[0])
    ax_rot = fig.add_subplot(gs_err[1], sharex=ax_pos)
    for which, axe, scale, unit in (
        (0, ax_pos, 100.0, "position error [cm]"),
        (1, ax_rot, 1.0, "rotation error [deg]"),
    ):
        for i in idx[missing]:
            axe.axvspan(i - 0.5, i + 0.5, color=C_GAP, alpha=0.10, lw=0)
        e = {name: scale * err[which] for name, err in errors.items()}
        axe.plot(idx[observed], e["reports"][observed], ".", ms=4, color=C_OBS, label="report")
        axe.plot(
            idx[missing],
            e["naive"][missing],
            "x",
            ms=4,
            color=C_NAIVE,
            label="missing: geodesic between the nearest reports",
        )
        axe.plot(idx, e["fit"], color=C_FIT, lw=1.5, label="fit")
        # Headroom above the largest error for the legend.
        axe.set_ylim(0, 1.45 * max(e["reports"][observed].max(), e["naive"][missing].max()))
        axe.set_ylabel(unit)
        axe.grid(True, lw=0.4, alpha=0.5)
    ax_pos.set_xlim(-0.5, K - 0.5)
    ax_pos.tick_params(labelbottom=False)
    ax_rot.set_xlabel("pose index i   (shaded: report missing)")
    ax_pos.set_title("Error of each pose against the ground truth", fontsize=10)
    ax_pos.legend(
        fontsize=8, ncol=3, loc="upper center", framealpha=0.9, handletextpad=0.3, columnspacing=1.2
    )

    # -- Loss curves. ---------------------------------------------------------------------
    ax2 = fig.add_subplot(gs_right[1])
    it = onp.arange(1, history.shape[0] + 1)  # iteration + 1, for the log axis
    ax2.loglog(it, history[:, 0], color=C_FIT, lw=1.8, label="loss = data + smoothness", zorder=3)
    # The data term is 0 (up to rounding) at the start, which is the reports themselves.
    ax2.loglog(it[1:], history[1:, 1], color=C_OBS, lw=1.1, label="data term")
    ax2.loglog(it, history[:, 2], color="#6a51a3", lw=1.1, label="smoothness term")
    ax2.axhline(loss_true, color=C_TRUE, lw=1.0, ls=(0, (4, 2)), label="loss of the ground truth")
    ax2.set_xlabel("Adam iteration + 1")
    ax2.set_ylabel("loss")
    ax2.set_title("Objective during the fit", fontsize=10)
    ax2.set_xlim(1, it[-1])
    ax2.set_ylim(0.1 * history[1:, 1].min(), 3 * history[:, 0].max())
    ax2.legend(fontsize=8, framealpha=0.9, ncol=2, loc="lower right")
    ax2.grid(True, which="major", lw=0.4, alpha=0.5)

    pos = {
        label: 100 * rmse(errors[name][0][where])
        for label, name, where in (
            ("reports", "reports", observed),
            ("fit_obs", "fit", observed),
            ("naive", "naive", missing),
            ("fit_miss", "fit", missing),
        )
    }
    rot = {
        label: rmse(errors[name][1][where])
        for label, name, where in (
            ("reports", "reports", observed),
            ("fit_obs", "fit", observed),
            ("naive", "naive", missing),
            ("fit_miss", "fit", missing),
        )
    }
    fig.suptitle(
        f"Fitting a smooth SE(3) trajectory to {K} noisy poses, {missing.sum()} of them missing "
        r"(Adam on the tangent space, $T \leftarrow T\,\exp(\delta)$)"
        "\n"
        f"RMSE at observed poses: reports {pos['reports']:.1f} cm, {rot['reports']:.1f}° → fit "
        f"{pos['fit_obs']:.1f} cm, {rot['fit_obs']:.1f}°;   at missing poses: geodesic gap "
        f"filling {pos['naive']:.1f} cm, {rot['naive']:.1f}° → fit {pos['fit_miss']:.1f} cm, "
        f"{rot['fit_miss']:.1f}°",
        fontsize=11.5,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="K = 80, 800 iterations, no bar")
    parser.add_argument("--k", type=int, default=None, help="number of poses (default 150)")
    parser.add_argument("--iters", type=int, default=None, help="Adam iterations (default 5000)")
    parser.add_argument("--lr", type=float, default=0.01, help="initial learning rate")
    parser.add_argument("--lam", type=float, default=1.0, help="weight λ of the smoothness prior")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("out/trajectory_fitting.png"))
    args = parser.parse_args(argv)
    K = args.k or (80 if args.quick else 150)
    iters = args.iters or (800 if args.quick else 5000)

    # -- 1. Data. ------------------------------------------------------------------------
    k_obs, k_miss = jax.random.split(jax.random.key(args.seed))
    T_true = ground_truth(K)
    Z = observe(k_obs, T_true)
    observed = ~missing_mask(k_miss, K)
    # The prior is per step; the true body displacement changes by (step size)² per step,
    # so its σ scales with (150 / K)² to keep the same physical stiffness at any K.
    scale = (150.0 / K) ** 2
    problem = Problem(
        Z_world_body=Z,
        observed=jnp.asarray(observed, dtype=jnp.float32),
        w_data=jnp.asarray([SIGMA_POS**-2] * 3 + [SIGMA_ROT**-2] * 3, dtype=jnp.float32),
        w_smooth=args.lam
        * jnp.asarray(
            [(scale * SIGMA_ACC_POS) ** -2] * 3 + [(scale * SIGMA_ACC_ROT) ** -2] * 3,
            dtype=jnp.float32,
        ),
    )
    print(
        f"{K} poses of a banked figure-eight; {int(observed.sum())} noisy reports "
        f"(σ = {100 * SIGMA_POS:.0f} cm and {onp.rad2deg(SIGMA_ROT):.0f}° per axis), "
        f"{int((~observed).sum())} missing ({100 * (~observed).mean():.0f}%)"
    )

    # -- 2. Fit. Start from the reports, gaps filled by geodesic interpolation. ----------
    T_naive = fill_gaps(Z, observed)
    T_fit, history, first_s, rest_s = fit(T_naive, problem, iters, args.lr, progress=not args.quick)
    loss_true = float(evaluate(T_true, problem)[0])
    print(
        f"Adam on the tangent space, {iters} iterations: first call (tracing + compilation) "
        f"{first_s:.1f} s, then {1e3 * rest_s / max(iters - 1, 1):.2f} ms/iteration"
    )
    print(
        f"  loss {history[0, 0]:.1f} -> {history[-1, 0]:.1f} (data {history[-1, 1]:.1f} + "
        f"smoothness {history[-1, 2]:.1f}); the ground truth scores {loss_true:.1f}"
    )

    # -- 3. How good is it? ----------------------------------------------------------------
    e = {
        name: pose_errors(T, T_true)
        for name, T in (("reports", Z), ("naive", T_naive), ("fit", T_fit))
    }
    missing = ~observed

    def row(label: str, name: str, where: onp.ndarray) -> None:
        pos, rot = e[name]
        print(f"  {label:<46} {100 * rmse(pos[where]):6.2f} cm {rmse(rot[where]):7.2f} deg")

    print(f"RMSE against the ground truth{'':<22}position   rotation")
    print(f" at the {int(observed.sum())} observed poses:")
    row("raw reports", "reports", observed)
    row("fit", "fit", observed)
    print(f" at the {int(missing.sum())} missing poses:")
    row("geodesic between the nearest reports (start)", "naive", missing)
    row("fit", "fit", missing)
    print(f" at all {K} poses:")
    row("fit", "fit", onp.ones(K, bool))

    # -- 4. Picture. -----------------------------------------------------------------------
    draw(args.out, T_true, Z, T_fit, T_naive, observed, history, loss_true)
    print(f"Wrote {args.out}")


if __name__ == "__main__":
    main()
