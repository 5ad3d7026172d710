"""Batches of elements: stacking elements along a new batch axis, and evaluating an
elementwise function over a large batch in chunks, on CPU, to bound its temporaries
(``docs/design/memory-and-chunks.md``). A leaf module: elements are read through their
``parameters`` and ``get_batch_axes`` alone."""

from __future__ import annotations

from typing import Any, Callable, Sequence, Tuple, TypeVar, cast

import jax
import jax.numpy as jnp

from ._checks import as_float_array, static_size

GroupT = TypeVar("GroupT")

CHUNK = 2**16
"""Elements per chunk in ``in_chunks``."""
CHUNKED_FROM = 2**19
"""Smallest batch ``in_chunks`` splits; below it the batch is evaluated whole."""


def _batch_may_be_sharded() -> bool:
    """Whether a traced batch may be split over several CPU devices (jax's sharding: a
    mesh of ``--xla_force_host_platform_device_count`` devices or several hosts). The
    chunk loop slices the batch axis: with a batch sharded across devices, XLA gathers
    the whole batch on every device (Auto axes) or refuses to trace (Explicit axes), so
    chunks run only where one CPU device exists or inside ``shard_map``, which hands the
    function each device's own shard."""
    try:
        if jax.device_count("cpu") == 1:
            return False
    except RuntimeError:  # no CPU backend (JAX_PLATFORMS): the chunks are never lowered
        return False
    get_mesh = getattr(jax.sharding, "get_abstract_mesh", None)
    mesh = get_mesh() if get_mesh is not None else None
    manual = set(getattr(mesh, "manual_axes", ()))
    return mesh is None or mesh.empty or not set(mesh.axis_names) <= manual


def _zeros_like_leaves(
    leaves: Sequence[jax.Array], shape: Tuple[int, ...], dtype: Any
) -> jax.Array:
    """Zeros of ``shape`` and ``dtype`` that vary over every manual mesh axis some leaf
    varies over: inside ``shard_map`` a loop's carry keeps one type, and chunks computed
    from a device's own shard, written into a device-invariant zero buffer, failed to
    trace. ``lax.full_like`` takes the type of its example, here a scalar that depends on
    every leaf (and is then dead code: only its type is used)."""
    probe = sum(jnp.sum(x[:1]).astype(dtype) for x in leaves)
    return jax.lax.full_like(probe, 0, dtype, shape)


def in_chunks(f: Callable[..., Any], batch: Tuple[int, ...], *args: Any) -> Any:
    """``f(*args)``, evaluated ``CHUNK`` elements at a time into one output buffer on CPU
    when the batch has at least ``CHUNKED_FROM`` elements; otherwise, on other backends and
    for derivatives, evaluated whole.

    Every leaf of ``args`` (group elements, arrays) must have leading axes ``batch``, and
    ``f`` must act element by element along them and take every array it depends on as an
    argument (a closed-over tracer would lose its derivative in the custom JVP). Under
    ``vmap`` the decision sees the per-example batch. A whole-batch kernel keeps its
    intermediates as whole-batch arrays, out of cache; in chunks they stay a few MB. Which
    operations use it, and the measurements: ``docs/design/memory-and-chunks.md``.

    The last chunk is shifted back to end at the batch's end (it recomputes part of its
    predecessor rather than padding, which would copy every input). Derivatives (a custom
    JVP) differentiate the whole-batch ``f``, which is faster than through the loop. GPUs
    are left whole: a loop there syncs with the host every iteration. With several CPU
    devices the batch may
    be sharded, and it is evaluated whole (see ``_batch_may_be_sharded``) except inside
    ``shard_map``.
    """
    n = static_size(batch)
    leaves = jax.tree_util.tree_leaves(args)
    if any(tuple(x.shape[: len(batch)]) != tuple(batch) for x in leaves):
        shapes = [tuple(x.shape) for x in leaves]
        raise ValueError(f"in_chunks: every input needs leading axes {batch}, got {shapes}.")
    if n is None or not CHUNKED_FROM <= n < 2**31 or _batch_may_be_sharded():
        return f(*args)  # symbolic; int32 chunk offsets; split over devices
    flat = [x.reshape((n,) + x.shape[len(batch) :]) for x in leaves]
    treedef = jax.tree_util.tree_structure(args)

    @jax.jit  # traced once per shape: eval_shape and the loop body share the trace
    def whole(*leaves: jax.Array) -> Any:
        return f(*jax.tree_util.tree_unflatten(treedef, leaves))

    def piece(start: Any, leaves: Sequence[jax.Array]) -> Any:
        return whole(*(jax.lax.dynamic_slice_in_dim(x, start, CHUNK) for x in leaves))

    def chunked(*leaves: jax.Array) -> Any:
        shapes = jax.eval_shape(piece, 0, leaves)
        out = jax.tree_util.tree_map(
            lambda s: _zeros_like_leaves(leaves, (n,) + s.shape[1:], s.dtype), shapes
        )

        def body(i: Any, out: Any) -> Any:
            start = jnp.minimum(i * CHUNK, n - CHUNK)
            return jax.tree_util.tree_map(
                lambda o, p: jax.lax.dynamic_update_slice_in_dim(o, p, start, 0),
                out,
                piece(start, leaves),
            )

        return jax.lax.fori_loop(0, -(-n // CHUNK), body, out)

    @jax.custom_jvp
    def evaluate(*leaves: jax.Array) -> Any:
        return jax.lax.platform_dependent(*leaves, cpu=chunked, default=whole)

    @evaluate.defjvp
    def _(primals, tangents):  # type: ignore[no-untyped-def]
        return jax.jvp(whole, primals, tangents)

    out = evaluate(*flat)
    return jax.tree_util.tree_map(lambda o: o.reshape(batch + o.shape[1:]), out)


def pairwise_in_chunks(f: Callable[..., Any], a: Any, b: Any, t: Any, where: str) -> Any:
    """``f(a, b, t)`` for two elements and times (``interpolate``), evaluated by
    ``in_chunks`` where ``a`` and ``b`` are of one group and one batch shape that ``t``
    broadcasts into (``t`` then a float array of the elements' dtype, broadcast to the
    batch), and whole otherwise (``t`` as an array)."""
    t = jnp.asarray(t)  # lists and tuples too, as in geodesic
    batch = a.get_batch_axes()
    same = type(b) is type(a) and b.get_batch_axes() == batch
    t_shape = jnp.shape(t)
    t_fits = len(t_shape) <= len(batch) and all(
        m in (1, n) for m, n in zip(t_shape[::-1], batch[::-1])
    )
    if not (same and t_fits):
        return f(a, b, t)
    like = jnp.zeros((), jnp.result_type(a.parameters(), b.parameters()))
    t = as_float_array(t, "t", (), where, like=like)
    return in_chunks(f, batch, a, b, jnp.broadcast_to(t, batch))


def stack(elements: Sequence[GroupT], axis: int = 0) -> GroupT:
    """Stack elements of one group along a new batch axis.

    Args:
        elements: elements of one group, all of the same batch shape ``B``.
        axis: position of the new axis, counted among the batch axes (the parameter axis
            stays last); negative values count from the end of ``(*B, new)``.

    Returns:
        An element of batch shape ``B`` with ``len(elements)`` inserted at ``axis``.

    Raises:
        ValueError: no elements, or ``axis`` out of range.
        TypeError: elements of different groups.
    """
    elements = list(elements)
    if not elements:
        raise ValueError("stack: need at least one element.")
    first: Any = elements[0]
    G = type(first)
    if any(type(e) is not G for e in elements):
        raise TypeError("stack: all elements must be of the same group.")
    ndim = len(first.get_batch_axes()) + 1
    if not -ndim <= axis < ndim:
        raise ValueError(f"stack: axis {axis} out of range for {ndim} batch axes.")
    params = [cast(Any, e).parameters() for e in elements]
    return cast(GroupT, G(jnp.stack(params, axis=axis % ndim)))
