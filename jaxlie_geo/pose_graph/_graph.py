"""The pose graph: vertices, relative-pose edges and their information matrices, and
optionally point landmarks with the poses' measurements of them.

A leaf module: plain NumPy containers on the host, float64, no JAX tracing. The solver
converts them to device arrays once per solve.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal, Optional, Union, cast

import numpy as onp

from .._base import MatrixLieGroup
from .._se2 import SE2
from .._se3 import SE3

Pose = Union[SE2, SE3]

#: Width of one pose in the vertex layout: SE2 (x, y, θ), SE3 (x, y, z, qx, qy, qz, qw).
POSE_WIDTH = {2: 3, 3: 7}
#: Tangent dimension: SE2 (vx, vy, ω), SE3 (vx, vy, vz, ωx, ωy, ωz).
TANGENT_DIM = {2: 3, 3: 6}
#: The default of the landmark attributes: replaced by empty arrays of their shapes.
_EMPTY: Any = None


@dataclasses.dataclass(frozen=True, eq=False)
class PoseGraph:
    """Poses and relative-pose measurements between them, as read from a file.

    Arrays are NumPy float64 (int64 for indices), on the host; the constructor converts
    array-likes to them and checks shapes, finiteness and the symmetry of the information
    (to 1e-12 of its largest entry), raising ``ValueError``. Poses and measurements are
    stored in the vertex layout of the g2o format, so that reading and writing are exact:

    - 2D (SE2): ``(x, y, θ)``, shape ``(·, 3)``;
    - 3D (SE3): ``(x, y, z, qx, qy, qz, qw)``, shape ``(·, 7)``, unit quaternion.

    ``poses`` and ``measurements`` may also be given as group elements (``SE2`` for
    ``dim=2``, ``SE3`` for ``dim=3``) of batch ``(N,)`` and ``(E,)``; they are stored in
    that layout (``from_group``: θ = atan2(sin, cos), the quaternion as the element holds
    it).

    A graph may also hold point landmarks l_m (positions in the world frame, in ℝ^dim) and
    observations of them: an observation (i, m) holds z, the position of landmark m in
    the frame of pose i, z ≈ T_world_i⁻¹ l_m = Rᵢᵀ(l_m − tᵢ), and the information of that
    residual. The five landmark attributes default to empty arrays (a pure pose graph).

    Attributes:
        dim: 2 or 3.
        ids: ``(N,)`` int64, the vertex ids used in the file, in the order of ``poses``.
        poses: ``(N, 3)`` or ``(N, 7)``, the estimate T_world_i of every vertex (or a group
            element of batch ``(N,)``).
        edges: ``(E, 2)`` int64, indices ``(i, j)`` into ``poses`` (not ids).
        measurements: ``(E, 3)`` or ``(E, 7)`` (or a group element of batch ``(E,)``),
            Zᵢⱼ, the measured pose of j in the frame of i: Zᵢⱼ ≈ T_world_i⁻¹ T_world_j.
        information: ``(E, k, k)``, symmetric positive definite, on this library's tangent
            of the residual rᵢⱼ = log(Zᵢⱼ⁻¹ T_world_i⁻¹ T_world_j): SE2 ``(vx, vy, ω)``,
            SE3 ``(vx, vy, vz, ωx, ωy, ωz)`` (translation first), k = 3 or 6.
        landmark_ids: ``(M,)`` int64, the landmarks' ids in the file (their own id space).
        landmarks: ``(M, dim)``, the estimate of every landmark's world position.
        observations: ``(K, 2)`` int64, ``(i, m)``: an index into ``poses`` and one into
            ``landmarks``.
        observation_measurements: ``(K, dim)``, z, landmark m in the frame of pose i.
        observation_information: ``(K, dim, dim)``, symmetric positive definite, on the
            residual Rᵢᵀ(l_m − tᵢ) − z.
    """

    dim: Literal[2, 3]
    ids: onp.ndarray
    poses: onp.ndarray
    edges: onp.ndarray
    measurements: onp.ndarray
    information: onp.ndarray
    landmark_ids: onp.ndarray = _EMPTY
    landmarks: onp.ndarray = _EMPTY
    observations: onp.ndarray = _EMPTY
    observation_measurements: onp.ndarray = _EMPTY
    observation_information: onp.ndarray = _EMPTY

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise ValueError(f"PoseGraph: dim must be 2 or 3, got {self.dim!r}")
        w, k = POSE_WIDTH[self.dim], TANGENT_DIM[self.dim]
        group = SE2 if self.dim == 2 else SE3
        for name in ("poses", "measurements"):  # group elements to the vertex layout
            value = getattr(self, name)
            if isinstance(value, MatrixLieGroup):
                if type(value) is not group:
                    raise ValueError(
                        f"PoseGraph.{name}: a {self.dim}D graph takes {group.__name__} "
                        f"elements, got {type(value).__name__}"
                    )
                object.__setattr__(self, name, from_group(value))
        d = self.dim
        empty = {"landmark_ids": (0,), "landmarks": (0, d), "observations": (0, 2)}
        empty.update(observation_measurements=(0, d), observation_information=(0, d, d))
        for name, shape in empty.items():
            if getattr(self, name) is None:
                integer = name in ("landmark_ids", "observations")
                object.__setattr__(self, name, onp.zeros(shape, onp.int64 if integer else float))
        kinds = {"ids": "i", "poses": "f", "edges": "i", "measurements": "f", "information": "f"}
        kinds.update(landmark_ids="i", landmarks="f", observations="i")
        kinds.update(observation_measurements="f", observation_information="f")
        for name, kind in kinds.items():  # integers to int64, reals to float64
            array = onp.asarray(getattr(self, name))
            if array.dtype.kind not in ("iu" if kind == "i" else "iuf"):
                raise ValueError(f"PoseGraph.{name}: expected numbers, got dtype {array.dtype}")
            target = onp.int64 if kind == "i" else onp.float64
            object.__setattr__(self, name, onp.asarray(array, dtype=target))
        n, e = len(self.ids), len(self.edges)
        shapes = {"ids": (n,), "poses": (n, w), "edges": (e, 2), "measurements": (e, w)}
        shapes["information"] = (e, k, k)
        m, o = len(self.landmark_ids), len(self.observations)
        shapes.update(landmark_ids=(m,), landmarks=(m, d), observations=(o, 2))
        shapes.update(observation_measurements=(o, d), observation_information=(o, d, d))
        for name, shape in shapes.items():
            array = getattr(self, name)
            if array.shape != shape:
                raise ValueError(f"PoseGraph.{name}: expected shape {shape}, got {array.shape}")
            if kinds[name] == "f" and not onp.all(onp.isfinite(array)):
                row = int(onp.argwhere(~onp.isfinite(array))[0][0])
                raise ValueError(f"PoseGraph.{name}: a non-finite value in row {row}")
        if e and (self.edges.min() < 0 or self.edges.max() >= n):
            raise ValueError(
                f"PoseGraph.edges: indices must lie in [0, {n}), "
                f"got {self.edges.min()}..{self.edges.max()}"
            )
        for column, count in ((0, n), (1, m)):
            index = self.observations[:, column]
            if o and (index.min() < 0 or index.max() >= count):
                raise ValueError(
                    f"PoseGraph.observations: column {column} must lie in [0, {count}), "
                    f"got {index.min()}..{index.max()}"
                )
        for name, what in (("information", "edge"), ("observation_information", "observation")):
            info = getattr(self, name)
            asymmetry = onp.abs(info - onp.swapaxes(info, -1, -2)).max(axis=(-2, -1), initial=0.0)
            scale = onp.abs(info).max(axis=(-2, -1), initial=0.0)
            bad = onp.flatnonzero(asymmetry > 1e-12 * scale)
            if len(bad):
                raise ValueError(f"PoseGraph.{name}: {what} {bad[0]} is not symmetric")

    @property
    def group(self) -> type[SE2] | type[SE3]:
        """SE2 for a 2D graph, SE3 for a 3D one."""
        return SE2 if self.dim == 2 else SE3

    @property
    def num_poses(self) -> int:
        return len(self.ids)

    @property
    def num_edges(self) -> int:
        return len(self.edges)

    @property
    def num_landmarks(self) -> int:
        return len(self.landmark_ids)

    @property
    def num_observations(self) -> int:
        return len(self.observations)

    def pose_group(self) -> Pose:
        """The poses as a group element of batch ``(N,)``, with NumPy float64 parameters
        (quaternions as stored: ``normalize()`` them for a file's few-digit ones)."""
        return to_group(self.dim, self.poses)

    def measurement_group(self) -> Pose:
        """The measurements as a group element of batch ``(E,)``."""
        return to_group(self.dim, self.measurements)

    def with_poses(
        self, poses: Pose | onp.ndarray, landmarks: Optional[onp.ndarray] = None
    ) -> PoseGraph:
        """The same graph with other pose estimates (a group element of batch ``(N,)`` or an
        array in the vertex layout), e.g. a solver's result, ready to be written; and other
        landmark positions ``(M, dim)`` where given."""
        array = poses if isinstance(poses, onp.ndarray) else from_group(poses)
        landmarks = self.landmarks if landmarks is None else onp.asarray(landmarks, onp.float64)
        return dataclasses.replace(
            self, poses=onp.asarray(array, dtype=onp.float64), landmarks=landmarks
        )


def to_group(dim: int, rows: onp.ndarray) -> Pose:
    """Vertex-layout rows ``(·, 3)`` / ``(·, 7)`` to SE2 / SE3."""
    if dim == 2:
        x, y, theta = rows[..., 0], rows[..., 1], rows[..., 2]
        return SE2(cast(Any, onp.stack([onp.cos(theta), onp.sin(theta), x, y], axis=-1)))
    xyz, q = rows[..., :3], rows[..., 3:]
    return SE3(cast(Any, onp.concatenate([q[..., 3:], q[..., :3], xyz], axis=-1)))


def from_group(pose: Pose) -> onp.ndarray:
    """SE2 / SE3 to vertex-layout rows, float64."""
    p = onp.asarray(pose.parameters(), dtype=onp.float64)
    if isinstance(pose, SE2):
        return onp.stack([p[..., 2], p[..., 3], onp.arctan2(p[..., 1], p[..., 0])], axis=-1)
    return onp.concatenate([p[..., 4:], p[..., 1:4], p[..., :1]], axis=-1)
