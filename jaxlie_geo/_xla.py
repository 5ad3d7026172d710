"""How the kernels are laid out for XLA: barriers, rank alignment, constants, matrices
assembled from entries and blocks, matrix products, and the version gates they depend on.

Nothing here changes a value: each helper decides only how XLA schedules or broadcasts a
computation. Why each exists, with the measurements, is in the design notes
(``docs/design/memory-and-chunks.md``, ``docs/design/precision.md``).

A leaf module: it knows a group element by its interface (``_checks.is_element``).
"""

from __future__ import annotations

import dataclasses
import importlib
import re
from typing import Any, List, Optional, Sequence, Tuple

import jax
import jax.numpy as jnp

from ._checks import is_element


def parse_version(text: str) -> Tuple[int, ...]:
    """The leading numeric components of a version string, then −1 for a pre-release
    (a, b, rc, dev), which precedes the release: "0.12.0.1" → (0, 12, 0, 1), "0.6.0rc1" →
    (0, 6, 0, -1), "0.7.0.dev20250601" → (0, 7, 0, -1), "0.5.3+cuda12" → (0, 5, 3)."""
    out = []
    for part in text.split("."):
        digits = re.match(r"\d*", part).group()  # type: ignore[union-attr]  # \d* always matches
        if digits:
            out.append(int(digits))
        if digits != part:
            suffix = part[len(digits) :]
            if re.match(r"[-_]?(a|b|c|rc|alpha|beta|pre|preview|dev)\d*$", suffix, re.I):
                out.append(-1)
            break
    return tuple(out)


def at_least(text: str, minimum: Tuple[int, ...]) -> bool:
    """Whether version ``text`` is ``minimum`` or later (missing components count as 0)."""
    have = parse_version(text)
    width = max(len(have), len(minimum))
    return have + (0,) * (width - len(have)) >= minimum + (0,) * (width - len(minimum))


# jax 0.5.3 is the first release with JVP and transpose rules for optimization_barrier
# (0.4.38 the first with its batching rule); older ones fail on the first grad or vmap.
if not at_least(jax.__version__, (0, 5, 3)):
    raise ImportError(
        f"jaxlie_geo needs jax >= 0.5.3 (the first release that differentiates "
        f"lax.optimization_barrier); found jax {jax.__version__}."
    )


def x64(enabled: bool) -> Any:
    """A context manager with float64 on or off, on every supported jax:
    ``jax.enable_x64(enabled)`` where jax has it, ``jax.experimental.enable_x64()`` or
    ``disable_x64()`` before."""
    if hasattr(jax, "enable_x64"):
        return jax.enable_x64(enabled)
    experimental: Any = importlib.import_module("jax.experimental")
    return experimental.enable_x64() if enabled else experimental.disable_x64()


TANGENTS_PASS_THROUGH = at_least(jax.__version__, (0, 11))
"""Whether ``materialize`` leaves tangents unbarriered: jax ≥ 0.11 puts them behind a
second barrier of its own, which jax 0.11.2 fails to transpose inside a ``custom_jvp``
rule; on older jax the barrier on the tangents is what keeps XLA from recomputing them."""


@jax.custom_jvp
def _barrier(xs: Any) -> Any:
    """``optimization_barrier`` on the primal values only (see ``materialize``)."""
    return jax.lax.optimization_barrier(xs)


@_barrier.defjvp
def _barrier_jvp(primals: Any, tangents: Any) -> Any:
    return _barrier(primals[0]), tangents[0]


def materialize(*xs: Any) -> Any:
    """The inputs, each computed once into memory before a kernel that reads its
    components several times (a Hamilton product reads each of 8 components 4 times).

    Without it XLA:CPU fuses an expensive producer (exp's sincos, log's arctangent) into
    every consumer and recomputes it per read. On a whole input already in memory the
    barrier is free; on a *slice* of one, jax ≥ 0.11 copies the slice, so the SE groups
    materialize whole elements and call their rotation's barrier-free kernels. Transparent
    to ``jit``, ``vmap`` and autodiff. Returns one value for one input, else a tuple.
    Measurements: ``docs/design/memory-and-chunks.md``.
    """
    out = _barrier(xs) if TANGENTS_PASS_THROUGH else jax.lax.optimization_barrier(xs)
    return out[0] if len(xs) == 1 else out


@dataclasses.dataclass(frozen=True)
class Schedule:
    """How XLA schedules a group's kernels, never their values: which inputs are computed
    into memory before a kernel reads them, and whether large ``interpolate`` batches run
    in chunks (``docs/design/memory-and-chunks.md`` has the measurements). Each group
    class sets its own (``MatrixLieGroup._schedule``)."""

    reread: bool = False
    """Whether the group's kernels read each input component several times (the quaternion
    groups: a Hamilton product reads each of 8 components 4 times), so that ``multiply``,
    ``apply``, ``inverse`` and ``interpolate`` compute their inputs into memory first
    (``inputs``). Without the barrier XLA:CPU fuses a producer into every read of it: an
    exp's sincos is recomputed per read, and a chain of K compositions grows as 4^K."""
    interpolate_in_memory: bool = False
    """Whether ``interpolate`` also computes its relative element, log and exp into memory
    before the next kernel reads them (``along``)."""
    interpolate_in_chunks: bool = False
    """Whether large ``interpolate`` batches run in chunks on CPU (``_batch.in_chunks``)."""

    def inputs(self, *xs: Any) -> Any:
        """The inputs computed once into memory (``materialize``) where ``reread``, else as
        they are; one value for one input, else a tuple."""
        if self.reread:
            return materialize(*xs)
        return xs[0] if len(xs) == 1 else xs

    def along(self, x: Any) -> Any:
        """``x`` computed into memory inside ``interpolate`` and geodesics where
        ``interpolate_in_memory``, else as it is."""
        return materialize(x) if self.interpolate_in_memory else x


def materialize_columns(*xs: jax.Array) -> List[jax.Array]:
    """The ``(*batch,)`` arrays ``xs``, computed once into one ``(*batch, len(xs))`` array
    before the kernel that reads them, and returned as its columns.

    For the per-element coefficients of a matrix written entry by entry (a Jacobian's F1,
    F2, ...): XLA:CPU fuses them into the loop that writes the stacked matrix, which
    evaluates every entry on its own and so recomputes each coefficient once per entry
    that reads it. Behind ``materialize`` as separate arrays they stay fused; stacked
    into one array they are computed once (``docs/design/memory-and-chunks.md``)."""
    stacked = materialize(jnp.stack(xs, axis=-1))
    return list(jnp.unstack(stacked, axis=-1))


Entries = List[List[jax.Array]]
"""A small matrix as its rows of entries, each ``(*batch,)``."""


def from_entries(rows: Sequence[Sequence[jax.Array]]) -> jax.Array:
    """The ``(*batch, m, n)`` matrix of ``m`` rows of ``n`` entries of shape ``(*batch,)``."""
    return jnp.stack([jnp.stack(list(row), axis=-1) for row in rows], axis=-2)


def from_block_entries(blocks: Sequence[Sequence[Optional[Entries]]]) -> jax.Array:
    """The matrix of 3 × 3 blocks given by their entries, ``None`` for a zero block:
    ``(*batch, 3 r, 3 c)`` for ``r`` rows of ``c`` blocks."""
    some = next(b for row in blocks for b in row if b is not None)
    zero = jnp.zeros_like(some[0][0])
    rows = []
    for block_row in blocks:
        for i in range(3):
            rows.append([e for b in block_row for e in (b[i] if b is not None else [zero] * 3)])
    return from_entries(rows)


def entries_product(a: Entries, b: Entries) -> Entries:
    """The entries of A B for 3 × 3 matrices given by their entries (multiply-adds in
    the order of the sum over k)."""
    return [
        [a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] for j in range(3)]
        for i in range(3)
    ]


def constant(values: Any, like: jax.Array) -> jax.Array:
    """``values`` (a constant vector or matrix) in ``like``'s dtype, with leading unit axes
    up to ``like``'s rank, so that combining it with batched arrays needs no implicit rank
    promotion (users may set ``jax_numpy_rank_promotion="raise"``). The same HLO as the
    implicit broadcast."""
    c = jnp.asarray(values, like.dtype)
    return c.reshape((1,) * (like.ndim - c.ndim) + c.shape)


def aligned(*xs: Any) -> Tuple[Any, ...]:
    """Group elements and ``(*batch, k)`` arrays with leading unit axes added so that all
    have the same number of batch axes (a reshape: nothing is copied).

    The binary operations broadcast their batch axes numpy-style; with the ranks made equal
    no implicit rank promotion is left. Unlike ``utils.broadcast_leading_axes`` it does not
    broadcast to the full batch, so ``materialize`` never writes a whole-batch copy of a
    single element composed with a batch."""
    params = [x.parameters() if is_element(x) else x for x in xs]
    ndim = max(jnp.ndim(p) for p in params)
    out = []
    for x, p in zip(xs, params):
        if jnp.ndim(p) < ndim:
            p = jnp.reshape(p, (1,) * (ndim - jnp.ndim(p)) + jnp.shape(p))
            x = type(x)(p) if is_element(x) else p
        out.append(x)
    return tuple(out)


def matmul(A: jax.Array, B: jax.Array) -> jax.Array:
    """``A @ B`` at full precision (``Precision.HIGHEST``). At JAX's default precision a
    float32 product on a GPU runs in TF32 (about 1e-3 relative error on an H100); on CPU
    the setting changes nothing. See ``docs/design/precision.md``."""
    return jnp.matmul(A, B, precision=jax.lax.Precision.HIGHEST)


def matmul_unrolled(A: jax.Array, B: jax.Array) -> jax.Array:
    """``(..., m, n) @ (..., n, k)`` for small m, n, k, written out as multiply-adds (exact
    in any precision mode; a batched 3×3 ``dot`` on XLA:CPU costs several times the fused
    multiply-adds)."""
    a = [jnp.unstack(r, axis=-1) for r in jnp.unstack(A, axis=-2)]  # see _scalar.components
    b = [jnp.unstack(r, axis=-1) for r in jnp.unstack(B, axis=-2)]
    rows = []
    for i in range(len(a)):
        row = []
        for j in range(len(b[0])):
            acc = a[i][0] * b[0][j]
            for m in range(1, len(b)):
                acc = acc + a[i][m] * b[m][j]
            row.append(acc)
        rows.append(jnp.stack(row, axis=-1))
    return jnp.stack(rows, axis=-2)


def block_matrix(rows: Sequence[Sequence[Optional[jax.Array]]]) -> jax.Array:
    """A matrix from blocks, ``(*batch, n_i, m_j)`` each, ``None`` for a zero block (its
    size read from the other blocks of its row and column); batch axes broadcast."""
    heights = [next(b.shape[-2] for b in row if b is not None) for row in rows]
    widths = [next(b.shape[-1] for b in col if b is not None) for col in zip(*rows)]
    present = [b for row in rows for b in row if b is not None]
    batch = jnp.broadcast_shapes(*(b.shape[:-2] for b in present))
    dtype = jnp.result_type(*present)

    def fill(b: Optional[jax.Array], h: int, w: int) -> jax.Array:
        if b is None:
            return jnp.zeros((*batch, h, w), dtype)
        return jnp.broadcast_to(b.astype(dtype), (*batch, h, w))

    return jnp.concatenate(
        [
            jnp.concatenate([fill(b, h, w) for b, w in zip(row, widths)], axis=-1)
            for row, h in zip(rows, heights)
        ],
        axis=-2,
    )
