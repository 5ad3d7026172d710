"""Pose-graph files: reading and writing the g2o and TORO text formats.

One record per line, tokens separated by whitespace; blank lines and lines whose first
non-blank character is ``#`` are skipped. The records, with the information matrix Ω of
each edge given by its upper triangle:

=================  ===================================================================
g2o 2D             ``VERTEX_SE2 id x y θ``
                   ``EDGE_SE2 i j dx dy dθ`` + 6 entries ``Ω11 Ω12 Ω13 Ω22 Ω23 Ω33``
                   (row by row, over ``(x, y, θ)``)
                   ``LANDMARK2 i m zx zy`` + 3 entries ``Ωxx Ωxy Ωyy``: pose i sees
                   landmark m at z in its frame
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
- Vertex ids are arbitrary non-negative integers. Landmark ids (``LANDMARK2``'s m) are
  their own id space: a landmark may share its number with a pose (cityTrees does).
- A ``LANDMARK2`` record (i, m) holds z ≈ Rᵢᵀ(l_m − tᵢ), landmark m's position in the
  frame of pose i, and the information of that 2-vector. The format has no landmark
  vertex: a landmark's initial position is where its first observation puts it,
  l_m = tᵢ + Rᵢ z, from pose i's initial estimate. GTSAM's ``readG2o`` and ``load2D``
  skip these records.

``TORO``'s ``EQUIV i j`` records (two vertices are the same place; TORO applies them only
on request, by collapsing the edge between them) and g2o's ``FIX id`` records (a vertex
held constant) have no counterpart in ``PoseGraph``: they are checked for their number of
tokens and otherwise ignored.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union, cast, get_args

import numpy as onp

from .. import hints
from .._so3 import SO3
from .._xla import x64
from ._graph import POSE_WIDTH, TANGENT_DIM, PoseGraph, from_group, to_group

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
    is_landmark: bool = False  # a pose–landmark observation


_TAGS = {
    tag.name: tag
    for tag in (
        _Tag("VERTEX_SE2", 2, "g2o", False, 1 + 3),
        _Tag("EDGE_SE2", 2, "g2o", True, 2 + 3 + 6),
        _Tag("LANDMARK2", 2, "g2o", False, 2 + 2 + 3, is_landmark=True),
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
    tag = records.tag
    k = tag.dim if tag.is_landmark else TANGENT_DIM[tag.dim]
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
    if tag.dim == 2 and not tag.is_landmark:
        other: hints.PoseGraphFormat = "toro" if order == "g2o" else "g2o"
        if _is_positive_definite(_information(records, other)[row]):
            message += (
                f"; read in {_NAMES[other]} order it is: pass information_order={other!r}"
                " if the file stores it so"
            )
    raise _Error(int(records.lines[row]), message)


# ---------------------------------------------------------------------------------------
# Rotations and poses: the library's groups, in float64.


def _padded(rows: onp.ndarray, fill: Sequence[float]) -> onp.ndarray:
    """``rows`` ``(m, w)`` followed by copies of ``fill`` up to the next power of two, so
    that the jitted group operations compile once per size class, not once per file."""
    m = len(rows)
    size = 1 << max(0, (m - 1).bit_length())
    return onp.concatenate(
        [rows, onp.broadcast_to(onp.asarray(fill, float), (size - m, len(fill)))]
    )


def rpy_to_quaternion(rpy: onp.ndarray) -> onp.ndarray:
    """ZYX Euler angles ``(…, 3)`` (roll, pitch, yaw) to unit quaternions ``(…, 4)``
    ``(qx, qy, qz, qw)`` of R = Rz(yaw) Ry(pitch) Rx(roll) (``SO3.from_rpy_radians``)."""
    rpy = onp.asarray(rpy, dtype=onp.float64)
    flat = rpy.reshape(-1, 3)
    a = _padded(flat, [0.0, 0.0, 0.0])
    with x64(True):
        R = SO3.from_rpy_radians(a[:, 0], a[:, 1], a[:, 2])
        q = onp.asarray(R.as_quaternion_xyzw(), dtype=onp.float64)
    return q[: len(flat)].reshape(*rpy.shape[:-1], 4)


def quaternion_to_rpy(q: onp.ndarray) -> onp.ndarray:
    """Quaternions ``(…, 4)`` ``(qx, qy, qz, qw)`` to ZYX Euler angles ``(…, 3)`` (roll,
    pitch, yaw), pitch in [−π/2, π/2], by ``SO3.as_rpy_radians``: the angles reproduce R to
    a few ulp also near pitch = ±π/2, where roll and yaw are not determined separately."""
    q = onp.asarray(q, dtype=onp.float64)
    flat = q.reshape(-1, 4)
    with x64(True):
        angles = SO3.from_quaternion_xyzw(_padded(flat, [0.0, 0.0, 0.0, 1.0])).as_rpy_radians()
        rpy = onp.stack([onp.asarray(a, dtype=onp.float64) for a in angles], axis=-1)
    return rpy[: len(flat)].reshape(*q.shape[:-1], 3)


def _spanning_forest(
    n: int, known: onp.ndarray, edges: onp.ndarray
) -> Tuple[onp.ndarray, onp.ndarray, onp.ndarray]:
    """Which edge places each vertex whose pose is not known, taking the edges in order:
    an edge with one end placed places the other, an edge with neither starts a new tree
    at the identity on its i (a loop closure, both ends placed, is skipped). Returns, per
    vertex, the placing edge (−1 for a root: a known vertex or a tree's start), its other
    end, and whether the edge is read backwards (the vertex is the edge's i)."""
    placed = known.copy()
    edge, parent = onp.full(n, -1), onp.full(n, -1)
    backwards = onp.zeros(n, dtype=bool)
    for e, (i, j) in enumerate(edges.tolist()):
        if placed[i] and placed[j]:
            continue
        if not placed[i] and not placed[j]:
            placed[i] = True  # a root at the identity
        if placed[i]:
            edge[j], parent[j], placed[j] = e, i, True
        else:
            edge[i], parent[i], backwards[i], placed[i] = e, j, True, True
    assert placed.all(), "every id appears in a vertex or an edge"
    return edge, parent, backwards


def _chain(
    dim: int, poses: onp.ndarray, known: onp.ndarray, edges: onp.ndarray, z: onp.ndarray
) -> None:
    """Fill the unknown rows of ``poses`` in place by composing the edges in order
    (``_spanning_forest``): T_j = T_i Z_ij forwards, T_i = T_j Z_ij⁻¹ backwards, roots
    kept (known) or at the identity. The compositions along each tree run batched, by
    pointer jumping: every vertex composes with its ancestor's product and jumps to the
    ancestor's ancestor, ⌈log₂(depth + 1)⌉ rounds of one group product."""
    n = len(poses)
    edge, parent, backwards = _spanning_forest(n, known, edges)
    if dim == 3:  # unit quaternions for composing (the stored measurements keep the file's)
        z = z.copy()
        z[:, 3:] /= onp.linalg.norm(z[:, 3:], axis=1, keepdims=True)
    identity = [0.0] * POSE_WIDTH[dim]
    if dim == 3:
        identity[6] = 1.0
    rows = poses.copy()
    rows[(edge < 0) & ~known] = identity
    # Each vertex's transform from its parent (its own pose at a root), padded with roots.
    root = _padded((edge < 0)[:, None].astype(float), [1.0])[:, 0] > 0
    m = len(root)
    ancestor = onp.concatenate([parent, onp.full(m - n, -1)])
    with x64(True):
        Z = to_group(dim, _padded(z[onp.maximum(edge, 0)], identity))
        G: Any = type(Z)
        step = onp.where(
            _padded(backwards[:, None].astype(float), [0.0]) > 0,
            onp.asarray(Z.inverse().parameters()),
            onp.asarray(Z.parameters()),
        )
        own = onp.asarray(to_group(dim, _padded(rows, identity)).parameters())
        product = onp.where(root[:, None], own, step)
        while (ancestor >= 0).any():
            active = ancestor >= 0
            up = onp.where(active, ancestor, onp.arange(m))
            composed = onp.asarray((G(product[up]) @ G(product)).parameters())
            product = onp.where(active[:, None], composed, product)
            ancestor = onp.where(active, ancestor[up], -1)
        chained = from_group(G(product[:n]))
    poses[~known] = chained[~known]


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
    sightings: List[Tuple[onp.ndarray, ...]] = []  # lines, (i, m), z, information
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
        if tag.is_landmark:
            information = _check_information(records, "g2o")
            sightings.append((records.lines, _ids(records, 2), records.values[:, 2:4], information))
            continue
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
        order = cast(
            hints.PoseGraphFormat,
            information_order if (information_order and dim == 2) else tag.format,
        )
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
    ids, index, _ = _by_appearance(onp.concatenate([v_ids, ij.reshape(-1)]))
    edge_index = index[len(v_ids) :].reshape(-1, 2)

    width = POSE_WIDTH[dim]
    poses = onp.zeros((len(ids), width))
    known = onp.zeros(len(ids), dtype=bool)
    poses[index[: len(v_ids)]] = v_poses
    known[index[: len(v_ids)]] = True
    if not known.all():
        _chain(dim, poses, known, edge_index, measurements)
    landmarks = {} if not sightings else _landmarks(groups, ids, poses, *_merge(sightings, dim))
    return PoseGraph(
        dim=2 if dim == 2 else 3,
        ids=ids.astype(onp.int64),
        poses=poses,
        edges=edge_index.astype(onp.int64),
        measurements=measurements,
        information=information,
        **landmarks,
    )


def _landmarks(
    groups: Dict[str, Tuple[List[int], List[str]]],
    ids: onp.ndarray,
    poses: onp.ndarray,
    lines: onp.ndarray,
    im: onp.ndarray,
    z: onp.ndarray,
    information: onp.ndarray,
) -> Dict[str, onp.ndarray]:
    """``PoseGraph``'s landmark attributes from the 2D observation records (in line order):
    landmark ids in order of first appearance, each landmark placed by its first
    observation, l = t + R z."""
    order = onp.argsort(ids, kind="stable")
    at = onp.minimum(onp.searchsorted(ids[order], im[:, 0]), len(ids) - 1)
    missing = ids[order][at] != im[:, 0]
    if missing.any():
        row = int(missing.argmax())
        raise _Error(
            int(lines[row]),
            f"{_tag_at(groups, int(lines[row]))}: pose {im[row, 0]} is in no vertex or edge",
        )
    pose = order[at]
    landmark_ids, landmark, first = _by_appearance(im[:, 1])
    x, y, theta = poses[pose[first]].T
    c, s = onp.cos(theta), onp.sin(theta)
    zx, zy = z[first].T
    return {
        "landmark_ids": landmark_ids,
        "landmarks": onp.stack([x + c * zx - s * zy, y + s * zx + c * zy], axis=1),
        "observations": onp.stack([pose, landmark], axis=1),
        "observation_measurements": z,
        "observation_information": information,
    }


def _by_appearance(values: onp.ndarray) -> Tuple[onp.ndarray, onp.ndarray, onp.ndarray]:
    """The distinct values in order of first appearance, each value's index into them, and
    the position of each distinct value's first appearance."""
    unique, first_seen, inverse = onp.unique(values, return_index=True, return_inverse=True)
    by_appearance = onp.argsort(first_seen, kind="stable")
    rank = onp.empty_like(by_appearance)
    rank[by_appearance] = onp.arange(len(unique))
    return unique[by_appearance], rank[inverse.reshape(-1)], first_seen[by_appearance]


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
    2D: ``xx xy yy θθ xθ yθ``). A 2D g2o graph's landmark observations follow the edges as
    ``LANDMARK2`` records; the format stores no landmark positions, so ``read`` places
    the landmarks again from their first observation.

    Args:
        path: the file, created or overwritten.
        graph: the pose graph; its information matrices must be symmetric.
        format: ``"g2o"`` (``VERTEX_SE2``/``EDGE_SE2`` or ``VERTEX_SE3:QUAT``/
            ``EDGE_SE3:QUAT``) or ``"toro"`` (``VERTEX2``/``EDGE2`` or
            ``VERTEX3``/``EDGE3``).

    Raises:
        ValueError: where ``format`` is neither, an information matrix is not exactly
            symmetric, a value is not finite (the file could not be read back), or the
            graph has landmark observations and is not written as 2D g2o.
    """
    if format not in _FORMATS:
        raise ValueError(f"write: format must be 'g2o' or 'toro', got {format!r}")
    if graph.num_observations and (format, graph.dim) != ("g2o", 2):
        raise ValueError(
            f"write: landmark observations are written as g2o 2D LANDMARK2 records; this "
            f"graph is {graph.dim}D, asked for {format!r}"
        )
    for name, what in (("information", "edge"), ("observation_information", "observation")):
        info = onp.asarray(getattr(graph, name), dtype=onp.float64)
        if not onp.array_equal(info, onp.swapaxes(info, -1, -2)):
            row = int((info != onp.swapaxes(info, -1, -2)).any(axis=(1, 2)).argmax())
            raise ValueError(
                f"write: the information matrix of {what} {row} is not symmetric (the file "
                "stores the upper triangle)"
            )
    info = onp.asarray(graph.information, dtype=onp.float64)
    for name in ("poses", "measurements", "information", "observation_measurements"):
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
    seen = onp.asarray(graph.observation_information, dtype=onp.float64)[:, [0, 0, 1], [0, 1, 1]]
    landmark_ids = graph.landmark_ids.tolist()
    for (i, m), z, e in zip(
        graph.observations.tolist(), graph.observation_measurements.tolist(), seen.tolist()
    ):
        out.append(f"LANDMARK2 {ids[i]} {landmark_ids[m]} {' '.join(map(repr, z + e))}")
    with open(path, "w", encoding="utf-8") as file:
        file.write("\n".join(out) + "\n")
