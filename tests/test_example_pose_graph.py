"""examples/pose_graph.py: run it as a user would (--quick), and check its pieces in-process.

The subprocess test reads the printed report: the analytic-vs-autodiff Jacobian check, the
cost at every Levenberg–Marquardt iteration (never increasing), the errors against ground
truth before and after, and the figure. The in-process tests import the example (it is not
a package) and check the Jacobians at large angles, the gradient of the normal equations
against autodiff, exact recovery from noise-free measurements, and Gauss–Newton. The last
two run ``main(["--file", ...])`` in-process on small g2o (2D) and TORO (3D) files written
here, with measurements drawn from the noise their information states, and check the report,
the χ² expectation at the optimum, the picture and the written graph.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Dict, List

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import over_se_groups

from jaxlie_geo import SE2, SE3, SO3, manifold, pose_graph

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "examples" / "pose_graph.py"
PROBLEMS = ("SE(2) Manhattan walk", "SE(3) sphere")


def _load_example() -> ModuleType:
    spec = importlib.util.spec_from_file_location("example_pose_graph", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the class is built
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def pg() -> ModuleType:
    return _load_example()


# ---------------------------------------------------------------------------------------
# The script, end to end.


def _section(out: str, name: str) -> str:
    """The report of one problem: from its header to the next header (or the end)."""
    start = out.index(f"{name}:")
    ends = [
        out.index(f"{other}:", start + 1)
        for other in PROBLEMS
        if other != name and f"{other}:" in out[start + 1 :]
    ]
    return out[start : min(ends)] if ends else out[start:]


def _parse(section: str) -> Dict[str, object]:
    jac = re.search(r"max \|analytic - jax\.jacfwd\|: dr/dT_i (\S+), dr/dT_j (\S+)", section)
    assert jac, section
    iters = re.finditer(r"^\s+iter\s+(\d+)\s+cost (\S+)", section, re.M)
    costs = [float(m.group(2)) for m in iters]
    expected = re.search(r"expected at the optimum: (\S+) \+- (\S+),", section)
    assert expected, section
    errors = {}
    for which in ("odometry ", "optimised"):
        m = re.search(
            rf"error vs ground truth, {which}: position RMSE\s+(\S+) m, "
            rf"rotation RMSE\s+(\S+) deg",
            section,
        )
        assert m, section
        errors[which.strip()] = (float(m.group(1)), float(m.group(2)))
    return dict(
        jac=(float(jac.group(1)), float(jac.group(2))),
        costs=costs,
        expected=(float(expected.group(1)), float(expected.group(2))),
        errors=errors,
    )


def test_pose_graph_quick(tmp_path: Path) -> None:
    """``examples/pose_graph.py --quick`` runs and reports what it should, for both problems:
    analytic Jacobians equal to jax.jacfwd, LM costs that never rise and end at the
    chi-square expectation, errors well below dead reckoning; and it writes a real PNG."""
    png = tmp_path / "pictures" / "x.png"  # parent does not exist yet
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick", "--out", str(png)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = proc.stdout
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{out}\nstderr:\n{proc.stderr}"

    for name in PROBLEMS:
        report = _parse(_section(out, name))
        # Analytic Jacobians agree with jax.jacfwd through a right perturbation (float64).
        assert max(report["jac"]) < 1e-10, (name, report["jac"])
        # LM only accepts steps that lower the cost: one line per iteration, never up.
        costs: List[float] = report["costs"]
        assert len(costs) >= 3, (name, costs)
        assert all(b <= a for a, b in zip(costs, costs[1:])), (name, costs)
        assert costs[-1] < costs[0] / 10, (name, costs)
        # At the optimum 2F is chi-square with (E - N + 1)k dof: within 4 standard deviations.
        mean, std = report["expected"]
        assert abs(costs[-1] - mean) < 4 * std, (name, costs[-1], mean, std)
        # Much closer to the ground truth than the dead-reckoning initialisation.
        (p0, r0), (p1, r1) = report["errors"]["odometry"], report["errors"]["optimised"]
        assert p1 < 0.25 * p0 and r1 < 0.33 * r0, (name, report["errors"])

    # A real, non-trivial PNG.
    assert png.is_file(), out
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 50_000


# ---------------------------------------------------------------------------------------
# The pieces, in-process (conftest enables float64).


def _random_edge(G: type, seed: int, angle: float):
    """T_world_bi, T_world_bj and a measurement whose residual rotates by ``angle``."""
    rng = np.random.default_rng(seed)
    T_i = G.exp(jnp.asarray(rng.normal(size=G.tangent_dim) * 2.0))
    T_j = G.exp(jnp.asarray(rng.normal(size=G.tangent_dim) * 2.0))
    r = rng.normal(size=G.tangent_dim)
    rot = slice(G.space_dim, None)  # θ (SE2) or ω (SE3)
    r[rot] *= angle / np.linalg.norm(r[rot])
    Z = (T_i.inverse() @ T_j) @ G.exp(-jnp.asarray(r))  # so that log(Z⁻¹ T_i⁻¹ T_j) = r
    return T_i, T_j, Z, r


@over_se_groups
@pytest.mark.parametrize("angle", [0.0, 1e-9, 0.5, 2.0, 3.0])
def test_jacobians_match_autodiff(pg: ModuleType, G: type, angle: float) -> None:
    """The example's closed-form edge Jacobians (poses: the SE groups) equal autodiff and the
    docstring's other closed form J_i = −J_r⁻¹(r) Ad(T_j⁻¹ T_i), at residual rotations from
    0 to 3 rad."""
    T_i, T_j, Z, r_want = _random_edge(G, seed=int(10 * angle) + G.tangent_dim, angle=angle)
    r, J_i, J_j = pg.edge_residual_and_jacobians(T_i, T_j, Z)
    np.testing.assert_allclose(r, r_want, atol=1e-12)
    A_i, A_j = pg.edge_jacobians_autodiff(T_i, T_j, Z)
    np.testing.assert_allclose(J_i, A_i, atol=1e-9)
    np.testing.assert_allclose(J_j, A_j, atol=1e-9)
    # The other closed form quoted in the docstring: J_i = −J_r⁻¹(r) Ad(T_j⁻¹ T_i).
    np.testing.assert_allclose(
        J_i, -G.jac_right_inv(r) @ (T_j.inverse() @ T_i).adjoint(), atol=1e-10
    )


@pytest.fixture(scope="module")
def small_graphs(pg: ModuleType):
    return [pg.make_manhattan_se2(60, seed=3, blocks=2), pg.make_sphere_se3(3, 10, seed=3)]


def test_gradient_and_gauge(pg: ModuleType, small_graphs) -> None:
    """H is symmetric with an identity block for pose 0 (the gauge) and g = Σ Jᵀ W² r is
    the gradient of F with respect to right perturbations of every pose, pose 0's entry
    zeroed (checked with jax.grad on the SE(2) graph; the SE(3) one compiles slowly)."""
    for graph in small_graphs:
        T = graph.T_world_body_odom
        k = type(T).tangent_dim
        r, J_i, J_j = pg.linearise(T, graph.edge_i, graph.edge_j, graph.T_bi_bj_meas)
        H, g, cost = pg.normal_equations(
            r, J_i, J_j, graph.edge_i, graph.edge_j, graph.sqrt_info, n_poses=graph.n_poses
        )
        np.testing.assert_allclose(H, H.T, atol=1e-9 * float(jnp.abs(H).max()))
        np.testing.assert_array_equal(H[:k, :k], np.eye(k))
        assert not np.any(H[:k, k:]) and not np.any(g[:k])
        assert np.all(np.linalg.eigvalsh(np.asarray(H)) > 0)  # gauge fixed: H is positive definite
        if k != 3:
            continue

        def F(delta, T=T, graph=graph):
            T_d = manifold.rplus(T, delta)
            res = pg.edge_residual(T_d[graph.edge_i], T_d[graph.edge_j], graph.T_bi_bj_meas)
            return 0.5 * jnp.sum((res * graph.sqrt_info) ** 2)

        zero = jnp.zeros((graph.n_poses, k))
        grad = np.array(jax.jit(jax.grad(F))(zero)).reshape(-1)
        grad[:k] = 0.0
        np.testing.assert_allclose(float(cost), float(F(zero)), rtol=1e-12)
        np.testing.assert_allclose(g, grad, rtol=1e-9, atol=1e-9 * np.abs(grad).max())


def test_noise_free_measurements_recover_the_truth(pg: ModuleType, small_graphs) -> None:
    """With exact measurements (and the noisy odometry as the start) the optimum is the
    ground truth, at zero cost: the signs and frames of residual, Jacobians and update
    all agree."""
    for graph in small_graphs:
        T_true = graph.T_world_body_true
        exact = T_true[graph.edge_i].inverse() @ T_true[graph.edge_j]
        result = pg.optimise(dataclasses.replace(graph, T_bi_bj_meas=exact), verbose=False)
        pos, rot = (float(x) for x in pg.trajectory_errors(result.T_world_body, T_true))
        assert pos < 1e-8 and rot < 1e-6, (graph.name, pos, rot)
        assert result.costs[-1] < 1e-12 * result.costs[0]


def test_gauss_newton_and_lm(pg: ModuleType, small_graphs) -> None:
    """Gauss-Newton and Levenberg-Marquardt reach the same minimum on both small graphs, LM
    without a cost increase, and both improve on the odometry."""
    for graph in small_graphs:
        lm = pg.optimise(graph, "lm", verbose=False)
        gn = pg.optimise(graph, "gn", verbose=False)
        assert all(b <= a for a, b in zip(lm.costs, lm.costs[1:])), lm.costs
        # Gauss-Newton takes every step; here it converges too, to the same minimum.
        assert gn.costs[-1] < 0.1 * gn.costs[0], gn.costs
        np.testing.assert_allclose(gn.costs[-1], lm.costs[-1], rtol=1e-6)
        before = pg.trajectory_errors(graph.T_world_body_odom, graph.T_world_body_true)
        after = pg.trajectory_errors(lm.T_world_body, graph.T_world_body_true)
        assert float(after[0]) < float(before[0]) and float(after[1]) < float(before[1])


# ---------------------------------------------------------------------------------------
# --file: a pose graph read from a g2o or TORO file and solved by jaxlie_geo.pose_graph.


def _write_square_loop_g2o(path: Path, seed: int = 0, side: int = 8, laps: int = 2) -> int:
    """A robot drives twice around a square of ``side`` one-metre steps (left turns at the
    corners): g2o 2D, 64 poses, odometry plus a loop closure from each pose of the second lap
    to the same place on the first. Measurements Z_ij = T_i⁻¹ T_j exp(n), n ~ N(0, Σ) on
    (vx, vy, ω), information Σ⁻¹. The vertices hold the odometry chained with a heading bias
    of 0.03 rad a step (a biased gyroscope): far from the optimum. Returns the χ² degrees of
    freedom (E − N + 1)·3."""
    rng = np.random.default_rng(seed)
    sigma = np.array([0.05, 0.05, 0.02])
    n = 4 * side * laps
    turn = np.where(np.arange(1, n) % side == 0, np.pi / 2, 0.0)
    step = SE2.from_xy_theta(jnp.ones(n - 1), jnp.zeros(n - 1), jnp.asarray(turn))
    poses = [SE2.identity()]
    for k in range(n - 1):
        poses.append(poses[-1] @ step[k])
    T = SE2(jnp.stack([p.parameters() for p in poses]))
    i = np.concatenate([np.arange(n - 1), np.arange(n - 4 * side)])
    j = np.concatenate([np.arange(1, n), np.arange(4 * side, n)])
    Z = T[i].inverse() @ T[j] @ SE2.exp(jnp.asarray(rng.normal(size=(len(i), 3)) * sigma))
    z = np.column_stack([np.asarray(Z.translation()), np.asarray(Z.rotation().log())[:, 0]])
    initial = [np.zeros(3)]
    for dx, dy, dtheta in z[: n - 1]:
        x, y, theta = initial[-1]
        c, s = np.cos(theta), np.sin(theta)
        initial.append(np.array([x + c * dx - s * dy, y + s * dx + c * dy, theta + dtheta + 0.03]))
    info = np.diag(1.0 / sigma**2)[np.triu_indices(3)]  # Ω11 Ω12 Ω13 Ω22 Ω23 Ω33
    lines = [
        f"VERTEX_SE2 {k} " + " ".join(map(repr, pose))
        for k, pose in enumerate(np.array(initial).tolist())
    ]
    lines += [
        f"EDGE_SE2 {a} {b} " + " ".join(map(repr, [*zab, *info.tolist()]))
        for a, b, zab in zip(i.tolist(), j.tolist(), z.tolist())
    ]
    path.write_text("\n".join(lines) + "\n")
    return (len(i) - n + 1) * 3


def _write_helix_toro3d(path: Path, seed: int = 0, turns: int = 3, per_turn: int = 12) -> int:
    """Three turns of a helix, 36 SE(3) poses, as a TORO 3D file of ``EDGE3`` records only
    (like sphere2500: the reader chains the odometry for the initial estimate); a loop
    closure from each pose to the one a turn below. Noise as above, σ = 5 cm and 0.02 rad;
    Euler angles R = Rz(yaw) Ry(pitch) Rx(roll), information over (x, y, z, roll, pitch,
    yaw), translation first. Returns the χ² degrees of freedom (E − N + 1)·6."""
    rng = np.random.default_rng(seed)
    sigma = np.array([0.05] * 3 + [0.02] * 3)
    n = turns * per_turn
    a = 2 * np.pi * np.arange(n) / per_turn
    R = SO3.from_rpy_radians(jnp.zeros(n), jnp.full(n, -0.1), jnp.asarray(a + np.pi / 2))
    p = np.column_stack([3 * np.cos(a), 3 * np.sin(a), 0.3 * a])
    T = SE3.from_rotation_and_translation(R, jnp.asarray(p))
    i = np.concatenate([np.arange(n - 1), np.arange(n - per_turn)])
    j = np.concatenate([np.arange(1, n), np.arange(per_turn, n)])
    Z = T[i].inverse() @ T[j] @ SE3.exp(jnp.asarray(rng.normal(size=(len(i), 6)) * sigma))
    rpy = np.column_stack([np.asarray(angle) for angle in Z.rotation().as_rpy_radians()])
    z = np.column_stack([np.asarray(Z.translation()), rpy])
    info = np.diag(1.0 / sigma**2)[np.triu_indices(6)]  # row by row
    lines = [
        f"EDGE3 {a} {b} " + " ".join(map(repr, [*zab, *info.tolist()]))
        for a, b, zab in zip(i.tolist(), j.tolist(), z.tolist())
    ]
    path.write_text("\n".join(lines) + "\n")
    return (len(i) - n + 1) * 6


def _run_file(pg: ModuleType, capsys, argv: List[str]) -> Dict[str, object]:
    """``main(argv)`` in-process; its printed report and what it returned."""
    result = pg.main(argv)
    out, err = capsys.readouterr()
    initial = re.search(r"initial cost (\S+)", out)
    final = re.search(r"final cost (\S+) after (\d+) iterations, (\S+) s", out)
    assert initial and final, out
    solution = result["solution"]
    assert float(initial.group(1)) == pytest.approx(solution.costs[0], rel=1e-8)
    assert float(final.group(1)) == pytest.approx(solution.costs[-1], rel=1e-8)
    assert int(final.group(2)) == solution.iterations
    # One progress line per iteration on stderr (no terminal: one line each), and the reason.
    progress = re.findall(r"iteration\s+(\d+)\s+cost (\S+)", err)
    assert [int(k) for k, _ in progress] == list(range(solution.iterations + 1)), err
    assert f"stopped: {solution.stop_reason}" in out
    return dict(result, out=out, err=err)


def _check_png(png: Path) -> None:
    assert png.is_file()
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 20_000


def test_file_g2o_2d(pg: ModuleType, tmp_path: Path, capsys) -> None:
    """``--file square.g2o``: LM from a badly biased start converges to the χ² expectation,
    the picture is written, and ``--write`` stores the optimised poses (reading the file back
    gives the final cost)."""
    path, png, written = tmp_path / "square.g2o", tmp_path / "pic" / "sq.png", tmp_path / "o.g2o"
    dof = _write_square_loop_g2o(path)
    run = _run_file(pg, capsys, ["--file", str(path), "--out", str(png), "--write", str(written)])
    costs = run["solution"].costs
    assert run["solution"].converged, run["out"]
    assert "64 poses, 95 edges (63 between consecutive poses, 32 others)" in run["out"]
    assert all(b <= a for a, b in zip(costs, costs[1:])), costs
    assert costs[-1] < 1e-3 * costs[0], costs
    # 2F at the optimum: chi-square with (E - N + 1)k = 96 dof; within 4 standard deviations.
    assert run["dof"] == dof == 96
    assert abs(costs[-1] - dof / 2) < 4 * np.sqrt(dof / 2), (costs[-1], dof)
    _check_png(png)
    back = pose_graph.read(written)
    assert back.num_poses == 64 and back.num_edges == 95
    assert pose_graph.graph_cost(back) == pytest.approx(costs[-1], rel=1e-6)


def test_file_toro_3d(pg: ModuleType, tmp_path: Path, capsys) -> None:
    """``--file helix.graph`` (TORO 3D, edges only) with Gauss-Newton and PCG: from the
    chained odometry to the χ² expectation; the 3D picture is drawn."""
    path, png = tmp_path / "helix.graph", tmp_path / "helix.png"
    dof = _write_helix_toro3d(path)
    argv = ["--file", str(path), "--out", str(png), "--method", "gn", "--linear-solver", "pcg"]
    run = _run_file(pg, capsys, argv)
    costs = run["solution"].costs
    assert "3D pose graph (SE3), 36 poses, 59 edges" in run["out"]
    assert costs[-1] < 0.2 * costs[0], costs
    assert run["dof"] == dof == 144
    assert abs(costs[-1] - dof / 2) < 4 * np.sqrt(dof / 2), (costs[-1], dof)
    _check_png(png)
