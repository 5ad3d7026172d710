"""Input validation at trace time, shared by every factory and operation.

Every check runs while JAX traces (shapes and dtypes are static), so a wrong input raises a
``ValueError``, ``TypeError`` or ``IndexError`` that names the operation, the argument, the
expected shape and the received one, before XLA sees anything.

A leaf module: it knows a group element by its interface (a ``parameters()`` method and a
``parameters_dim`` class attribute), not by importing the base class.
"""

from __future__ import annotations

import math
from typing import Any, Optional, Sequence, Tuple

import jax
import jax.numpy as jnp
import numpy as onp


def is_element(x: Any) -> bool:
    """Whether ``x`` is a group element: an instance of a class with ``parameters_dim`` and a
    ``parameters()`` method (jaxlie_geo's groups; jaxlie's elements have the same
    interface, so mixing the two libraries in one call is reported, not misread)."""
    return isinstance(getattr(type(x), "parameters_dim", None), int) and callable(
        getattr(x, "parameters", None)
    )


def default_float() -> jnp.dtype:
    """The default float dtype: float64 when ``jax_enable_x64`` is on, else float32."""
    return jnp.zeros(()).dtype


def as_float_array(
    x: Any, name: str, trailing: Tuple[int, ...], where: str, like: Any = None
) -> jax.Array:
    """Convert ``x`` to a floating JAX array and check its trailing shape.

    Integer and boolean inputs are promoted to ``like``'s dtype when given (the element
    they are combined with: int ⊕ float32 → float32, as JAX promotes), else to the default
    float dtype; floating inputs keep their dtype.

    Args:
        x: array-like input.
        name: the argument's name, for the message.
        trailing: the required trailing shape, e.g. ``(3,)`` for points; ``()`` for scalars.
        where: the operation, e.g. ``"SO3.exp"``.
        like: an array whose dtype integer inputs take.

    Returns:
        ``x`` as a floating array of shape ``(*batch, *trailing)``.

    Raises:
        ValueError: complex input, or a trailing shape other than ``trailing``.
    """
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        if jnp.issubdtype(x.dtype, jnp.complexfloating):
            raise ValueError(f"{where}: `{name}` must be real, got dtype {x.dtype}.")
        x = x.astype(default_float() if like is None else jnp.asarray(like).dtype)
    k = len(trailing)
    if x.ndim < k or tuple(x.shape[x.ndim - k :]) != tuple(trailing):
        expected = "(*batch, " + ", ".join(map(str, trailing)) + ")" if k else "(*batch,)"
        raise ValueError(
            f"{where}: `{name}` must have shape {expected}, got shape {tuple(x.shape)}."
        )
    return x


def resolve_dtype(dtype: Any) -> jnp.dtype:
    """``None`` → the default float dtype; anything else must be a floating dtype
    (``ValueError`` otherwise), canonicalised as JAX does (float64 → float32 without x64)."""
    if dtype is None:
        return default_float()
    dtype = jnp.dtype(dtype)
    if not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(f"dtype must be a floating dtype, got {dtype}.")
    return jax.dtypes.canonicalize_dtype(dtype)


def static_size(shape: Sequence[Any]) -> Optional[int]:
    """The number of elements of ``shape``, or None when a dimension is symbolic
    (``jax.export`` shape polymorphism), where size-dependent choices take their default."""
    if all(isinstance(d, (int, onp.integer)) for d in shape):
        return math.prod(shape)
    return None


def check_batches(where: str, what: str, *batches: Tuple[int, ...]) -> Tuple[int, ...]:
    """The broadcast of ``batches`` (numpy rules); ``ValueError`` naming ``where``, ``what``
    and the shapes when they do not broadcast."""
    try:  # jnp's, not numpy's: it takes jax.export's symbolic dimensions
        return tuple(jnp.broadcast_shapes(*batches))
    except ValueError:
        shown = " and ".join(str(b) for b in batches)
        raise ValueError(
            f"{where}: {what} {shown} do not broadcast together (numpy rules)."
        ) from None


def check_elements(where: str, *args: Any) -> None:
    """Check the group elements among ``args``: real parameters of shape
    ``(*batch, parameters_dim)``, and batch axes that broadcast together (numpy rules).

    Raises:
        ValueError: naming ``where``, the group and the shapes.
    """
    batches = []
    for a in args:
        if not is_element(a):
            continue
        shape = getattr(a.parameters(), "shape", None)
        if shape is None:  # pytree rebuilt with placeholders (None, object()) by JAX
            continue
        dtype = getattr(a.parameters(), "dtype", None)
        if dtype is not None and jnp.issubdtype(dtype, jnp.complexfloating):
            raise ValueError(
                f"{where}: {type(a).__name__} parameters must be real, got dtype {dtype}."
            )
        if tuple(shape[-1:]) != (a.parameters_dim,):
            raise ValueError(
                f"{where}: {type(a).__name__} parameters must have shape "
                f"(*batch, {a.parameters_dim}), got shape {tuple(shape)}."
            )
        batches.append(tuple(shape[:-1]))
    check_batches(where, "batch axes", *batches)


def _type_names(want: type, got: type) -> Tuple[str, str]:
    """The two classes' names, module-qualified where the short names agree (jaxlie's
    ``SO3`` passed where jaxlie_geo's is expected)."""
    if want.__name__ != got.__name__:
        return want.__name__, got.__name__
    return f"{want.__module__}.{want.__qualname__}", f"{got.__module__}.{got.__qualname__}"


def check_same_group(where: str, first: Any, *rest: Any) -> None:
    """``TypeError`` naming ``where`` when an element among ``rest`` is not of ``first``'s
    group."""
    for a in rest:
        if is_element(a) and type(a) is not type(first):
            want, got = _type_names(type(first), type(a))
            raise TypeError(f"{where}: expected {want}, got {got}.")


def check_type(where: str, name: str, value: Any, expected: type) -> None:
    """``TypeError`` naming ``where`` and the argument ``name`` when ``value`` is not an
    instance of ``expected``; an array is told to be wrapped in ``expected``."""
    if isinstance(value, expected):
        return
    want, got = _type_names(expected, type(value))
    if want == expected.__name__ and hasattr(value, "shape") and hasattr(value, "dtype"):
        got = f"an array of shape {tuple(value.shape)} (wrap it: {expected.__name__}(...))"
    raise TypeError(f"{where}: `{name}` must be {want}, got {got}.")


def check_index(name: str, batch: Tuple[Any, ...], index: Tuple[Any, ...]) -> None:
    """``IndexError`` for a static index out of range of the batch axes ``batch``.

    Static entries are Python or NumPy integers and lists or NumPy arrays of them (also
    after ``...``); they are checked from the left as NumPy would (JAX clamps instead, and
    Python's iteration fallback relies on the error). A JAX array or a traced entry ends
    the check: those clamp, as in JAX. Symbolic sizes are not checked.
    """

    def static(i: Any) -> Optional[onp.ndarray]:  # integers or a mask, known now
        if isinstance(i, (bool, onp.bool_)) or not isinstance(
            i, (int, list, onp.ndarray, onp.integer)
        ):
            return None
        a = onp.asarray(i)
        return a if a.dtype.kind in "iu" or (a.dtype.kind == "b" and a.ndim > 0) else None

    def width(i: Any) -> int:  # batch axes an entry consumes
        if i is None or i is Ellipsis or isinstance(i, (bool, onp.bool_)):
            return 0  # a scalar bool adds an axis, as None does
        a = static(i) if not isinstance(i, jax.Array) else i
        return a.ndim if a is not None and a.dtype == bool else 1

    checked = list(index)
    at = [k for k, i in enumerate(checked) if i is Ellipsis]  # `is`: ndarray == ... is elementwise
    if len(at) == 1:
        rest = len(batch) - sum(width(i) for i in checked)
        checked[at[0] : at[0] + 1] = [slice(None)] * max(rest, 0)
    axis = 0
    for i in checked:
        if width(i) == 0 and not isinstance(i, slice):
            continue
        a = None if isinstance(i, slice) else static(i)
        if not isinstance(i, slice) and a is None:
            break
        n = batch[axis] if axis < len(batch) else 0
        if a is not None and a.dtype != bool and isinstance(n, (int, onp.integer)):
            if not onp.all((-n <= a) & (a < n)):
                raise IndexError(
                    f"{name}: index {i} is out of range for batch axes {batch} (axis {axis})."
                )
        axis += width(i)
