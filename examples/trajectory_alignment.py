"""Aligning an estimated trajectory to its ground truth: SE(3) or Sim(3).

A monocular visual odometry estimate knows its trajectory only up to a similarity: it
starts in a frame of its own, with a unit of length fixed arbitrarily at initialisation,
and that scale then drifts slowly as the run goes on. Before the estimate can be scored
against the ground truth, it must be brought into the ground truth's frame by the
transform T that minimises

    Σ_k ‖p_k − T @ p̂_k‖²        (p_k true positions, p̂_k estimated ones),

which has a closed form (Umeyama, IEEE TPAMI 13(4), 1991): ``Sim3.align(p̂, p)`` for a
similarity (rotation, translation and scale), ``SE3.align(p̂, p)`` for a rigid transform.
The score is then the absolute trajectory error (ATE), the RMSE of the aligned positions,

    ATE = sqrt(mean_k ‖p_k − T @ p̂_k‖²).

This script builds the data itself:

1. the ground truth, K poses along a smooth closed 3D path (a rounded figure-eight with a
   climb, heading along the direction of travel);
2. the estimate, as a drifting odometry produces it: the relative motions between
   consecutive poses, their translations multiplied by a scale that drifts by about +25%
   over the run and perturbed by small noise, chained again from the start (a
   ``jax.lax.scan`` of SE(3) products), plus small position noise, then seen through an
   unknown similarity (the estimate's own frame and unit of length);
3. the two alignments, the ATE before alignment, after the SE(3) one (the rotation and
   translation are fitted, the unit of length stays wrong) and after the Sim(3) one (only
   the drift is left), and, with ``weights``, a Sim(3) alignment on the first poses only
   (as when only the start of a run is surveyed): the drift then shows in full.

It prints these numbers and draws the top view of the ground truth, the raw estimate and
both aligned estimates, with the per-pose errors, to ``docs/gallery/trajectory_alignment.png``.

Run: ``python examples/trajectory_alignment.py`` (K = 300 poses; about 10 s on two shared
CPU cores, nearly all of it start-up and compilation);
``--quick`` (K = 120) is the tests' smoke run; ``--out`` changes the picture path.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Dict

import jax
import jax.numpy as jnp
import numpy as onp

from jaxlie_geo import SE3, SO3, Sim3

# ---------------------------------------------------------------------------------------
# 0. Settings.

SCALE_DRIFT = 0.25  # the estimated step lengths grow by this fraction over the run ...
SCALE_WOBBLE = 0.03  # ... with a random wobble of this size (in log-scale) on top
STEP_NOISE_POS = 0.005  # odometry noise per step, each translation coordinate [m]
STEP_NOISE_ROT = onp.deg2rad(0.05)  # odometry noise per step, each rotation coordinate [rad]
POSITION_NOISE = 0.02  # noise of the reported positions [m, in the true unit]
# The estimate's frame, ``p = TRUE_FRAME @ p̂`` before the drift: where its origin lies, how
# it is turned, and its unit of length (one estimated unit is 2.5 m).
FRAME_UNIT = 2.5
TRUE_FRAME = Sim3.from_rotation_translation_and_scale(
    SO3.from_rpy_radians(0.15, -0.1, 0.8), jnp.asarray([-4.0, 3.0, 1.0]), FRAME_UNIT
)


# ---------------------------------------------------------------------------------------
# 1. The ground truth.


def ground_truth(K: int) -> SE3:
    """K poses ``T_world_body`` along a closed rounded figure-eight, x ∈ [−12, 12] m,
    y ∈ [−6, 6] m, climbing and descending 2 m; the body x axis along the velocity."""
    s = onp.linspace(0.0, 2.0 * onp.pi, K, endpoint=False)
    p = onp.stack([12.0 * onp.sin(s), 6.0 * onp.sin(2 * s), 2.0 * onp.sin(s) ** 2], -1)
    v = onp.stack([12.0 * onp.cos(s), 12.0 * onp.cos(2 * s), 2.0 * onp.sin(2 * s)], -1)
    yaw = onp.arctan2(v[:, 1], v[:, 0])
    pitch = -onp.arcsin(v[:, 2] / onp.linalg.norm(v, axis=-1))
    f32 = lambda x: jnp.asarray(x, dtype=jnp.float32)  # noqa: E731
    R = SO3.from_rpy_radians(f32(onp.zeros(K)), f32(pitch), f32(yaw))
    return SE3.from_rotation_and_translation(R, f32(p))


# ---------------------------------------------------------------------------------------
# 2. The estimate: drifting odometry, seen through an unknown similarity.


def odometry(rng: onp.random.Generator, T_true: SE3) -> jax.Array:
    """Positions ``(K, 3)`` of the estimate, in its own frame and unit.

    The steps ``T_k⁻¹ T_{k+1}`` of the ground truth, their translations multiplied by the
    drifting scale λ_k and each step perturbed on the right by ``exp(n)``, n small; chained
    from the first pose, ``T_0 ∘ step_0 ∘ … ∘ step_{k−1}`` (a ``jax.lax.scan`` over the
    steps, each an ``SE3`` element); then given position noise and mapped into the
    estimate's frame by ``TRUE_FRAME⁻¹``. The random numbers come from ``rng``."""
    K = T_true.get_batch_axes()[0]
    dtype = T_true.parameters().dtype
    tau = onp.linspace(0.0, 1.0, K - 1)
    wobble = onp.cumsum(rng.normal(size=K - 1)) / onp.sqrt(K - 1.0)  # a random walk
    scale = onp.exp(onp.log1p(SCALE_DRIFT) * tau + SCALE_WOBBLE * wobble)  # λ_k
    sigma = onp.array([STEP_NOISE_POS] * 3 + [STEP_NOISE_ROT] * 3)
    n_step = sigma * rng.normal(size=(K - 1, 6))
    n_pos = POSITION_NOISE * rng.normal(size=(K, 3))
    return _odometry(T_true, *(jnp.asarray(a, dtype) for a in (scale, n_step, n_pos)))


@jax.jit
def _odometry(T_true: SE3, scale: jax.Array, n_step: jax.Array, n_pos: jax.Array) -> jax.Array:
    steps = T_true[:-1].inverse() @ T_true[1:]  # (K − 1,) body-frame motions
    steps = SE3.from_rotation_and_translation(
        steps.rotation(), scale[:, None] * steps.translation()
    ) @ SE3.exp(n_step)

    def chain(T: SE3, step: SE3):  # one odometry update, T_{k+1} = T_k ∘ step_k
        T = T @ step
        return T, T.translation()

    _, p_rest = jax.lax.scan(chain, T_true[0], steps)
    p = jnp.concatenate([T_true[0].translation()[None], p_rest]) + n_pos
    return TRUE_FRAME.inverse() @ p  # the estimate reports p̂ with TRUE_FRAME @ p̂ ≈ p


# ---------------------------------------------------------------------------------------
# 3. Alignment and error.


@jax.jit
def align(p_est: jax.Array, p_true: jax.Array, weights_start: jax.Array):
    """The three alignments of the estimate, compiled together: ``Sim3.align`` and
    ``SE3.align`` on all poses, and ``Sim3.align`` weighted by ``weights_start`` (1 on the
    first poses, 0 elsewhere). Returns the three elements and the estimate mapped by each."""
    T_sim3 = Sim3.align(p_est, p_true)
    T_se3 = SE3.align(p_est, p_true)
    T_start = Sim3.align(p_est, p_true, weights_start)
    return (T_sim3, T_se3, T_start), (T_sim3 @ p_est, T_se3 @ p_est, T_start @ p_est)


def ate(p_true, p_est) -> float:
    """Absolute trajectory error: the RMSE of the positions, [m]."""
    d = onp.asarray(p_true, onp.float64) - onp.asarray(p_est, onp.float64)
    return float(onp.sqrt(onp.mean(onp.sum(d * d, axis=-1))))


# ---------------------------------------------------------------------------------------
# 4. The picture.

C_TRUE, C_RAW, C_SE3, C_SIM3 = "0.1", "#e6873c", "#b2182b", "#2166ac"


def draw(path: Path, p_true, p_raw, p_se3, p_sim3, errors: Dict[str, float]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p_true, p_raw, p_se3, p_sim3 = (onp.asarray(p) for p in (p_true, p_raw, p_se3, p_sim3))
    K = p_true.shape[0]
    fig, (ax, ax_err) = plt.subplots(
        1, 2, figsize=(14, 6.2), dpi=130, gridspec_kw={"width_ratios": [1.25, 1.0]}
    )
    ax.plot(*p_true[:, :2].T, color=C_TRUE, lw=1.3, ls=(0, (4, 2)), label="ground truth")
    ax.plot(
        *p_raw[:, :2].T,
        color=C_RAW,
        lw=1.4,
        label=f"raw estimate, its own frame and unit (ATE {errors['before alignment']:.2f} m)",
    )
    ax.plot(
        *p_se3[:, :2].T,
        color=C_SE3,
        lw=1.6,
        label=f"SE3.align: rotation + translation (ATE {errors['after SE3 alignment']:.2f} m)",
    )
    ax.plot(
        *p_sim3[:, :2].T,
        color=C_SIM3,
        lw=1.8,
        label=f"Sim3.align: + scale (ATE {errors['after Sim3 alignment']:.2f} m)",
    )
    for p, c in ((p_true, C_TRUE), (p_raw, C_RAW), (p_se3, C_SE3), (p_sim3, C_SIM3)):
        ax.plot(*p[0, :2], "o", color=c, ms=5)  # start of each trajectory
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Top view (dots: first pose)", fontsize=10)
    ax.grid(True, lw=0.4, alpha=0.5)
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + 0.3 * (hi - lo))  # headroom for the legend
    ax.legend(fontsize=8.5, loc="upper left", framealpha=0.9)

    idx = onp.arange(K)
    for p, c, label in (
        (p_se3, C_SE3, "after SE3.align"),
        (p_sim3, C_SIM3, "after Sim3.align"),
    ):
        ax_err.plot(idx, onp.linalg.norm(p - p_true, axis=-1), color=c, lw=1.5, label=label)
    ax_err.set_xlim(0, K - 1)
    ax_err.set_ylim(0, None)
    ax_err.set_xlabel("pose index k (the scale drifts as k grows)")
    ax_err.set_ylabel("position error ‖p_k − T p̂_k‖ [m]")
    ax_err.set_title("Error of each aligned position", fontsize=10)
    ax_err.grid(True, lw=0.4, alpha=0.5)
    ax_err.legend(fontsize=8.5, framealpha=0.9)

    fig.suptitle(
        f"Aligning a monocular-style estimate of {K} poses (scale drift "
        f"+{100 * SCALE_DRIFT:.0f}%) to the ground truth by least squares (Umeyama 1991)",
        fontsize=11.5,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------


def main(argv=None) -> Dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="K = 120 poses")
    parser.add_argument("--k", type=int, default=None, help="number of poses (default 300)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("docs/gallery/trajectory_alignment.png"))
    args = parser.parse_args(argv)
    K = args.k or (120 if args.quick else 300)

    T_true = ground_truth(K)
    p_true = T_true.translation()
    p_est = odometry(onp.random.default_rng(args.seed), T_true)
    print(
        f"{K} ground-truth poses; the estimate: scale drift +{100 * SCALE_DRIFT:.0f}% over the "
        f"run, odometry noise {1000 * STEP_NOISE_POS:.0f} mm and "
        f"{onp.rad2deg(STEP_NOISE_ROT):.2f}° per step, position noise "
        f"{100 * POSITION_NOISE:.0f} cm, in a frame of its own with unit "
        f"{FRAME_UNIT:.2f} m"
    )

    first = max(K // 5, 3)
    weights = jnp.asarray(onp.arange(K) < first, p_est.dtype)  # the first poses only
    (T_sim3, _, T_start), (p_sim3, p_se3, p_start) = align(p_est, p_true, weights)

    errors = {
        "before alignment": ate(p_true, p_est),
        "after SE3 alignment": ate(p_true, p_se3),
        "after Sim3 alignment": ate(p_true, p_sim3),
        f"after Sim3 alignment on the first {first} poses": ate(p_true, p_start),
    }
    for label, value in errors.items():
        print(f"  ATE {label:<44} {value:8.3f} m")
    print(
        f"  scale of Sim3.align: {onp.exp(T_sim3.log_scale()):.3f} (the frame's "
        f"{FRAME_UNIT:.2f} divided by the drift, 1 at the start to "
        f"{1 + SCALE_DRIFT:.2f} at the end); on the first {first} poses: "
        f"{onp.exp(T_start.log_scale()):.3f}"
    )

    draw(args.out, p_true, p_est, p_se3, p_sim3, errors)
    print(f"Wrote {args.out}")
    return errors


if __name__ == "__main__":
    main()
