"""examples/pose_graph.py: run it as a user would (--quick), and check its pieces in-process.

The subprocess test reads the printed report: the analytic-vs-autodiff Jacobian check, the
cost at every Levenberg–Marquardt iteration (never increasing), the errors against ground
truth before and after, and the figure. The in-process tests import the example (it is not
a package) and check the Jacobians at large angles, the gradient of the normal equations
against autodiff, exact recovery from noise-free measurements, and Gauss–Newton.
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

from jaxlie_geo import manifold

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
