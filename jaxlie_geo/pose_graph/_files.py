"""Pose-graph files: reading and writing the g2o and TORO text formats.

One record per line, tokens separated by whitespace; blank lines and lines whose first
non-blank character is ``#`` are skipped. The records, with the information matrix Ω of
each edge given by its upper triangle:

=================  ===================================================================
g2o 2D             ``VERTEX_SE2 id x y θ``
                   ``EDGE_SE2 i j dx dy dθ`` + 6 entries ``Ω11 Ω12 Ω13 Ω22 Ω23 Ω33``
                   (row by row, over ``(x, y, θ)``)
g2o 3D             ``VERTEX_SE3:QUAT id x y z qx qy qz qw``
                   ``EDGE_SE3:QUAT i j x y z qx qy qz qw`` + 21 entries (row by row,
                   over ``(x, y, z, qx, qy, qz)``)
TORO 2D            ``VERTEX2 id x y θ``
                   ``EDGE2 i j dx dy dθ`` + 6 entries in TORO's order
                   ``Ωxx Ωxy Ωyy Ωθθ Ωxθ Ωyθ``
TORO 3D            ``VERTEX3 id x y z roll pitch yaw``
                   ``EDGE3 i j x y z roll pitch yaw`` + 21 entries (row by row, over
                   ``(x, y, z, roll, pitch, yaw)``, translation first)
=================  ===================================================================

Conventions, common to all four:

- An edge ``(i, j)`` holds Zᵢⱼ, the pose of vertex j in the frame of vertex i:
  Zᵢⱼ ≈ Tᵢ⁻¹ Tⱼ, with i and j as written in the file.
- TORO's angles are ZYX Euler angles: R = Rz(yaw) Ry(pitch) Rx(roll), as
  ``SO3.from_rpy_radians``.
- Ω is taken as the information of the residual on this library's tangent, translation
  first: ``(vx, vy, ω)`` for SE(2) and ``(vx, vy, vz, ωx, ωy, ωz)`` for SE(3), with the
  entries in the positions the format gives them (no rescaling, so that writing
  reproduces the file). g2o's own 3D residual uses the vector part of the error
  quaternion, ≈ ω/2, for the rotation; like GTSAM's reader, its rotation block is used
  as the information of ω itself. TORO 3D's block over (roll, pitch, yaw) is likewise
  used as that of ω (equal to first order at small angles); its translation block comes
  first, as HOG-Man reads it (GTSAM's ``load3D`` puts the first block on the rotation).
- Vertex ids are arbitrary non-negative integers.

``TORO``'s ``EQUIV i j`` records (two vertices are the same place; TORO applies them only
on request, by collapsing the edge between them) and g2o's ``FIX id`` records (a vertex
held constant) have no counterpart in ``PoseGraph``: they are checked for their number of
tokens and otherwise ignored.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Dict, List, Optional, Sequence, Tuple, Union, get_args

import numpy as onp

from .. import hints
from ._graph import POSE_WIDTH, TANGENT_DIM, PoseGraph

PathLike = Union[str, "os.PathLike[str]"]
_FORMATS = get_args(hints.PoseGraphFormat)

#: |‖q‖ − 1| above which a g2o quaternion is rejected (files store about 6 digits).
QUATERNION_NORM_TOLERANCE = 1e-3


@dataclasses.dataclass(frozen=True)
class _Tag:
    name: str
    dim: int
    format: hints.PoseGraphFormat
    is_edge: bool
    numbers: int  # tokens after the tag, ids included


_TAGS = {
    tag.name: tag
    for tag in (
        _Tag("VERTEX_SE2", 2, "g2o", False, 1 + 3),
        _Tag("EDGE_SE2", 2, "g2o", True, 2 + 3 + 6),
        _Tag("VERTEX2", 2, "toro", False, 1 + 3),
        _Tag("EDGE2", 2, "toro", True, 2 + 3 + 6),
        _Tag("VERTEX_SE3:QUAT", 3, "g2o", False, 1 + 7),
        _Tag("EDGE_SE3:QUAT", 3, "g2o", True, 2 + 7 + 21),
        _Tag("VERTEX3", 3, "toro", False, 1 + 6),
        _Tag("EDGE3", 3, "toro", True, 2 + 6 + 21),
    )
}
_WRITE_TAGS = {
    ("g2o", 2): ("VERTEX_SE2", "EDGE_SE2"),
    ("g2o", 3): ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT"),
    ("toro", 2): ("VERTEX2", "EDGE2"),
    ("toro", 3): ("VERTEX3", "EDGE3"),
}
_NAMES = {"g2o": "g2o", "toro": "TORO"}
#: Ignored records: tag -> (fewest, most) tokens after the tag.
_IGNORED = {"EQUIV": (2, 2), "FIX": (1, None)}


def _upper_triangle(k: int, order: hints.PoseGraphFormat) -> Tuple[onp.ndarray, onp.ndarray]:
    """Row and column of each stored information entry, in the file's order."""
    if k == 3 and order == "toro":  # xx, xy, yy, θθ, xθ, yθ
        return onp.array([0, 0, 1, 2, 0, 1]), onp.array([0, 1, 1, 2, 2, 2])
    rows, cols = onp.triu_indices(k)  # row by row
    return rows, cols


class _Error(Exception):
    """A problem with one record: its line number and message, completed by ``read``."""

    def __init__(self, line: int, message: str):
        super().__init__(line, message)
        self.line = line
        self.message = message


class _EmptyError(Exception):
    """A file without edges."""


@dataclasses.dataclass
class _Records:
    """The records of one tag: line numbers and the numbers after the tag."""

    tag: _Tag
    lines: onp.ndarray  # (n,) int64
    values: onp.ndarray  # (n, tag.numbers) float64


# ---------------------------------------------------------------------------------------
# Parsing.


def _split_by_tag(text: str) -> Tuple[Dict[str, Tuple[List[int], List[str]]], int]:
    """The non-blank, non-comment lines grouped by tag, with their line numbers; the
    dimension of the file."""
    groups: Dict[str, Tuple[List[int], List[str]]] = {}
    first: Optional[Tuple[_Tag, int]] = None
    for number, line in enumerate(text.splitlines(), 1):
        head = line.split(None, 1)
        if not head or head[0].startswith("#"):
            continue
        name = head[0]
        group = groups.get(name)
        if group is None:
            tag = _TAGS.get(name)
            if tag is None and name not in _IGNORED:
                known = ", ".join([*_TAGS, *_IGNORED])
                raise _Error(number, f"{name}: unknown tag (expected one of {known})")
            group = groups[name] = ([], [])
            if tag is not None:
                if first is None:
                    first = (tag, number)
                elif tag.dim != first[0].dim:
                    raise _Error(
                        number,
                        f"{name}: a {tag.dim}D record in a {first[0].dim}D file "
                        f"(line {first[1]}: {first[0].name})",
                    )
        group[0].append(number)
        group[1].append(line)
    return groups, (first[0].dim if first is not None else 0)


def _parse_numbers(tag: _Tag, numbers: List[int], lines: List[str]) -> _Records:
    """The numbers of every record of ``tag``, float64, checked for count and finiteness."""
    k = tag.numbers + 1
    tokens = " ".join(lines).split()
    values: Optional[onp.ndarray] = None
    if len(tokens) == len(lines) * k:
        # Every line starts with the tag; with n·k tokens in all, all lines have k tokens
        # exactly when no tag lands among the numbers (a tag is not a number).
        del tokens[::k]
        try:
            values = onp.array(tokens, dtype=onp.float64).reshape(len(lines), tag.numbers)
        except ValueError:
            values = None
    if values is None:  # locate the first bad line, parsing as the block does
        for number, line in zip(numbers, lines):
            found = line.split()[1:]
            if len(found) != tag.numbers:
                raise _Error(
                    number, f"{tag.name}: expected {tag.numbers} numbers, got {len(found)}"
                )
            for token in found:
                try:
                    onp.array(token, dtype=onp.float64)
                except ValueError:
                    raise _Error(number, f"{tag.name}: {token!r} is not a number") from None
        raise AssertionError("the block did not parse but every line does")
    bad = ~onp.isfinite(values).all(axis=1)
    if bad.any():
        raise _Error(numbers[int(bad.argmax())], f"{tag.name}: a value is not finite")
    return _Records(tag, onp.asarray(numbers, dtype=onp.int64), values)


def _ids(records: _Records, columns: int) -> onp.ndarray:
    """The first ``columns`` numbers as ids: non-negative integers."""
    ids = records.values[:, :columns]
    bad = ~((ids == onp.floor(ids)) & (ids >= 0) & (ids < 2.0**53)).all(axis=1)
    if bad.any():
        row = int(bad.argmax())
        raise _Error(
            int(records.lines[row]),
            f"{records.tag.name}: a vertex id must be a non-negative integer, got "
            f"{ids[row].tolist()}",
        )
    return ids.astype(onp.int64)


def _check_quaternions(records: _Records, q: onp.ndarray) -> None:
    bad = onp.abs(onp.linalg.norm(q, axis=1) - 1.0) > QUATERNION_NORM_TOLERANCE
    if bad.any():
        row = int(bad.argmax())
        raise _Error(
            int(records.lines[row]),
            f"{records.tag.name}: the quaternion {q[row].tolist()} has norm "
            f"{float(onp.linalg.norm(q[row])):.9g}, not 1 (tolerance "
            f"{QUATERNION_NORM_TOLERANCE:g})",
        )


def _pose_values(records: _Records, start: int) -> onp.ndarray:
    """The pose or measurement columns in the vertex layout."""
    tag = records.tag
    if tag.dim == 2:
        return records.values[:, start : start + 3]
    if tag.format == "g2o":
        rows = records.values[:, start : start + 7]
        _check_quaternions(records, rows[:, 3:])
        return rows
    xyz, rpy = records.values[:, start : start + 3], records.values[:, start + 3 : start + 6]
    return onp.concatenate([xyz, rpy_to_quaternion(rpy)], axis=1)


def _information(records: _Records, order: hints.PoseGraphFormat) -> onp.ndarray:
    """The information matrices ``(n, k, k)``, the entries read in ``order``."""
    k = TANGENT_DIM[records.tag.dim]
    return _fill(records.values[:, -(k * (k + 1) // 2) :], k, order)


def _fill(entries: onp.ndarray, k: int, order: hints.PoseGraphFormat) -> onp.ndarray:
    """``(n, k(k+1)/2)`` upper-triangle entries in the file's order to ``(n, k, k)``."""
    rows, cols = _upper_triangle(k, order)
    out = onp.zeros((len(entries), k, k))
    out[:, rows, cols] = entries
    out[:, cols, rows] = entries
    return out


def _is_positive_definite(m: onp.ndarray) -> bool:
    try:
        onp.linalg.cholesky(m)
    except onp.linalg.LinAlgError:
        return False
    return True


def _check_information(records: _Records, order: hints.PoseGraphFormat) -> onp.ndarray:
    """The information matrices, else an error at the first one that is not positive
    definite (suggesting the other 2D order where it would give one)."""
    info = _information(records, order)
    if _is_positive_definite(info):
        return info
    for row in range(len(info)):
        if not _is_positive_definite(info[row]):
            break
    tag = records.tag
    message = (
        f"{tag.name}: the information matrix (read in {_NAMES[order]} order) is not "
        f"symmetric positive definite: {info[row].tolist()}"
    )
    if tag.dim == 2:
        other = "toro" if order == "g2o" else "g2o"
        if _is_positive_definite(_information(records, other)[row]):
            message += (
                f"; read in {_NAMES[other]} order it is: pass information_order={other!r}"
                " if the file stores it so"
            )
    raise _Error(int(records.lines[row]), message)


# ---------------------------------------------------------------------------------------
# Rotations and poses, NumPy float64.


def rpy_to_quaternion(rpy: onp.ndarray) -> onp.ndarray:
    """ZYX Euler angles ``(…, 3)`` (roll, pitch, yaw) to unit quaternions ``(…, 4)``
    ``(qx, qy, qz, qw)`` of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    half = 0.5 * onp.asarray(rpy, dtype=onp.float64)
    cr, cp, cy = onp.cos(half[..., 0]), onp.cos(half[..., 1]), onp.cos(half[..., 2])
    sr, sp, sy = onp.sin(half[..., 0]), onp.sin(half[..., 1]), onp.sin(half[..., 2])
    return onp.stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ],
        axis=-1,
    )


def quaternion_to_rpy(q: onp.ndarray) -> onp.ndarray:
    """Quaternions ``(…, 4)`` ``(qx, qy, qz, qw)``, normalised first, to ZYX Euler angles
    ``(…, 3)`` (roll, pitch, yaw), pitch in [−π/2, π/2].

    Yaw is read off the matrix, and roll and pitch off Rz(yaw)ᵀ R, so that the angles
    reproduce R to a few ulp also near pitch = ±π/2 (where roll and yaw are not
    determined separately)."""
    q = onp.asarray(q, dtype=onp.float64)
    x, y, z, w = onp.moveaxis(q / onp.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    r10, r11, r12 = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    r20 = 2 * (x * z - y * w)
    yaw = onp.arctan2(r10, r00)
    c, s = onp.cos(yaw), onp.sin(yaw)
    pitch = onp.arctan2(-r20, c * r00 + s * r10)
    roll = onp.arctan2(s * r02 - c * r12, c * r11 - s * r01)
    return onp.stack([roll, pitch, yaw], axis=-1)


def _compose2(a: Sequence[float], b: Sequence[float]) -> List[float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return [
        a[0] + c * b[0] - s * b[1],
        a[1] + s * b[0] + c * b[1],
        math.remainder(a[2] + b[2], math.tau),
    ]


def _inverse2(a: Sequence[float]) -> List[float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return [-(c * a[0] + s * a[1]), s * a[0] - c * a[1], -a[2]]


def _rotate(q: Sequence[float], v: Sequence[float]) -> List[float]:
    """v rotated by the unit quaternion q = (x, y, z, w): v + 2w(u×v) + 2u×(u×v)."""
    x, y, z, w = q
    tx = 2 * (y * v[2] - z * v[1])
    ty = 2 * (z * v[0] - x * v[2])
    tz = 2 * (x * v[1] - y * v[0])
    return [
        v[0] + w * tx + (y * tz - z * ty),
        v[1] + w * ty + (z * tx - x * tz),
        v[2] + w * tz + (x * ty - y * tx),
    ]


def _compose3(a: Sequence[float], b: Sequence[float]) -> List[float]:
    t = _rotate(a[3:], b[:3])
    x1, y1, z1, w1 = a[3:]
    x2, y2, z2, w2 = b[3:]
    return [
        a[0] + t[0],
        a[1] + t[1],
        a[2] + t[2],
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
    ]


def _inverse3(a: Sequence[float]) -> List[float]:
    q = [-a[3], -a[4], -a[5], a[6]]
    t = _rotate(q, a[:3])
    return [-t[0], -t[1], -t[2], *q]


def _chain(
    dim: int, poses: onp.ndarray, known: onp.ndarray, edges: onp.ndarray, z: onp.ndarray
) -> None:
    """Fill the unknown rows of ``poses`` in place by composing the edges in order."""
    if dim == 3:  # unit quaternions for composing (the stored measurements keep the file's)
        z = z.copy()
        z[:, 3:] /= onp.linalg.norm(z[:, 3:], axis=1, keepdims=True)
    compose, inverse = (_compose2, _inverse2) if dim == 2 else (_compose3, _inverse3)
    identity = [0.0] * POSE_WIDTH[dim]
    if dim == 3:
        identity[6] = 1.0
    rows: List[Optional[List[float]]] = [None] * len(poses)
    for index in onp.flatnonzero(known).tolist():
        rows[index] = poses[index].tolist()
    for (i, j), zij in zip(edges.tolist(), z.tolist()):
        ti, tj = rows[i], rows[j]
        if ti is not None and tj is not None:
            continue
        if ti is None and tj is None:
            ti = rows[i] = list(identity)
        if tj is None:
            assert ti is not None
            rows[j] = compose(ti, zij)
        else:
            rows[i] = compose(tj, inverse(zij))
    missing = [index for index, row in enumerate(rows) if row is None]
    assert not missing, "every id appears in a vertex or an edge"
    poses[~known] = onp.array([row for row, k in zip(rows, known.tolist()) if not k])


# ---------------------------------------------------------------------------------------
# The public functions.


def read(path: PathLike, *, information_order: Optional[hints.PoseGraphFormat] = None) -> PoseGraph:
    """Read a pose graph from a g2o or TORO file, 2D or 3D, the format told by the tags.

    The records and conventions are those of this module's description: Zᵢⱼ is the pose
    of j in the frame of i, TORO's angles are R = Rz(yaw) Ry(pitch) Rx(roll), and the
    information matrix is on the translation-first tangent (g2o's 3D rotation block taken
    as the information of ω, unscaled, as GTSAM does). Numbers are kept exactly as
    written: g2o quaternions are not normalised (their norm is checked), so that writing
    the graph in the same format reproduces them; TORO's Euler angles are converted to
    unit quaternions in float64.

    Ids: ``graph.ids`` lists the vertex ids in the order of their vertex records, then the
    ids that appear only in edges, in the order they appear there; ``graph.edges`` indexes
    that order. Poses without a vertex record (all of them in files of edges only) are
    initialised as GTSAM's loaders do, by composing the edges in file order: for an edge
    (i, j) whose two poses are unknown, Tᵢ = identity; then Tⱼ = Tᵢ Zᵢⱼ if Tⱼ is
    unknown, or Tᵢ = Tⱼ Zᵢⱼ⁻¹ if only Tᵢ is.
    TORO's ``EQUIV`` and g2o's ``FIX`` records are ignored (see the module's description).

    Args:
        path: the file, read as text.
        information_order: the order of the 6 information entries of 2D edges: None for
            each tag's own (g2o's row-by-row upper triangle for ``EDGE_SE2``, TORO's
            ``xx xy yy θθ xθ yθ`` for ``EDGE2``), ``"g2o"`` or ``"toro"`` to read every 2D
            edge so (some files, e.g. GTSAM's ``w20000.txt``, store g2o's order under
            ``EDGE2`` tags). 3D edges store a row-by-row upper triangle in both formats;
            the argument does not change them.

    Returns:
        The ``PoseGraph``, float64 arrays: poses and measurements in the vertex layout
        (``(x, y, θ)`` or ``(x, y, z, qx, qy, qz, qw)``), information ``(E, 3, 3)`` or
        ``(E, 6, 6)``, edges ``(E, 2)`` as written (not reordered).

    Raises:
        FileNotFoundError: (and the other ``OSError``) where the file cannot be opened.
        ValueError: with a message that starts with ``"{path}:{line}: "`` and names the
            tag, for a malformed record: an unknown tag, a wrong number of tokens, a token
            that is not a number, a value that is not finite, an id that is not a
            non-negative integer, a 2D and a 3D record in one file, a duplicate vertex id,
            an edge from a vertex to itself, a g2o quaternion whose norm differs from 1 by
            more than ``QUATERNION_NORM_TOLERANCE``, an information matrix that is not
            symmetric positive definite (the message suggests ``information_order`` where
            the other 2D order gives one). With a message that starts with
            ``"{path}: "``: a file without edges. Also where ``information_order`` is
            not None, ``"g2o"`` or ``"toro"``.
    """
    if information_order is not None and information_order not in _FORMATS:
        raise ValueError(
            f"read: information_order must be None, 'g2o' or 'toro', got {information_order!r}"
        )
    with open(path, encoding="utf-8-sig") as file:  # a byte-order mark is skipped
        text = file.read()
    try:
        return _read(text, information_order)
    except _Error as error:
        raise ValueError(f"{os.fspath(path)}:{error.line}: {error.message}") from None
    except _EmptyError as error:
        raise ValueError(f"{os.fspath(path)}: {error}") from None


def _read(text: str, information_order: Optional[str]) -> PoseGraph:
    groups, dim = _split_by_tag(text)
    vertices: List[Tuple[onp.ndarray, onp.ndarray, onp.ndarray]] = []  # lines, ids, poses
    edges: List[Tuple[onp.ndarray, ...]] = []  # lines, ij, measurements, information
    for name, (numbers, lines) in groups.items():
        if name in _IGNORED:
            low, high = _IGNORED[name]
            for number, line in zip(numbers, lines):
                count = len(line.split()) - 1
                if count < low or (high is not None and count > high):
                    expected = f"{low}" if low == high else f"at least {low}"
                    raise _Error(number, f"{name}: expected {expected} ids, got {count}")
            continue
        records = _parse_numbers(_TAGS[name], numbers, lines)
        tag = records.tag
        if not tag.is_edge:
            vertices.append((records.lines, _ids(records, 1)[:, 0], _pose_values(records, 1)))
            continue
        ij = _ids(records, 2)
        loops = ij[:, 0] == ij[:, 1]
        if loops.any():
            row = int(loops.argmax())
            raise _Error(
                int(records.lines[row]), f"{name}: an edge from vertex {ij[row, 0]} to itself"
            )
        order = information_order if (information_order and dim == 2) else tag.format
        information = _check_information(records, order)
        edges.append((records.lines, ij, _pose_values(records, 2), information))
    if not edges:
        what = "no edges" if vertices else "no vertices or edges"
        raise _EmptyError(f"{what}: not a pose graph in the g2o or TORO format")

    v_lines, v_ids, v_poses = _merge(vertices, dim)
    e_lines, ij, measurements, information = _merge(edges, dim)

    # Duplicate vertex ids (records in line order): the first repeat is the error.
    _, first_rows = onp.unique(v_ids, return_index=True)
    if len(first_rows) < len(v_ids):
        is_first = onp.zeros(len(v_ids), dtype=bool)
        is_first[first_rows] = True
        row = int(onp.argmin(is_first))
        at = int(v_lines[row])
        first = int(v_lines[onp.flatnonzero(v_ids == v_ids[row])[0]])
        raise _Error(
            at,
            f"{_tag_at(groups, at)}: duplicate vertex id {v_ids[row]} (first defined on "
            f"line {first})",
        )

    # Ids in order of first appearance: vertex records, then edges (i before j).
    every = onp.concatenate([v_ids, ij.reshape(-1)])
    unique, first_seen, inverse = onp.unique(every, return_index=True, return_inverse=True)
    by_appearance = onp.argsort(first_seen, kind="stable")
    rank = onp.empty_like(by_appearance)
    rank[by_appearance] = onp.arange(len(unique))
    index = rank[inverse.reshape(-1)]
    ids = unique[by_appearance]
    edge_index = index[len(v_ids) :].reshape(-1, 2)

    width = POSE_WIDTH[dim]
    poses = onp.zeros((len(ids), width))
    known = onp.zeros(len(ids), dtype=bool)
    poses[index[: len(v_ids)]] = v_poses
    known[index[: len(v_ids)]] = True
    if not known.all():
        _chain(dim, poses, known, edge_index, measurements)
    return PoseGraph(
        dim=2 if dim == 2 else 3,
        ids=ids.astype(onp.int64),
        poses=poses,
        edges=edge_index.astype(onp.int64),
        measurements=measurements,
        information=information,
    )


def _merge(parts: Sequence[Tuple[onp.ndarray, ...]], dim: int) -> Tuple[onp.ndarray, ...]:
    """Concatenate the records of several tags, in line order."""
    if not parts:
        width = POSE_WIDTH[dim]
        return (
            onp.zeros(0, dtype=onp.int64),
            onp.zeros(0, dtype=onp.int64),
            onp.zeros((0, width)),
        )
    if len(parts) == 1:
        return parts[0]
    joined = [onp.concatenate(column) for column in zip(*parts)]
    order = onp.argsort(joined[0], kind="stable")
    return tuple(column[order] for column in joined)


def _tag_at(groups: Dict[str, Tuple[List[int], List[str]]], line: int) -> str:
    for name, (numbers, _) in groups.items():
        if line in numbers:
            return name
    return "?"


def write(path: PathLike, graph: PoseGraph, *, format: hints.PoseGraphFormat = "g2o") -> None:
    """Write a pose graph as a g2o or TORO file: the vertex records, then the edges.

    The records and conventions are those of this module's description; ``read`` reads the
    file back. Floats are written with the shortest representation that reads back to the
    same float64 (``repr``), so that g2o files (2D and 3D) and TORO 2D files read back
    bit for bit. TORO 3D files store Euler angles: the quaternions are normalised and
    converted to (roll, pitch, yaw), and read back as unit quaternions that give the same
    rotation to a few ulp (not bit for bit; the sign of the quaternion may flip).
    Information matrices are written as their upper triangle in the format's order (TORO
    2D: ``xx xy yy θθ xθ yθ``).

    Args:
        path: the file, created or overwritten.
        graph: the pose graph; its information matrices must be symmetric.
        format: ``"g2o"`` (``VERTEX_SE2``/``EDGE_SE2`` or ``VERTEX_SE3:QUAT``/
            ``EDGE_SE3:QUAT``) or ``"toro"`` (``VERTEX2``/``EDGE2`` or
            ``VERTEX3``/``EDGE3``).

    Raises:
        ValueError: where ``format`` is neither, an information matrix is not exactly
            symmetric, or a value is not finite (the file could not be read back).
    """
    if format not in _FORMATS:
        raise ValueError(f"write: format must be 'g2o' or 'toro', got {format!r}")
    info = onp.asarray(graph.information, dtype=onp.float64)
    if not onp.array_equal(info, onp.swapaxes(info, -1, -2)):
        row = int((info != onp.swapaxes(info, -1, -2)).any(axis=(1, 2)).argmax())
        raise ValueError(
            f"write: the information matrix of edge {row} is not symmetric (the file "
            "stores the upper triangle)"
        )
    for name in ("poses", "measurements", "information"):
        if not onp.isfinite(getattr(graph, name)).all():
            raise ValueError(f"write: graph.{name} has a value that is not finite")
    dim = graph.dim
    vertex_tag, edge_tag = _WRITE_TAGS[(format, dim)]
    poses = onp.asarray(graph.poses, dtype=onp.float64)
    measurements = onp.asarray(graph.measurements, dtype=onp.float64)
    if format == "toro" and dim == 3:
        poses = onp.concatenate([poses[:, :3], quaternion_to_rpy(poses[:, 3:])], axis=1)
        measurements = onp.concatenate(
            [measurements[:, :3], quaternion_to_rpy(measurements[:, 3:])], axis=1
        )
    rows, cols = _upper_triangle(TANGENT_DIM[dim], format)
    entries = info[:, rows, cols]
    ids = graph.ids.tolist()
    out: List[str] = []
    for vertex_id, pose in zip(ids, poses.tolist()):
        out.append(f"{vertex_tag} {vertex_id} {' '.join(map(repr, pose))}")
    for (i, j), z, e in zip(graph.edges.tolist(), measurements.tolist(), entries.tolist()):
        out.append(f"{edge_tag} {ids[i]} {ids[j]} {' '.join(map(repr, z + e))}")
    with open(path, "w", encoding="utf-8") as file:
        file.write("\n".join(out) + "\n")
