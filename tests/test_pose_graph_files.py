"""jaxlie_geo.pose_graph: reading and writing g2o and TORO files.

The references are independent of the module: expected matrices written by hand from the
format definitions, rotations built from explicit Rz·Ry·Rx matrices and
``scipy.spatial.transform.Rotation``, relative poses checked with homogeneous matrices,
and (where GTSAM is installed) GTSAM's own readers on the files it ships. No JAX
compilation: the module is NumPy on the host.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, List, Optional, Tuple

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxlie_geo.pose_graph._files import read, write
from jaxlie_geo.pose_graph._graph import PoseGraph

# ---------------------------------------------------------------------------------------
# Independent references.


def _rot(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _matrix(dim: int, row: np.ndarray) -> np.ndarray:
    """Homogeneous matrix of a vertex-layout row (scipy's quaternions are x, y, z, w)."""
    T = np.eye(dim + 1)
    if dim == 2:
        T[:2, :2] = _rot("z", row[2])[:2, :2]
        T[:2, 2] = row[:2]
    else:
        T[:3, :3] = Rotation.from_quat(row[3:]).as_matrix()
        T[:3, 3] = row[:3]
    return T


def _bits(a: np.ndarray) -> np.ndarray:
    """The raw float64 bits: equality tells -0.0 from 0.0."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _write_text(tmp_path: Path, lines: List[str], name: str = "graph.txt") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def _random_graph(dim: int, rng: np.random.Generator, n: int = 40, e: int = 90) -> PoseGraph:
    """Random poses and measurements, shuffled sparse ids, SPD information with
    off-diagonal entries, a few awkward floats (signed zero, subnormal, huge)."""
    k = 3 if dim == 2 else 6
    ids = rng.choice(10**9, size=n, replace=False).astype(np.int64)

    def rows(m: int) -> np.ndarray:
        xyz = rng.normal(scale=30.0, size=(m, dim))
        if dim == 2:
            return np.concatenate([xyz, rng.uniform(-4.0, 4.0, size=(m, 1))], axis=1)
        q = rng.normal(size=(m, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        return np.concatenate([xyz, q], axis=1)

    poses, measurements = rows(n), rows(e)
    poses[0, 0], poses[1, 0], poses[2, 1], poses[3, 0] = -0.0, 5e-324, 1e300, 0.1
    i = rng.integers(0, n, size=e)
    j = (i + rng.integers(1, n, size=e)) % n  # never i
    A = rng.normal(size=(e, k, k))
    information = A @ A.transpose(0, 2, 1) + 0.5 * np.eye(k)
    information[0, 0, 0] += 2.0**-30  # not a short decimal
    return PoseGraph(
        dim=dim,
        ids=ids,
        poses=poses,
        edges=np.stack([i, j], axis=1).astype(np.int64),
        measurements=measurements,
        information=information,
    )


# ---------------------------------------------------------------------------------------
# Round trips.


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("fmt", ["g2o", "toro"])
def test_round_trip(tmp_path: Path, dim: int, fmt: str) -> None:
    graph = _random_graph(dim, np.random.default_rng(10 * dim + len(fmt)))
    path = tmp_path / f"graph.{fmt}"
    write(path, graph, format=fmt)  # type: ignore[arg-type]
    back = read(path)
    tags = {line.split()[0] for line in path.read_text().splitlines()}
    expected_tags = {
        ("g2o", 2): {"VERTEX_SE2", "EDGE_SE2"},
        ("g2o", 3): {"VERTEX_SE3:QUAT", "EDGE_SE3:QUAT"},
        ("toro", 2): {"VERTEX2", "EDGE2"},
        ("toro", 3): {"VERTEX3", "EDGE3"},
    }[(fmt, dim)]
    assert tags == expected_tags
    assert back.dim == dim
    np.testing.assert_array_equal(back.ids, graph.ids)
    np.testing.assert_array_equal(back.edges, graph.edges)
    np.testing.assert_array_equal(_bits(back.information), _bits(graph.information))
    if fmt == "g2o" or dim == 2:
        for name in ("poses", "measurements"):
            np.testing.assert_array_equal(_bits(getattr(back, name)), _bits(getattr(graph, name)))
        return
    # TORO 3D stores Euler angles: positions exact, rotations to a few ulp.
    for name in ("poses", "measurements"):
        a, b = getattr(graph, name), getattr(back, name)
        np.testing.assert_array_equal(_bits(b[:, :3]), _bits(a[:, :3]))
        np.testing.assert_allclose(np.linalg.norm(b[:, 3:], axis=1), 1.0, rtol=0, atol=4e-16)
        Ra, Rb = Rotation.from_quat(a[:, 3:]).as_matrix(), Rotation.from_quat(b[:, 3:]).as_matrix()
        np.testing.assert_allclose(Rb, Ra, rtol=0, atol=2e-15)


def test_toro_3d_round_trip_near_gimbal_lock(tmp_path: Path) -> None:
    """Pitch at and next to ±90°: roll and yaw are not determined separately, the rotation
    is still reproduced."""
    angles = [(0.3, s * (math.pi / 2 - d), 1.2) for s in (1, -1) for d in (0.0, 1e-9, 1e-5)]
    q = Rotation.from_euler("ZYX", [[y, p, r] for r, p, y in angles]).as_quat()
    n = len(q)
    graph = PoseGraph(
        dim=3,
        ids=np.arange(n, dtype=np.int64),
        poses=np.concatenate([np.zeros((n, 3)), q], axis=1),
        edges=np.array([[0, 1]], dtype=np.int64),
        measurements=np.concatenate([np.zeros((1, 3)), q[:1]], axis=1),
        information=np.eye(6)[None],
    )
    write(tmp_path / "g.graph", graph, format="toro")
    back = read(tmp_path / "g.graph")
    R0, R1 = Rotation.from_quat(q).as_matrix(), Rotation.from_quat(back.poses[:, 3:]).as_matrix()
    np.testing.assert_allclose(R1, R0, rtol=0, atol=2e-15)


# ---------------------------------------------------------------------------------------
# The layout of each record, from the format definitions.

# Information with distinct entries, SPD (diagonally dominant), written out by hand.
INFO3 = np.array([[100.0, 2.0, 3.0], [2.0, 200.0, 5.0], [3.0, 5.0, 300.0]])
INFO6 = np.array(
    [
        [1000.0, 1.0, 2.0, 3.0, 4.0, 5.0],
        [1.0, 2000.0, 6.0, 7.0, 8.0, 9.0],
        [2.0, 6.0, 3000.0, 10.0, 11.0, 12.0],
        [3.0, 7.0, 10.0, 4000.0, 13.0, 14.0],
        [4.0, 8.0, 11.0, 13.0, 5000.0, 15.0],
        [5.0, 9.0, 12.0, 14.0, 15.0, 6000.0],
    ]
)
UPPER6 = "1000 1 2 3 4 5 2000 6 7 8 9 3000 10 11 12 4000 13 14 5000 15 6000"


@pytest.mark.parametrize(
    "edge, information",
    [
        # g2o: I11 I12 I13 I22 I23 I33
        ("EDGE_SE2 4 9 1.5 -2.5 0.25 100 2 3 200 5 300", INFO3),
        # TORO: Ixx Ixy Iyy Itt Ixt Iyt
        ("EDGE2 4 9 1.5 -2.5 0.25 100 2 200 300 3 5", INFO3),
    ],
)
def test_information_order_2d(tmp_path: Path, edge: str, information: np.ndarray) -> None:
    graph = read(_write_text(tmp_path, [edge]))
    assert graph.dim == 2
    np.testing.assert_array_equal(graph.ids, [4, 9])
    np.testing.assert_array_equal(graph.edges, [[0, 1]])
    np.testing.assert_array_equal(graph.measurements, [[1.5, -2.5, 0.25]])
    np.testing.assert_array_equal(graph.information, information[None])
    np.testing.assert_array_equal(graph.poses, [[0.0, 0.0, 0.0], [1.5, -2.5, 0.25]])


def test_information_order_3d(tmp_path: Path) -> None:
    q = [0.1, -0.2, 0.3, math.sqrt(1 - 0.14)]
    g2o = read(
        _write_text(
            tmp_path, [f"EDGE_SE3:QUAT 4 9 1.5 -2.5 0.25 {' '.join(map(repr, q))} {UPPER6}"]
        )
    )
    assert g2o.dim == 3
    np.testing.assert_array_equal(g2o.measurements, [[1.5, -2.5, 0.25, *q]])
    np.testing.assert_array_equal(g2o.information, INFO6[None])
    toro = read(_write_text(tmp_path, [f"EDGE3 4 9 1.5 -2.5 0.25 0 0 0 {UPPER6}"], "t.graph"))
    np.testing.assert_array_equal(toro.measurements, [[1.5, -2.5, 0.25, 0.0, 0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(toro.information, INFO6[None])


def test_vertices(tmp_path: Path) -> None:
    q = [0.5, 0.5, -0.5, 0.5]
    g2o = read(
        _write_text(
            tmp_path,
            [
                "VERTEX_SE3:QUAT 3 1 2 3 0.5 0.5 -0.5 0.5",
                f"EDGE_SE3:QUAT 3 3000 0 0 1 0 0 0 1 {UPPER6}",
            ],
        )
    )
    np.testing.assert_array_equal(g2o.poses[0], [1, 2, 3, *q])
    toro2 = read(_write_text(tmp_path, ["VERTEX2 3 1 2 -3", "EDGE2 3 5 0 0 0 1 0 1 1 0 0"]))
    np.testing.assert_array_equal(toro2.poses[0], [1, 2, -3])


def test_ids_in_order_of_appearance(tmp_path: Path) -> None:
    """Vertex records first (wherever they are), then ids seen only in edges, i before j."""
    lines = [
        "EDGE2 3 9 1 0 0 1 0 1 1 0 0",
        "VERTEX2 7 0 0 0",
        "EDGE2 12 7 1 0 0 1 0 1 1 0 0",
        "# a comment",
        "",
        "VERTEX2 3 1 0 0",
        "EDGE2 9 12 1 0 0 1 0 1 1 0 0",
        "EQUIV 9 12",
    ]
    graph = read(_write_text(tmp_path, lines))
    np.testing.assert_array_equal(graph.ids, [7, 3, 9, 12])
    np.testing.assert_array_equal(graph.edges, [[1, 2], [3, 0], [2, 3]])
    assert graph.ids.dtype == np.int64 and graph.edges.dtype == np.int64


# ---------------------------------------------------------------------------------------
# TORO 3D angles.


def test_toro_euler_convention(tmp_path: Path) -> None:
    roll, pitch, yaw = 0.3, -1.1, 2.5
    path = _write_text(
        tmp_path,
        [
            f"VERTEX3 0 1 2 3 {roll} {pitch} {yaw}",
            f"EDGE3 0 1 0 0 0 {-yaw} {roll} {pitch} {UPPER6}",
        ],
    )
    graph = read(path)
    explicit = _rot("z", yaw) @ _rot("y", pitch) @ _rot("x", roll)
    scipy_R = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    ours = Rotation.from_quat(graph.poses[0, 3:]).as_matrix()
    np.testing.assert_allclose(explicit, scipy_R, atol=1e-15)
    np.testing.assert_allclose(ours, explicit, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(graph.poses[0, :3], [1, 2, 3])
    edge = _rot("z", pitch) @ _rot("y", roll) @ _rot("x", -yaw)
    np.testing.assert_allclose(
        Rotation.from_quat(graph.measurements[0, 3:]).as_matrix(), edge, rtol=0, atol=1e-15
    )


def test_toro_euler_matches_library_convention(tmp_path: Path) -> None:
    """The reader's angles are SO3.from_rpy_radians's."""
    from jaxlie_geo import SO3

    roll, pitch, yaw = -0.7, 0.4, -2.9
    graph = read(_write_text(tmp_path, [f"EDGE3 0 1 0 0 0 {roll} {pitch} {yaw} {UPPER6}"]))
    expected = np.asarray(SO3.from_rpy_radians(roll, pitch, yaw).as_matrix(), dtype=np.float64)
    ours = Rotation.from_quat(graph.measurements[0, 3:]).as_matrix()
    np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-15)


# ---------------------------------------------------------------------------------------
# Initial poses from the edges.


def _check_chained(graph: PoseGraph, chained: List[int], atol: float) -> None:
    for e in chained:
        i, j = graph.edges[e]
        Ti, Tj = _matrix(graph.dim, graph.poses[i]), _matrix(graph.dim, graph.poses[j])
        Z = _matrix(graph.dim, graph.measurements[e])
        np.testing.assert_allclose(np.linalg.inv(Ti) @ Tj, Z, rtol=0, atol=atol)


@pytest.mark.parametrize("dim", [2, 3])
def test_chaining(tmp_path: Path, dim: int) -> None:
    """Edges only: the first edge starts at the identity, later ones extend the chain
    forwards (j from i) or backwards (i from j); a second component starts at the
    identity; a loop closure is left as it is."""
    rng = np.random.default_rng(dim)
    pairs = [(0, 1), (1, 2), (5, 2), (2, 3), (3, 0), (20, 21), (6, 5)]
    chained = [0, 1, 2, 3, 5, 6]  # (3, 0) closes a loop
    lines = []
    for i, j in pairs:
        if dim == 2:
            z = [*rng.normal(size=2).tolist(), float(rng.uniform(-3, 3))]
            lines.append(f"EDGE2 {i} {j} {' '.join(map(repr, z))} 1 0 1 1 0 0")
        else:
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            z = [*rng.normal(size=3).tolist(), *q.tolist()]
            lines.append(f"EDGE_SE3:QUAT {i} {j} {' '.join(map(repr, z))} {UPPER6}")
    graph = read(_write_text(tmp_path, lines))
    np.testing.assert_array_equal(graph.ids, [0, 1, 2, 5, 3, 20, 21, 6])
    identity = [0, 0, 0] if dim == 2 else [0, 0, 0, 0, 0, 0, 1]
    np.testing.assert_array_equal(graph.poses[0], identity)
    np.testing.assert_array_equal(graph.poses[5], identity)  # id 20
    _check_chained(graph, chained, atol=1e-13)
    if dim == 3:
        np.testing.assert_allclose(np.linalg.norm(graph.poses[:, 3:], axis=1), 1, atol=1e-15)


def test_chaining_from_given_vertices(tmp_path: Path) -> None:
    """Vertices given for some ids: the others follow from them; given ones are kept."""
    lines = [
        "VERTEX_SE2 1 10 -4 2.5",
        "EDGE_SE2 0 1 1 0 0.5 1 0 0 1 0 1",
        "EDGE_SE2 1 2 2 1 -0.25 1 0 0 1 0 1",
        "EDGE_SE2 2 0 0 0 0 1 0 0 1 0 1",
    ]
    graph = read(_write_text(tmp_path, lines))
    np.testing.assert_array_equal(graph.ids, [1, 0, 2])
    np.testing.assert_array_equal(graph.poses[0], [10, -4, 2.5])
    _check_chained(graph, [0, 1], atol=1e-14)


def test_chaining_3d_normalises_file_quaternions(tmp_path: Path) -> None:
    """Quaternions written with 6 digits are not unit; the chained poses are."""
    q = Rotation.from_rotvec([0.3, -0.2, 1.1]).as_quat()
    q6 = " ".join(f"{c:.6f}" for c in q)
    lines = [f"EDGE_SE3:QUAT {i} {i + 1} 1 0.5 0 {q6} {UPPER6}" for i in range(200)]
    graph = read(_write_text(tmp_path, lines))
    np.testing.assert_allclose(np.linalg.norm(graph.poses[:, 3:], axis=1), 1, atol=1e-13)
    np.testing.assert_array_equal(
        graph.measurements[:, 3:], np.array([[float(c) for c in q6.split()]] * 200)
    )
    unit = graph.measurements.copy()
    unit[:, 3:] /= np.linalg.norm(unit[:, 3:], axis=1, keepdims=True)
    _check_chained(
        PoseGraph(3, graph.ids, graph.poses, graph.edges, unit, graph.information),
        list(range(200)),
        atol=1e-11,
    )


# ---------------------------------------------------------------------------------------
# information_order.


def test_information_order_override(tmp_path: Path) -> None:
    # Written in g2o's order under a TORO tag: I11 I12 I13 I22 I23 I33.
    lines = ["VERTEX2 0 0 0 0", "EDGE2 0 1 1 0 0 4 1 0.5 5 2 6"]
    path = _write_text(tmp_path, lines)
    as_g2o = np.array([[4.0, 1.0, 0.5], [1.0, 5.0, 2.0], [0.5, 2.0, 6.0]])
    np.testing.assert_array_equal(read(path, information_order="g2o").information, as_g2o[None])
    with pytest.raises(ValueError) as info:
        read(path)
    message = str(info.value)
    assert message.startswith(f"{path}:2: EDGE2")
    assert "information_order='g2o'" in message
    with pytest.raises(ValueError, match=f"^{path}:2: EDGE2"):
        read(path, information_order="toro")
    # And the other way: TORO's order under a g2o tag (Ixx Ixy Iyy Itt Ixt Iyt).
    g2o_path = _write_text(tmp_path, ["EDGE_SE2 0 1 1 0 0 4 1 5 6 0.5 2"], "g.g2o")
    with pytest.raises(ValueError, match="information_order='toro'"):
        read(g2o_path)
    np.testing.assert_array_equal(
        read(g2o_path, information_order="toro").information, as_g2o[None]
    )
    with pytest.raises(ValueError, match="information_order"):
        read(g2o_path, information_order="G2O")  # type: ignore[arg-type]


def test_information_order_leaves_3d_alone(tmp_path: Path) -> None:
    path = _write_text(tmp_path, [f"EDGE3 0 1 0 0 0 0 0 0 {UPPER6}"])
    for graph in (
        read(path),
        read(path, information_order="g2o"),
        read(path, information_order="toro"),
    ):
        np.testing.assert_array_equal(graph.information, INFO6[None])


# ---------------------------------------------------------------------------------------
# Errors.

E2 = "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1"
MALFORMED = [
    ("unknown tag", ["VERTEX_XY 3 1 2"], "VERTEX_XY"),
    ("too few numbers", ["EDGE_SE2 0 1 1 0 0 1 0 0 1 0"], "EDGE_SE2"),
    ("too many numbers", ["EDGE2 0 1 1 0 0 1 0 1 1 0 0 7"], "EDGE2"),
    ("not a number", ["EDGE_SE2 0 1 1 0 zero 1 0 0 1 0 1"], "'zero'"),
    ("inline comment", ["EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1 # odometry"], "EDGE_SE2"),
    ("nan", ["EDGE_SE2 0 1 1 nan 0 1 0 0 1 0 1"], "not finite"),
    ("inf", ["VERTEX_SE2 0 inf 0 0"], "VERTEX_SE2"),
    ("duplicate vertex", ["VERTEX_SE2 0 0 0 0", "VERTEX_SE2 0 1 0 0"], "duplicate vertex id 0"),
    ("2D and 3D", ["VERTEX3 0 0 0 0 0 0 0"], "VERTEX3"),
    ("self loop", ["EDGE_SE2 1 1 1 0 0 1 0 0 1 0 1"], "to itself"),
    ("not positive definite", ["EDGE_SE2 0 1 1 0 0 1 0 0 1 0 -1"], "positive definite"),
    ("negative id", ["VERTEX_SE2 -1 0 0 0"], "non-negative integer"),
    ("fractional id", ["EDGE_SE2 0 1.5 1 0 0 1 0 0 1 0 1"], "non-negative integer"),
    ("EQUIV arity", ["EQUIV 1"], "EQUIV"),
]


@pytest.mark.parametrize("case, bad, fragment", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_line(tmp_path: Path, case: str, bad: List[str], fragment: str) -> None:
    """The bad record is the last line, after a comment, a blank line and good records."""
    lines = ["# header", "", "VERTEX_SE2 7 0 0 0", E2, "   ", *bad]
    path = _write_text(tmp_path, lines)
    with pytest.raises(ValueError) as info:
        read(path)
    assert str(info.value).startswith(f"{path}:{len(lines)}: "), str(info.value)
    assert fragment in str(info.value)


def test_malformed_3d(tmp_path: Path) -> None:
    bad_q = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0.99"
    path = _write_text(tmp_path, [f"EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1 {UPPER6}", bad_q])
    with pytest.raises(ValueError, match=f"^{path}:2: VERTEX_SE3:QUAT: the quaternion"):
        read(path)
    # 6-digit quaternions are accepted as written.
    ok = _write_text(
        tmp_path,
        [
            "VERTEX_SE3:QUAT 0 0 0 0 0.577350 0.577350 0.577350 0",
            f"EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1 {UPPER6}",
        ],
        "ok.g2o",
    )
    assert read(ok).poses[0, 3] == 0.57735
    mixed = _write_text(tmp_path, [f"EDGE3 0 1 0 0 0 0 0 0 {UPPER6}", E2], "mixed.txt")
    with pytest.raises(ValueError, match=f"^{mixed}:2: EDGE_SE2: a 2D record in a 3D file"):
        read(mixed)


@pytest.mark.parametrize(
    "lines", [[], ["# only a comment", ""], ["VERTEX_SE2 0 0 0 0"], ["EQUIV 1 2"]]
)
def test_no_edges(tmp_path: Path, lines: List[str]) -> None:
    path = tmp_path / "empty.g2o"
    path.write_text("\n".join(lines))
    with pytest.raises(ValueError, match=f"^{path}: no "):
        read(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        read(tmp_path / "absent.g2o")


def test_write_errors(tmp_path: Path) -> None:
    graph = _random_graph(2, np.random.default_rng(0), n=4, e=2)
    with pytest.raises(ValueError, match="format"):
        write(tmp_path / "g", graph, format="tum")  # type: ignore[arg-type]
    asymmetric = graph.information.copy()
    asymmetric[1, 0, 2] += 1.0
    with pytest.raises(ValueError, match="edge 1 is not symmetric"):
        write(
            tmp_path / "g",
            PoseGraph(2, graph.ids, graph.poses, graph.edges, graph.measurements, asymmetric),
        )
    poses = graph.poses.copy()
    poses[0, 0] = np.nan
    with pytest.raises(ValueError, match="poses"):
        write(
            tmp_path / "g",
            PoseGraph(2, graph.ids, poses, graph.edges, graph.measurements, graph.information),
        )


# ---------------------------------------------------------------------------------------
# GTSAM's readers on the files GTSAM ships (optional: GTSAM is not a test dependency; the
# tests above cover the formats without it).


def _gtsam() -> Tuple[Any, Path]:
    """gtsam and its data folder; the comparisons skip where gtsam (the ``bench`` extra)
    is not installed."""
    gtsam = pytest.importorskip("gtsam")
    return gtsam, Path(gtsam.__file__).parent / "Data"


def _compare_with_gtsam(
    graph: PoseGraph, factors, values, permutation: Optional[List[int]]
) -> None:
    """Same edges, measurements and information (reordered by ``permutation`` to GTSAM's
    tangent), and the same poses where GTSAM has them."""
    key = {int(v): n for n, v in enumerate(graph.ids)}
    assert factors.size() == graph.num_edges
    edges, measured, information = [], [], []
    for e in range(factors.size()):
        f = factors.at(e)
        edges.append([key[int(k)] for k in f.keys()])
        measured.append(f.measured().matrix())
        information.append(f.noiseModel().information())
    np.testing.assert_array_equal(np.array(edges), graph.edges)
    ours = np.array([_matrix(graph.dim, row) for row in graph.measurements])
    np.testing.assert_allclose(ours, np.array(measured), rtol=0, atol=1e-12)
    p = slice(None) if permutation is None else np.array(permutation)
    np.testing.assert_allclose(graph.information[:, p][:, :, p], np.array(information), rtol=1e-14)
    known = [(n, v) for n, v in enumerate(graph.ids.tolist()) if values.exists(v)]
    if known:
        at = values.atPose2 if graph.dim == 2 else values.atPose3
        ours = np.array([_matrix(graph.dim, graph.poses[n]) for n, _ in known])
        np.testing.assert_allclose(
            ours, np.array([at(v).matrix() for _, v in known]), rtol=0, atol=1e-12
        )


def test_against_gtsam_g2o_3d() -> None:
    gtsam, data = _gtsam()
    omega_v = [3, 4, 5, 0, 1, 2]  # GTSAM's Pose3 tangent is (ω, v)
    for name, poses, edges in [
        ("pose3example-grid.txt", 27, 44),
        ("pose3example-offdiagonal.txt", 2, 1),
    ]:
        graph = read(data / name)
        assert (graph.num_poses, graph.num_edges) == (poses, edges)
        factors, values = gtsam.readG2o(str(data / name), True)
        _compare_with_gtsam(graph, factors, values, omega_v)


def test_against_gtsam_toro_2d() -> None:
    gtsam, data = _gtsam()
    graph = read(data / "w10000.graph")
    assert (graph.num_poses, graph.num_edges) == (10000, 64311)
    np.testing.assert_array_equal(graph.information, np.broadcast_to(np.eye(3), (64311, 3, 3)))
    factors, values = gtsam.load2D(
        str(data / "w10000.graph"), noiseFormat=gtsam.NoiseFormat.NoiseFormatTORO
    )
    _compare_with_gtsam(graph, factors, values, None)


def test_against_gtsam_toro_3d() -> None:
    """sphere2500: edges only. GTSAM's load3D reads the same 21 numbers but applies them
    to its (ω, v) tangent unpermuted (rotation first); this reader puts the first block on
    the translation, as HOG-Man does."""
    gtsam, data = _gtsam()
    graph = read(data / "sphere2500.txt")
    assert (graph.num_poses, graph.num_edges) == (2500, 4949)
    np.testing.assert_array_equal(
        graph.information, np.broadcast_to(np.diag([10.0, 10, 10, 100, 100, 25]), (4949, 6, 6))
    )
    factors, _ = gtsam.load3D(str(data / "sphere2500.txt"))
    _compare_with_gtsam(graph, factors, gtsam.Values(), None)


def test_gtsam_files_without_vertices() -> None:
    _, data = _gtsam()
    graph = read(data / "w20000.txt", information_order="g2o")
    assert graph.num_edges == 26831
    np.testing.assert_array_equal(
        graph.information, np.broadcast_to(np.diag([3.16228, 3.16228, 5.0]), (26831, 3, 3))
    )
    odometry = np.flatnonzero(graph.ids[graph.edges[:, 1]] == graph.ids[graph.edges[:, 0]] + 1)
    _check_chained(graph, odometry[:: len(odometry) // 50].tolist(), atol=1e-9)


# ---------------------------------------------------------------------------------------
# Graphs from group elements.


@pytest.mark.parametrize("dim", [2, 3])
def test_graph_from_group_elements(dim: int) -> None:
    """Poses and measurements given as SE2 / SE3 elements (built from homogeneous matrices
    of scipy's rotations) are stored as vertex-layout rows whose matrices are those
    matrices, to rounding; an element of the other group raises ``ValueError``."""
    from jaxlie_geo import SE2, SE3

    G, other = (SE2, SE3) if dim == 2 else (SE3, SE2)
    rows = _random_graph(dim, np.random.default_rng(7), n=12, e=20)
    matrices = {
        name: np.stack([_matrix(dim, r) for r in getattr(rows, name)])
        for name in ("poses", "measurements")
    }
    elements = {name: G.from_matrix(m) for name, m in matrices.items()}
    graph = PoseGraph(dim, rows.ids, elements["poses"], rows.edges, elements["measurements"],
                      rows.information)  # fmt: skip
    for name, want in matrices.items():
        stored = getattr(graph, name)
        assert stored.dtype == np.float64 and stored.shape == getattr(rows, name).shape
        got = np.stack([_matrix(dim, r) for r in stored])
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12, err_msg=name)
    with pytest.raises(ValueError, match=f"takes {G.__name__} elements, got {other.__name__}"):
        PoseGraph(dim, rows.ids, other.identity((12,)), rows.edges, rows.measurements,
                  rows.information)  # fmt: skip
