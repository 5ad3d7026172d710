"""The duck game (Zhang, *A Geometric Introduction to Lie Theory*, 2022, §6.5).

A motorised toy duck is set down at t = 0 and moves with a constant *local* (body-frame)
linear and angular velocity until t = 8, when it stops. It had to rescue some bread from a
burning building at exactly t = 3, but nobody recorded its velocity — only its poses at
t = 0 and t = 8. Was the duck at the bread at t = 3?

Lie theory answers in two lines. The constant body velocity that carries G₀ to G₈ in 8 s
is ξ = log(G₀⁻¹ G₈) / 8, and the pose at any time is G(t) = G₀ exp(t ξ):

    xi = motion.velocity_between(g0, g8, 8.0)     # (vx, vy, ω), body frame
    g3 = motion.pose_at(g0, xi, 3.0)

In the plane the path is an arc of a circle (``motion.arc`` gives its centre and radius);
the naive answer — interpolating x, y and θ linearly — puts the duck on the chord instead.

The second figure plays the same game in 3D (SE(3)): a flying duck with constant linear
*and* angular velocity climbs a helix. Its path turns several times, and the principal log
sees at most half a turn, so the poses at t = 0 and t = 8 alone do not determine the
motion (``velocity_between`` on them gives the shortest screw, a different path with the
same ends). With a second measurement one second in — less than half a turn — the
velocity is recovered exactly, and ``pose_at`` follows it for all eight seconds.

Run: ``python examples/duck_game.py [--out DIR]`` (default ``out/``); writes
``duck_game.png`` and ``duck_game_3d.png``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)  # the story is small; float64 costs nothing here

import jax.numpy as jnp  # noqa: E402
import numpy as onp  # noqa: E402

from jaxlie_geo import SE2, SE3, SO3, motion  # noqa: E402

# --- the 2D story (SE(2): tangent (vx, vy, ω)) ----------------------------------------

T_END = 8.0  # the duck stops
T_BREAD = 3.0  # the bread must be rescued now
POSE_0 = (0.0, 0.0, 0.0)  # x [m], y [m], heading [deg]: set down at the origin, facing +x
POSE_8 = (4.0, 5.0, 150.0)  # measured when the duck has stopped
BREAD = onp.array([3.0, 0.5])  # where the bread is
REACH = 0.5  # the duck grabs bread within this distance [m]

# --- the 3D story (SE(3): tangent (v, ω), jaxlie's order) ------------------------------

# The flying duck's true (unrecorded) body velocity: forward, yawing, with a bit of roll
# rate (so it climbs along the tilted rotation axis) — about 2.6 turns in 8 s.
XI_TRUE_3D = onp.array([1.5, 0.0, 0.0, 0.3, 0.0, 2.0])
T_PROBE = 1.0  # the extra measurement (turn in 1 s: ‖ω‖·1 ≈ 2.0 rad < π)
BREAD_3D_GAP = 0.25  # the bread floats this far outside the helix, next to the t = 3 pose


def se2_pose(x: float, y: float, heading_deg: float) -> SE2:
    return SE2.from_xy_theta(x, y, onp.deg2rad(heading_deg))


def xy_theta(g: SE2) -> onp.ndarray:
    """(..., 3) array of x, y, heading [rad]."""
    return onp.concatenate(
        [onp.asarray(g.translation()), onp.asarray(g.rotation().as_radians())[..., None]], axis=-1
    )


def solve_2d():
    g0, g8 = se2_pose(*POSE_0), se2_pose(*POSE_8)
    xi = motion.velocity_between(g0, g8, T_END)
    g3 = motion.pose_at(g0, xi, T_BREAD)
    return g0, g8, xi, g3


def start_pose_3d() -> SE3:
    """Bank the duck so that its rotation axis ω points straight up (a vertical helix)."""
    w = XI_TRUE_3D[3:] / onp.linalg.norm(XI_TRUE_3D[3:])
    # Rotation about the y axis taking the body's ω direction to +z.
    tilt = onp.arctan2(w[0], w[2])
    return SE3.from_rotation_and_translation(SO3.from_y_radians(-tilt), jnp.array([0.0, 0.0, 0.0]))


def solve_3d():
    g0 = start_pose_3d()
    g1 = motion.pose_at(g0, jnp.asarray(XI_TRUE_3D), T_PROBE)  # "measured" at t = 1
    g8 = motion.pose_at(g0, jnp.asarray(XI_TRUE_3D), T_END)  # "measured" at t = 8
    xi = motion.velocity_between(g0, g1, T_PROBE)
    g3 = motion.pose_at(g0, xi, T_BREAD)
    xi_principal = motion.velocity_between(g0, g8, T_END)  # only the two end poses
    return g0, g1, g8, xi, g3, xi_principal


# --- drawing ---------------------------------------------------------------------------

C_START, C_T3, C_END, C_PATH = "#1b9e77", "#d95f02", "#7570b3", "0.15"
C_BREAD = "#b5651d"


def draw_2d(path: Path, g0: SE2, g8: SE2, xi, g3: SE2) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    arc = motion.arc(g0, xi)
    centre, radius = onp.asarray(arc.centre), float(arc.radius)
    # One body, a batch of times: the dense trail and the whole seconds, in one call.
    tk = onp.arange(0.0, T_END + 0.5, 1.0)
    ts = onp.concatenate([onp.linspace(0.0, T_END, 401), tk])
    poses = xy_theta(motion.pose_at(g0, xi, jnp.asarray(ts)))
    trail, ticks = poses[:401], poses[401:]
    p0, p3, p8 = xy_theta(g0), xy_theta(g3), xy_theta(g8)
    naive = onp.asarray(p0) + (T_BREAD / T_END) * (onp.asarray(p8) - onp.asarray(p0))

    fig, ax = plt.subplots(figsize=(7.6, 6.4), dpi=150)
    phi = onp.linspace(0, 2 * onp.pi, 361)
    ax.plot(
        centre[0] + radius * onp.cos(phi),
        centre[1] + radius * onp.sin(phi),
        ls=(0, (2, 3)),
        lw=0.9,
        color="0.6",
        zorder=1,
        label=f"circle of the motion (r = {radius:.2f} m)",
    )
    ax.plot(*centre, marker="+", ms=10, mew=1.5, color="0.4", ls="none", zorder=2)
    ax.annotate(
        "centre c", centre, xytext=(6, -12), textcoords="offset points", fontsize=9, color="0.35"
    )
    ax.plot([centre[0], p0[0]], [centre[1], p0[1]], lw=0.8, color="0.6", zorder=1)
    ax.plot(
        trail[:, 0],
        trail[:, 1],
        color=C_PATH,
        lw=2.0,
        zorder=3,
        label=r"path $G_0\,\exp(t\,\xi)$, $0 \leq t \leq 8$",
    )
    ax.plot(
        [p0[0], p8[0]],
        [p0[1], p8[1]],
        color="0.55",
        lw=1.0,
        ls="--",
        zorder=2,
        label="chord (naive straight-line interpolation)",
    )

    # The duck's heading (its body x axis) once a second.
    L = 0.55
    u, v = L * onp.cos(ticks[:, 2]), L * onp.sin(ticks[:, 2])
    ax.quiver(
        ticks[:, 0],
        ticks[:, 1],
        u,
        v,
        angles="xy",
        scale_units="xy",
        scale=1,
        width=0.0045,
        headwidth=4,
        headlength=5,
        color="#3b6fb6",
        zorder=4,
        label="heading (body x axis), every 1 s",
    )
    for (x, y, _), t in zip(ticks, tk):
        if t in (0.0, T_BREAD, T_END):
            continue
        # Label on the outside of the circle.
        out = onp.array([x, y]) - centre
        out = out / onp.linalg.norm(out)
        ax.annotate(
            f"{t:.0f} s",
            (x, y),
            xytext=(x + 0.38 * out[0], y + 0.38 * out[1]),
            fontsize=8,
            color="0.3",
            ha="center",
            va="center",
        )

    def key_pose(p, color, marker, label, text, offset):
        ax.quiver(
            [p[0]],
            [p[1]],
            [1.0 * onp.cos(p[2])],
            [1.0 * onp.sin(p[2])],
            angles="xy",
            scale_units="xy",
            scale=1,
            width=0.007,
            color=color,
            zorder=6,
        )
        ax.plot(
            p[0],
            p[1],
            marker=marker,
            ms=10,
            color=color,
            mec="k",
            mew=0.7,
            ls="none",
            zorder=7,
            label=label,
        )
        ax.annotate(
            text,
            (p[0], p[1]),
            xytext=offset,
            textcoords="offset points",
            fontsize=9,
            color=color,
            fontweight="bold",
        )

    key_pose(p0, C_START, "o", r"$G_0$ (t = 0, known)", "t = 0", (-14, -18))
    key_pose(p8, C_END, "s", r"$G_8$ (t = 8, measured)", "t = 8", (8, 8))
    key_pose(p3, C_T3, "*", r"$G_3 = G_0 \exp(3\xi)$ (found)", "t = 3", (8, -17))
    ax.plot(
        *naive[:2],
        marker="X",
        ms=8,
        color="0.55",
        mec="k",
        mew=0.5,
        ls="none",
        zorder=5,
        label="naive guess at t = 3",
    )

    ax.add_patch(
        Circle(
            BREAD,
            REACH,
            facecolor=C_BREAD,
            alpha=0.12,
            edgecolor=C_BREAD,
            lw=0.8,
            ls="--",
            zorder=0,
        )
    )
    ax.plot(
        *BREAD,
        marker="h",
        ms=13,
        color="#e3b26b",
        mec=C_BREAD,
        mew=1.5,
        ls="none",
        zorder=5,
        label=f"bread (reach {REACH} m)",
    )
    ax.annotate(
        "bread",
        BREAD,
        xytext=(-44, 6),
        textcoords="offset points",
        fontsize=9,
        color=C_BREAD,
        fontweight="bold",
    )

    d = float(onp.linalg.norm(p3[:2] - BREAD))
    ax.set_title(
        "The duck game in SE(2): constant body velocity from two poses\n"
        rf"$\xi = \log(G_0^{{-1}}G_8)/8 = ({float(xi[0]):.3f},\ {float(xi[1]):.3f},\ "
        rf"{float(xi[2]):.3f})$,  duck–bread distance at t = 3: {d:.2f} m",
        fontsize=10.5,
    )
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    ax.grid(True, lw=0.4, alpha=0.5)
    lo = onp.minimum(trail[:, :2].min(0), centre - radius) - 0.6
    hi = onp.maximum(trail[:, :2].max(0), centre + radius) + 0.6
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.legend(loc="upper left", fontsize=8, framealpha=0.92, bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def screw_axis(g0: SE3, xi) -> tuple:
    """World-frame point on the screw axis and its unit direction (ω ≠ 0)."""
    xw = onp.asarray(g0.adjoint() @ xi)  # body twist → world (spatial) twist
    v, w = xw[:3], xw[3:]
    return onp.cross(w, v) / (w @ w), w / onp.linalg.norm(w)


def bread_3d(g0: SE3, xi, g3: SE3) -> onp.ndarray:
    q, d = screw_axis(g0, onp.asarray(xi))
    p3 = onp.asarray(g3.translation())
    out = (p3 - q) - ((p3 - q) @ d) * d  # radial direction, away from the axis
    return p3 + BREAD_3D_GAP * out / onp.linalg.norm(out)


def draw_3d(path: Path, g0: SE3, g1: SE3, g8: SE3, xi, g3: SE3, xi_principal) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MultipleLocator

    # Both velocities at once (batch of 2) and all times at once: (K, 1) against (2,).
    n_dense = 801
    tf = onp.arange(0.0, T_END + 1e-9, 0.4)
    ts = onp.concatenate([onp.linspace(0.0, T_END, n_dense), tf])
    paths = motion.pose_at(
        g0, jnp.stack([jnp.asarray(xi), jnp.asarray(xi_principal)]), jnp.asarray(ts)[:, None]
    )
    positions = onp.asarray(paths.translation())  # (K, 2, 3)
    trail, short = positions[:n_dense, 0], positions[:n_dense, 1]
    origins = positions[n_dense:, 0]
    axes = onp.asarray(paths[n_dense:, 0].rotation().as_matrix())  # columns: body x, y, z
    q, d = screw_axis(g0, onp.asarray(xi))
    bread = bread_3d(g0, xi, g3)

    fig = plt.figure(figsize=(8.2, 7.0), dpi=150)
    ax = fig.add_subplot(projection="3d", computed_zorder=False)
    s = onp.array([trail[:, 2].min() - 0.25, trail[:, 2].max() + 0.25])
    axis_pts = q[None] + ((s - q[2]) / d[2])[:, None] * d[None]
    ax.plot(*axis_pts.T, color="0.5", lw=1.0, ls="-.", zorder=1)
    ax.plot(*short.T, color="0.55", lw=1.3, ls="--", zorder=2)
    ax.plot(*trail.T, color=C_PATH, lw=1.8, zorder=3)
    L = 0.2
    frame_colors = ("#d62728", "#2ca02c", "#1f77b4")
    for o, R in zip(origins, axes):
        for j, c in enumerate(frame_colors):
            ax.plot(*onp.stack([o, o + L * R[:, j]]).T, color=c, lw=1.3, zorder=4)
    marks = [
        (g0, C_START, "o", "t = 0"),
        (g1, "#e7298a", "D", "t = 1"),
        (g3, C_T3, "*", "t = 3"),
        (g8, C_END, "s", "t = 8"),
    ]
    for g, c, m, text in marks:
        p = onp.asarray(g.translation())
        ax.scatter(
            *p,
            color=c,
            marker=m,
            s=160 if m == "*" else 60,
            edgecolors="k",
            linewidths=0.6,
            depthshade=False,
            zorder=10,
        )
        ax.text(
            *(p + onp.array([0.0, 0.0, 0.12])),
            text,
            color=c,
            fontsize=9.5,
            fontweight="bold",
            ha="center",
            zorder=11,
        )
    ax.scatter(
        *bread,
        marker="h",
        s=120,
        color="#e3b26b",
        edgecolors=C_BREAD,
        linewidths=1.3,
        depthshade=False,
        zorder=9,
    )

    lo = onp.minimum(trail.min(0), short.min(0)) - 0.3
    hi = onp.maximum(trail.max(0), short.max(0)) + 0.3
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    half[:2] = half[:2].max()
    lo, hi = mid - half, mid + half
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
    ax.set_box_aspect(hi - lo, zoom=1.0)  # equal scale on all axes: frames look orthogonal
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MultipleLocator(0.5))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.view_init(elev=20, azim=-60)
    turns = float(onp.linalg.norm(onp.asarray(xi)[3:])) * T_END / (2 * onp.pi)
    ax.set_title(
        "The duck game in SE(3): a constant body velocity traces a helix\n"
        rf"$\xi = \log(G_0^{{-1}}G_1)/1$: v = {_fmt(xi[:3], 2, '')},  "
        rf"$\omega$ = {_fmt(xi[3:], 2, '')},  {turns:.1f} turns in 8 s",
        fontsize=10.5,
        y=1.02,
    )
    frame = tuple(Line2D([], [], color=c, lw=1.5) for c in frame_colors)
    handles = [
        Line2D([], [], color=C_PATH, lw=1.8),
        Line2D([], [], color="0.55", lw=1.3, ls="--"),
        Line2D([], [], color="0.5", lw=1.0, ls="-."),
        frame,
        Line2D([], [], color=C_START, marker="o", ls="none", mec="k"),
        Line2D([], [], color="#e7298a", marker="D", ls="none", mec="k"),
        Line2D([], [], color=C_T3, marker="*", ms=12, ls="none", mec="k"),
        Line2D([], [], color=C_END, marker="s", ls="none", mec="k"),
        Line2D([], [], color="#e3b26b", marker="h", ms=10, ls="none", mec=C_BREAD),
    ]
    labels = [
        r"path $G_0\exp(t\xi)$, $0 \leq t \leq 8$",
        r"$G_0\exp(t\,\log(G_0^{-1}G_8)/8)$: from the end poses"
        "\n"
        "alone (principal log: shortest screw)",
        r"screw axis of $\xi$",
        "body x / y / z axes every 0.4 s",
        r"$G_0$ (t = 0, known)",
        r"$G_1$ (t = 1, measured)",
        r"$G_3 = G_0\exp(3\xi)$ (found)",
        r"$G_8 = G_0\exp(8\xi)$",
        "bread",
    ]
    fig.legend(
        handles,
        labels,
        loc="center left",
        bbox_to_anchor=(0.80, 0.5),
        fontsize=8,
        framealpha=0.92,
        handler_map={tuple: HandlerTuple(ndivide=None, pad=0.2)},
    )
    fig.subplots_adjust(left=0.0, right=0.80, bottom=0.02, top=0.93)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def _fmt(a, digits: int = 6, sign: str = "+") -> str:
    """'(x, y, ...)', with rounding noise such as -1e-17 shown as 0."""
    return (
        "("
        + ", ".join(f"{round(float(x), digits) + 0.0:{sign}.{digits}f}" for x in onp.ravel(a))
        + ")"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out"), help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    g0, g8, xi, g3 = solve_2d()
    p3 = xy_theta(g3)
    arc = motion.arc(g0, xi)
    dist = float(onp.linalg.norm(p3[:2] - BREAD))
    print("SE(2) duck game")
    print(
        f"  G0 = x, y, heading {POSE_0[:2]}, {POSE_0[2]:.0f} deg;  "
        f"G8 = {POSE_8[:2]}, {POSE_8[2]:.0f} deg"
    )
    print(f"  body velocity xi = (vx, vy, omega) = {_fmt(xi)}  [m/s, m/s, rad/s]")
    print(
        f"  pose at t = 3: x = {p3[0]:.6f} m, y = {p3[1]:.6f} m, "
        f"heading = {onp.rad2deg(p3[2]):.4f} deg"
    )
    print(
        f"  arc: centre {_fmt(arc.centre)}, radius {float(arc.radius):.6f} m, "
        f"curvature {float(arc.curvature):+.6f} 1/m"
    )
    print(
        f"  bread at {_fmt(BREAD)}: distance {dist:.3f} m -> "
        + ("rescued!" if dist <= REACH else "missed.")
    )

    g0s, g1s, g8s, xis, g3s, xip = solve_3d()
    print("SE(3) duck game (helix)")
    print(f"  body velocity xi = (v, omega) = {_fmt(xis)}")
    print(f"  (true velocity                  {_fmt(XI_TRUE_3D)})")
    print(f"  from G0, G8 alone (principal):  {_fmt(xip)}")
    print(
        f"  pose at t = 3: position = {_fmt(g3s.translation())} m, rotation vector = "
        f"{_fmt(g3s.rotation().log())} rad"
    )
    print(f"                 (wxyz_xyz = {_fmt(g3s.wxyz_xyz)})")
    bread = bread_3d(g0s, xis, g3s)
    dist3 = float(onp.linalg.norm(onp.asarray(g3s.translation()) - bread))
    print(
        f"  bread at {_fmt(bread)}: distance {dist3:.3f} m -> "
        + ("rescued!" if dist3 <= REACH else "missed.")
    )

    draw_2d(args.out / "duck_game.png", g0, g8, xi, g3)
    draw_3d(args.out / "duck_game_3d.png", g0s, g1s, g8s, xis, g3s, xip)
    print(f"wrote {args.out / 'duck_game.png'} and {args.out / 'duck_game_3d.png'}")


if __name__ == "__main__":
    main()
