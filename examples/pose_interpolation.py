"""Interpolating a million rigid-body poses in one call.

The geodesic between two poses ``a`` and ``b`` in SE(3) is the constant-velocity screw
motion that takes ``a`` to ``b``:

    a.interpolate(b, t) == a @ SE3.exp(t * log(a⁻¹ @ b))        t = 0 → a,  t = 1 → b

This script shows, in order:

1. how to interpolate 10⁶ random pose pairs, each at its own time ``t``, in a single
   ``jax.jit`` call (float32), and how long one pose takes;
2. the speed-up over the same expression written with jaxlie 1.5 (if it is installed)
   and over a plain Python loop, and the largest difference from jaxlie's result;
3. a picture of a few geodesics, drawn as small coordinate frames along their paths,
   written to ``out/pose_interpolation.png``.

Run it with ``make demo`` or ``python examples/pose_interpolation.py``
(``--quick`` for a fast smoke run, ``--n`` to change the batch size).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as onp

import jaxlie_geo as jlg
from jaxlie_geo import SE3, SO3

try:  # Optional: only used for the comparison.
    import jaxlie
except ImportError:  # pragma: no cover - depends on the environment
    jaxlie = None


# ---------------------------------------------------------------------------------------
# 1. The batched computation.
#
# ``a`` and ``b`` hold N poses each (batch axes (N,)), ``t`` holds N times. Batch axes
# broadcast numpy-style, so this one line interpolates pair i at time t[i]. Wrapping it
# in ``jax.jit`` fuses log, exp and the two compositions into one compiled kernel.


@jax.jit
def interpolate_ours(a: SE3, b: SE3, t: jax.Array) -> SE3:
    return a.interpolate(b, t)


# The same geodesic, spelled out with jaxlie 1.5 (which has no ``interpolate``).
@jax.jit
def interpolate_jaxlie(a, b, t):
    return a @ jaxlie.SE3.exp(t[:, None] * (a.inverse() @ b).log())


@jax.jit
def max_matrix_difference(ours: SE3, theirs_params: jax.Array):
    """Largest entry-wise difference between two batches of poses as 4x4 matrices, and
    the index of the pose where it occurs."""
    theirs = SE3(theirs_params)  # same (qw, qx, qy, qz, x, y, z) layout as jaxlie
    per_pose = jnp.max(jnp.abs(ours.as_matrix() - theirs.as_matrix()), axis=(-2, -1))
    return jnp.max(per_pose), jnp.argmax(per_pose)


# ---------------------------------------------------------------------------------------
# 2. The baseline: one pose at a time in plain NumPy (float64), as you might write it
#    without JAX. Quaternions are (w, x, y, z), like jaxlie's.


def _quat_mul(p: onp.ndarray, q: onp.ndarray) -> onp.ndarray:
    pw, pv, qw, qv = p[0], p[1:], q[0], q[1:]
    return onp.concatenate([[pw * qw - pv @ qv], pw * qv + qw * pv + onp.cross(pv, qv)])


def _skew(w: onp.ndarray) -> onp.ndarray:
    return onp.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _quat_to_matrix(q: onp.ndarray) -> onp.ndarray:
    w, v = q[0], q[1:]
    return (w * w - v @ v) * onp.eye(3) + 2.0 * onp.outer(v, v) + 2.0 * w * _skew(v)


def numpy_interpolate_one(pa: onp.ndarray, pb: onp.ndarray, t: float) -> onp.ndarray:
    """``a @ exp(t log(a⁻¹ b))`` for one pair of (w, x, y, z, tx, ty, tz) poses → 4x4."""
    qa, qb = pa[:4], pb[:4]
    qa_inv = qa * onp.array([1.0, -1.0, -1.0, -1.0])
    R_a = _quat_to_matrix(qa)
    # Relative pose a⁻¹ b.
    q_rel = _quat_mul(qa_inv, qb)
    q_rel = q_rel if q_rel[0] >= 0.0 else -q_rel
    p_rel = R_a.T @ (pb[4:] - pa[4:])
    # log: rotation vector ω and translational part v = V(ω)⁻¹ p.
    s = onp.linalg.norm(q_rel[1:])
    theta = 2.0 * onp.arctan2(s, q_rel[0])
    omega = q_rel[1:] * (theta / s if s > 1e-12 else 2.0)
    W = _skew(omega)
    if theta > 1e-6:
        c = (1.0 - theta * onp.sin(theta) / (2.0 * (1.0 - onp.cos(theta)))) / theta**2
    else:
        c = 1.0 / 12.0
    v = (onp.eye(3) - 0.5 * W + c * W @ W) @ p_rel
    # exp of the scaled tangent t·(v, ω): Rodrigues for the rotation, V(tω) for the translation.
    th, W = t * theta, t * W
    if th > 1e-6:
        A, B, C = onp.sin(th) / th, (1 - onp.cos(th)) / th**2, (th - onp.sin(th)) / th**3
    else:
        A, B, C = 1.0, 0.5, 1.0 / 6.0
    R_t = onp.eye(3) + A * W + B * W @ W
    p_t = (onp.eye(3) + B * W + C * W @ W) @ (t * v)
    # Compose with a.
    out = onp.eye(4)
    out[:3, :3] = R_a @ R_t
    out[:3, 3] = R_a @ p_t + pa[4:]
    return out


# ---------------------------------------------------------------------------------------
# Timing helpers.


def _time_call(fn, *args) -> float:
    start = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return time.perf_counter() - start


def _fmt_time(seconds: float) -> str:
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6), ("ns", 1e-9)):
        if seconds >= scale:
            return f"{seconds / scale:.3g} {unit}"
    return f"{seconds / 1e-9:.3g} ns"


# ---------------------------------------------------------------------------------------
# 3. The picture.


def draw_geodesics(path: Path, frames_per_path: int = 12) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MultipleLocator

    # Four hand-picked pose pairs (rotation from roll/pitch/yaw, then translation) with
    # large relative rotations, so that the screw motion is visible.
    def pose(rpy_deg, xyz):
        r, p, y = jnp.deg2rad(jnp.asarray(rpy_deg, dtype=jnp.float32))
        return SE3.from_rotation_and_translation(
            SO3.from_rpy_radians(r, p, y), jnp.asarray(xyz, dtype=jnp.float32)
        )

    starts = jlg.stack(
        [
            pose([0, 0, 0], [0.0, 0.0, 0.0]),
            pose([0, 0, 0], [0.0, 2.5, 0.0]),
            pose([90, 0, 0], [0.0, 5.0, 0.0]),
            pose([0, -30, 45], [0.0, 7.5, 0.0]),
        ]
    )
    ends = jlg.stack(
        [
            pose([0, 0, 170], [4.0, 0.0, 0.0]),  # mostly a turn about z: an arc
            pose([160, 0, 0], [4.0, 2.5, 1.5]),  # a turn about x: a corkscrew
            pose([-60, 80, 0], [4.0, 5.0, 1.5]),
            pose([120, 30, -90], [4.0, 8.0, 0.0]),
        ]
    )

    # One call gives every frame of every path: t has shape (K, 1) and the endpoints
    # have batch axes (4,), so they broadcast to (K, 4).
    t = jnp.linspace(0.0, 1.0, frames_per_path, dtype=jnp.float32)
    frames = starts.interpolate(ends, t[:, None])
    # A geodesic object computes log(a⁻¹ b) once; evaluate it densely for the path line.
    dense = jlg.geodesic(starts, ends)(jnp.linspace(0.0, 1.0, 200, dtype=jnp.float32)[:, None])

    M = onp.asarray(frames.as_matrix())  # (K, 4, 4, 4)
    origins = M[..., :3, 3]
    axes = M[..., :3, :3]  # columns are the frame's x, y, z axes
    trail = onp.asarray(dense.translation())  # (200, 4, 3)

    fig = plt.figure(figsize=(9, 6.5), dpi=130)
    ax = fig.add_subplot(projection="3d")
    length = 0.3  # drawn length of a frame's axes
    for j in range(starts.get_batch_axes()[0]):
        ax.plot(*trail[:, j].T, color="0.45", lw=1.2)
        for k in range(frames_per_path):
            at_end = k in (0, frames_per_path - 1)
            scale, width = (1.5, 2.8) if at_end else (1.0, 1.3)
            for axis, rgb in enumerate(("red", "green", "blue")):
                tip = origins[k, j] + scale * length * axes[k, j, :, axis]
                ax.plot(*onp.stack([origins[k, j], tip]).T, color=rgb, lw=width)
        ax.text(
            *(origins[0, j] + [-0.25, 0, 0]),
            "a",
            fontsize=12,
            ha="right",
            va="center",
            weight="bold",
        )
        ax.text(
            *(origins[-1, j] + [0.25, 0, 0]),
            "b",
            fontsize=12,
            ha="left",
            va="center",
            weight="bold",
        )

    lo, hi = onp.min(trail, axis=(0, 1)) - 0.5, onp.max(trail, axis=(0, 1)) + 0.5
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
    ax.set_box_aspect(hi - lo, zoom=1.15)  # equal scale on all axes: frames look orthogonal
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MultipleLocator(1.0))
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")
    ax.view_init(elev=38, azim=-58)
    ax.set_title(
        f"SE(3) geodesics  a.interpolate(b, t),  {frames_per_path} frames per path, t ∈ [0, 1]\n"
        "each path is a constant-velocity screw motion",
        fontsize=11,
    )
    handles = [Line2D([], [], color=c, lw=2.5) for c in ("red", "green", "blue")]
    handles.append(Line2D([], [], color="0.45", lw=1.2))
    fig.legend(
        handles,
        ["frame x axis", "frame y axis", "frame z axis", "translation path"],
        loc="upper left",
        bbox_to_anchor=(0.02, 0.9),
        fontsize=9,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=None, help="number of pose pairs (default 10⁶)")
    parser.add_argument("--quick", action="store_true", help="small n, fewer repeats")
    parser.add_argument("--repeats", type=int, default=None, help="timed runs (default 7)")
    parser.add_argument("--loop-n", type=int, default=None, help="pairs timed in the Python loops")
    parser.add_argument("--out", type=Path, default=Path("out/pose_interpolation.png"))
    args = parser.parse_args()
    n = args.n or (10_000 if args.quick else 1_000_000)
    repeats = args.repeats or (3 if args.quick else 7)
    loop_n = min(n, args.loop_n or (20 if args.quick else 200))

    # -- Inputs: uniformly random rotations, translations in [-1, 1]³, t in [0, 1]. ------
    key_a, key_b, key_t = jax.random.split(jax.random.key(0), 3)
    a = SE3.sample_uniform(key_a, batch_axes=(n,), dtype=jnp.float32)
    b = SE3.sample_uniform(key_b, batch_axes=(n,), dtype=jnp.float32)
    t = jax.random.uniform(key_t, (n,), dtype=jnp.float32)
    jax.block_until_ready((a, b, t))
    print(
        f"Interpolating {n:,} SE3 pose pairs (float32) on {jax.devices()[0].platform}, "
        f"{os.cpu_count()} CPU cores"
    )

    # -- Speed. The first call traces and compiles; later calls reuse the kernel. -------
    compile_s = _time_call(interpolate_ours, a, b, t)
    print(f"  compile (first call, incl. tracing)    {_fmt_time(compile_s):>9}")
    if jaxlie is not None:
        a_jl, b_jl = jaxlie.SE3(a.wxyz_xyz), jaxlie.SE3(b.wxyz_xyz)  # the very same arrays
        _time_call(interpolate_jaxlie, a_jl, b_jl, t)  # compile jaxlie's version too

    # Timed runs, interleaved so that both libraries see the same machine state.
    ours_runs, jaxlie_runs = [], []
    for _ in range(repeats):
        ours_runs.append(_time_call(interpolate_ours, a, b, t))
        if jaxlie is not None:
            jaxlie_runs.append(_time_call(interpolate_jaxlie, a_jl, b_jl, t))
    ours = statistics.median(ours_runs) / n  # seconds per pose
    print(
        f"  jaxlie_geo, one jit call               {_fmt_time(ours):>9}/pose "
        f"({_fmt_time(ours * n)} per call, median of {repeats} runs)"
    )
    if jaxlie is not None:
        theirs = statistics.median(jaxlie_runs) / n
        print(
            f"  jaxlie 1.5, same expression, jit       {_fmt_time(theirs):>9}/pose "
            f"-> jaxlie_geo is {theirs / ours:.1f}x faster"
        )
    else:
        print("  jaxlie not installed: no jaxlie comparison (pip install 'jaxlie==1.5.*')")

    # Python loops over a small subsample; the cost per pose is flat, so we extrapolate.
    pa, pb, tt = (onp.asarray(x, dtype=onp.float64) for x in (a.wxyz_xyz, b.wxyz_xyz, t))
    start = time.perf_counter()
    loop_result = onp.stack([numpy_interpolate_one(pa[i], pb[i], tt[i]) for i in range(loop_n)])
    numpy_loop = (time.perf_counter() - start) / loop_n
    print(
        f"  Python loop, NumPy per pose            {_fmt_time(numpy_loop):>9}/pose "
        f"-> jaxlie_geo is {numpy_loop / ours:,.0f}x faster"
    )

    pa32, pb32, tt32 = (onp.asarray(x[:loop_n]) for x in (a.wxyz_xyz, b.wxyz_xyz, t))
    SE3(pa32[0]).interpolate(SE3(pb32[0]), tt32[0])  # compile the unbatched kernel first
    start = time.perf_counter()
    for i in range(loop_n):
        jax.block_until_ready(SE3(pa32[i]).interpolate(SE3(pb32[i]), tt32[i]))
    eager_loop = (time.perf_counter() - start) / loop_n
    print(
        f"  Python loop, jaxlie_geo call per pose  {_fmt_time(eager_loop):>9}/pose "
        f"-> jaxlie_geo is {eager_loop / ours:,.0f}x faster"
    )
    print(
        f"    (loops timed on {loop_n} pairs, extrapolated to {n:,}: "
        f"{_fmt_time(numpy_loop * n)} and {_fmt_time(eager_loop * n)})"
    )

    # -- Accuracy. -----------------------------------------------------------------------
    print("Accuracy (float32 results)")
    ours_out = interpolate_ours(a, b, t)
    if jaxlie is not None:
        jaxlie_out = interpolate_jaxlie(a_jl, b_jl, t)
        diff, worst = (x.item() for x in max_matrix_difference(ours_out, jaxlie_out.wxyz_xyz))
        print(f"  max |ours - jaxlie| over {n:,} poses, as 4x4 matrices: {diff:.2e}")
        # Where the two libraries disagree most, ask a float64 reference which is right.
        ref = numpy_interpolate_one(pa[worst], pb[worst], tt[worst])
        ours_err = onp.max(onp.abs(onp.asarray(ours_out[worst].as_matrix()) - ref))
        jaxlie_err = onp.max(onp.abs(onp.asarray(jaxlie_out.as_matrix()[worst]) - ref))
        print(
            f"    worst pair #{worst:,} vs a float64 NumPy reference: "
            f"ours {ours_err:.1e}, jaxlie {jaxlie_err:.1e}"
        )
    ref_diff = onp.max(onp.abs(loop_result - onp.asarray(ours_out.as_matrix()[:loop_n])))
    print(f"  max |ours - float64 NumPy| over the {loop_n} looped pairs: {ref_diff:.2e}")

    # -- Picture. ------------------------------------------------------------------------
    draw_geodesics(args.out)
    print(f"Wrote {args.out}")


if __name__ == "__main__":
    main()
