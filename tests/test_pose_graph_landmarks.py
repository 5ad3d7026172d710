"""jaxlie_geo.pose_graph with point landmarks: ``LANDMARK2`` records, the observation
residual and its Jacobian, and solves against GTSAM.

The references are independent of the module: the files' own lines counted and parsed
with plain string splitting, homogeneous matrices for the frames, forward-mode autodiff of
the residual through the group's exp for the closed-form Jacobian, and GTSAM's
Levenberg–Marquardt on the same cost (its ``Pose2.transformTo`` and Jacobians, through a
``CustomFactor``) for the optimum.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import List

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlie_geo import SE2, SE3, pose_graph
from jaxlie_geo._xla import x64
from jaxlie_geo.pose_graph._factors import observation_jacobian, observation_residual
from jaxlie_geo.pose_graph._graph import PoseGraph

#: file: (poses, edges, landmarks, observations), as counted from the files' lines.
FILES = {
    "victoriaPark_reduced_1k.g2o": (1000, 999, 48, 606),
    "cityTrees_reduced_1k.g2o": (1000, 999, 66, 406),
}


def _data(name: str) -> Path:
    gtsam = pytest.importorskip("gtsam")
    return Path(gtsam.findExampleDataFile(name))


def _matrix(row: np.ndarray) -> np.ndarray:
    c, s = math.cos(row[2]), math.sin(row[2])
    return np.array([[c, -s, row[0]], [s, c, row[1]], [0, 0, 1]])


def _write_text(tmp_path: Path, lines: List[str]) -> Path:
    path = tmp_path / "graph.g2o"
    path.write_text("\n".join(lines) + "\n")
    return path


# ---------------------------------------------------------------------------------------
# Reading and writing.


@pytest.mark.parametrize("name", list(FILES))
def test_gtsam_landmark_files(name: str) -> None:
    """Counts, ids, measurements and information against the file's own tokens; poses
    against GTSAM's chained odometry; each landmark where its first observation puts it."""
    gtsam = pytest.importorskip("gtsam")
    path = _data(name)
    graph = pose_graph.read(path)
    rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    edges = [r for r in rows if r[0] == "EDGE_SE2"]
    seen = [r for r in rows if r[0] == "LANDMARK2"]
    assert len(edges) + len(seen) == len(rows)
    pose_ids = {int(t) for r in edges for t in r[1:3]}
    landmark_ids = sorted({int(r[2]) for r in seen})
    counts = (len(pose_ids), len(edges), len(landmark_ids), len(seen))
    assert counts == FILES[name]
    assert (graph.num_poses, graph.num_edges, graph.num_landmarks, graph.num_observations) == (
        counts
    )
    assert sorted(graph.landmark_ids.tolist()) == landmark_ids
    pose, landmark = graph.observations.T
    observed = np.stack([graph.ids[pose], graph.landmark_ids[landmark]], axis=1)
    np.testing.assert_array_equal(observed, [[int(r[1]), int(r[2])] for r in seen])
    numbers = np.array([[float(t) for t in r[3:]] for r in seen])
    np.testing.assert_array_equal(graph.observation_measurements, numbers[:, :2])
    a, b, c = numbers[:, 2], numbers[:, 3], numbers[:, 4]
    expected = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
    np.testing.assert_array_equal(graph.observation_information, expected)
    # GTSAM's reader drops the LANDMARK2 records but chains the same odometry.
    factors, values = gtsam.readG2o(str(path), False)
    assert factors.size() == len(edges)
    ours = np.array([_matrix(row) for row in graph.poses])
    theirs = np.array([values.atPose2(int(i)).matrix() for i in graph.ids])
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)
    first = {}
    for r in seen:
        first.setdefault(int(r[2]), r)
    for m, position in zip(graph.landmark_ids.tolist(), graph.landmarks):
        r = first[m]
        T = theirs[graph.ids.tolist().index(int(r[1]))]
        np.testing.assert_allclose(position, (T @ [float(r[3]), float(r[4]), 1.0])[:2], atol=1e-9)


def test_landmark_round_trip(tmp_path: Path) -> None:
    """Landmark ids apart from the pose ids (one shared number), information with an
    off-diagonal entry; write then read gives the same graph, bit for bit."""
    lines = [
        "EDGE_SE2 10 11 1 0 0.5 100 0 0 100 0 400",
        "EDGE_SE2 11 12 1 0.25 -0.5 100 1 0 100 0 400",
        "LANDMARK2 11 10 2.5 -1 4 0.5 3",
        "LANDMARK2 10 7 0.125 3 2 0 2",
        "LANDMARK2 12 10 1.5 -2 4 -0.5 3",
    ]
    graph = pose_graph.read(_write_text(tmp_path, lines))
    assert graph.landmark_ids.tolist() == [10, 7]
    assert graph.observations.tolist() == [[1, 0], [0, 1], [2, 0]]
    T_11 = _matrix(graph.poses[1])
    np.testing.assert_allclose(graph.landmarks[0], (T_11 @ [2.5, -1, 1])[:2], atol=1e-15)
    out = tmp_path / "out.g2o"
    pose_graph.write(out, graph)
    again = pose_graph.read(out)
    names = ["ids", "poses", "edges", "measurements", "information", "landmark_ids"]
    names += ["landmarks", "observations", "observation_measurements", "observation_information"]
    for name in names:
        np.testing.assert_array_equal(getattr(again, name), getattr(graph, name), err_msg=name)


@pytest.mark.parametrize(
    "bad, fragment",
    [
        (["LANDMARK2 5 0 1 1 1 0 1"], "pose 5 is in no vertex or edge"),
        (["LANDMARK2 0 0 1 1 1 0"], "expected 7 numbers"),
        (["LANDMARK2 0 0 1 1 1 2 1"], "positive definite"),
        (["LANDMARK2 0 1.5 1 1 1 0 1"], "non-negative integer"),
    ],
)
def test_malformed_landmark_records(tmp_path: Path, bad: List[str], fragment: str) -> None:
    lines = ["EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1", *bad]
    path = _write_text(tmp_path, lines)
    with pytest.raises(ValueError) as info:
        pose_graph.read(path)
    assert str(info.value).startswith(f"{path}:2: "), str(info.value)
    assert fragment in str(info.value)


def test_landmark_graph_errors(tmp_path: Path) -> None:
    graph = pose_graph.read(
        _write_text(tmp_path, ["EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1", "LANDMARK2 1 3 1 1 1 0 1"])
    )
    with pytest.raises(ValueError, match="LANDMARK2"):
        pose_graph.write(tmp_path / "out.graph", graph, format="toro")
    fields = dict(
        dim=2,
        ids=graph.ids,
        poses=graph.poses,
        edges=graph.edges,
        measurements=graph.measurements,
        information=graph.information,
        landmark_ids=[3],
        landmarks=[[0.0, 0.0]],
        observation_measurements=[[1.0, 1.0]],
        observation_information=[np.eye(2)],
    )
    with pytest.raises(ValueError, match=r"observations: column 1 must lie in \[0, 1\)"):
        PoseGraph(**fields, observations=[[1, 1]])
    with pytest.raises(ValueError, match=r"landmarks: expected shape \(1, 2\)"):
        PoseGraph(**{**fields, "landmarks": [[0.0, 0.0, 0.0]]}, observations=[[1, 0]])
    two = {**fields, "landmark_ids": [3, 4], "landmarks": [[0.0, 0.0], [1.0, 1.0]]}
    lonely = PoseGraph(**two, observations=[[1, 0]])
    with pytest.raises(ValueError, match=r"landmark 1 \(id 4\) is not joined"):
        pose_graph.solve(lonely)


# ---------------------------------------------------------------------------------------
# The residual and its closed-form Jacobian.


def _autodiff_agrees(group, points: int):
    """max |closed form − autodiff| / max |J| over random poses, landmarks and whitening
    matrices, both groups in one program."""
    key = jax.random.PRNGKey(0)
    d = 2 if group is SE2 else 3
    k1, k2, k3, k4 = jax.random.split(key, 4)
    T = group.exp(3.0 * jax.random.normal(k1, (points, group.tangent_dim)))
    l = 5.0 * jax.random.normal(k2, (points, d))
    z = jax.random.normal(k3, (points, d))
    W = jnp.triu(jax.random.normal(k4, (points, d, d))) + 3.0 * jnp.eye(d)

    def one(T, l, z, W):
        def moved(delta):
            return observation_residual(
                T @ group.exp(delta[: group.tangent_dim]), l + delta[group.tangent_dim :], (z, W)
            )

        J_auto = jax.jacfwd(moved)(jnp.zeros(group.tangent_dim + d))
        e, J = observation_jacobian(T, l, (z, W))
        return jnp.max(jnp.abs(e - moved(jnp.zeros(group.tangent_dim + d)))), jnp.max(
            jnp.abs(J - J_auto)
        ) / jnp.max(jnp.abs(J_auto))

    return jax.vmap(one)(T, l, z, W)


@jax.jit
def _both_groups():
    return _autodiff_agrees(SE2, 64), _autodiff_agrees(SE3, 64)


def test_observation_jacobian_matches_autodiff() -> None:
    with x64(True):
        for e, J in _both_groups():
            assert float(jnp.max(e)) < 1e-13  # the residual, moved by exp(0)
            assert float(jnp.max(J)) < 1e-13


# ---------------------------------------------------------------------------------------
# Solving.


def test_solve_recovers_exact_landmarks() -> None:
    """Exact measurements from a known layout (a loop of poses, each landmark seen from
    three poses), a perturbed initial estimate: the optimum is the layout (cost 0)."""
    rng = np.random.default_rng(3)
    n, m = 12, 5
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    truth = np.stack([4 * np.cos(angles), 4 * np.sin(angles), angles + np.pi / 2], axis=1)
    points = rng.uniform(-6, 6, size=(m, 2))
    M = [_matrix(r) for r in truth]
    edges = np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)
    rel = [np.linalg.inv(M[i]) @ M[j] for i, j in edges]
    measurements = [[A[0, 2], A[1, 2], math.atan2(A[1, 0], A[0, 0])] for A in rel]
    obs = np.array([[(3 * l + s) % n, l] for l in range(m) for s in range(3)])
    z = [(np.linalg.inv(M[i]) @ [*points[l], 1.0])[:2] for i, l in obs]
    start = truth + rng.normal(scale=0.05, size=truth.shape)
    start[0] = truth[0]
    graph = PoseGraph(
        dim=2, ids=np.arange(n), poses=start, edges=edges, measurements=measurements,
        information=np.broadcast_to(np.diag([100.0, 100, 400]), (n, 3, 3)),
        landmark_ids=np.arange(m), landmarks=points + rng.normal(scale=0.3, size=points.shape),
        observations=obs, observation_measurements=z,
        observation_information=np.broadcast_to([[4.0, 1.0], [1.0, 3.0]], (len(obs), 2, 2)),
    )  # fmt: skip
    solution = pose_graph.solve(graph, linear_solver="dense", tolerance=1e-12)
    assert solution.costs[-1] < 1e-16
    np.testing.assert_allclose(solution.landmarks, points, atol=1e-8)
    np.testing.assert_allclose(solution.graph.landmarks, points, atol=1e-8)
    np.testing.assert_allclose(
        [_matrix(r) for r in solution.graph.poses], [_matrix(r) for r in truth], atol=1e-8
    )
    assert pose_graph.graph_cost(solution.graph) == pytest.approx(solution.costs[-1], abs=1e-16)


@pytest.mark.parametrize("name", list(FILES))
def test_landmark_files_reach_gtsam_optimum(name: str) -> None:
    """GTSAM's Levenberg–Marquardt (default parameters) on the same cost from the same
    initial values; ours reaches its final cost × (1 + 1e-6), GTSAM's cost of our
    estimate."""
    gtsam = pytest.importorskip("gtsam")
    from benchmarks.pose_graphs import ANCHOR_SIGMA, to_gtsam

    graph = pose_graph.read(_data(name))
    factors, values = to_gtsam(graph)
    assert factors.error(values) == pytest.approx(
        pose_graph.graph_cost(graph, anchor_sigma=ANCHOR_SIGMA), rel=1e-12
    )
    optimum = gtsam.LevenbergMarquardtOptimizer(
        factors, values, gtsam.LevenbergMarquardtParams()
    ).optimize()
    solution = pose_graph.solve(graph, anchor_sigma=ANCHOR_SIGMA)
    ours = factors.error(to_gtsam(solution.graph)[1])
    assert ours <= factors.error(optimum) * (1 + 1e-6)
    assert solution.costs[-1] == pytest.approx(ours, rel=1e-10)
