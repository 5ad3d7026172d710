"""Helpers with jaxlie.utils' names: precision constants, group registration, broadcasting."""

from __future__ import annotations

from typing import Callable, Tuple, Type, TypeVar, Union, cast

import jax.numpy as jnp

from ._base import GroupT, MatrixLieGroup
from ._checks import check_batches
from .hints import Array


def get_epsilon(dtype: jnp.dtype) -> float:
    """Small-angle tolerance jaxlie uses per dtype (1e-5 for float32, 1e-10 for float64).

    Kept for compatibility; jaxlie_geo's own kernels do not use it (their switches are
    per-kernel and documented in ``_scalar``)."""
    dtype = jnp.dtype(dtype)
    table = {jnp.dtype("float32"): 1e-5, jnp.dtype("float64"): 1e-10}
    if dtype not in table:
        raise ValueError(f"get_epsilon: unsupported dtype {dtype}; use float32 or float64.")
    return table[dtype]


def register_lie_group(
    *, matrix_dim: int, parameters_dim: int, tangent_dim: int, space_dim: int
) -> Callable[[Type[GroupT]], Type[GroupT]]:
    """Class decorator setting the four dimension attributes of a group class."""

    def wrap(cls: Type[GroupT]) -> Type[GroupT]:
        cls.matrix_dim = matrix_dim
        cls.parameters_dim = parameters_dim
        cls.tangent_dim = tangent_dim
        cls.space_dim = space_dim
        return cls

    return wrap


TupleOfBroadcastable = TypeVar(
    "TupleOfBroadcastable", bound="Tuple[Union[MatrixLieGroup, Array], ...]"
)


def broadcast_leading_axes(inputs: TupleOfBroadcastable) -> TupleOfBroadcastable:
    """Broadcast the leading (batch) axes of group elements and arrays to a common shape.

    Arrays are taken as ``(*batch, d)`` (last axis kept); group elements as their
    parameters. Returns a tuple of the same kinds in the same order.
    """
    arrays = [x.parameters() if isinstance(x, MatrixLieGroup) else jnp.asarray(x) for x in inputs]
    for i, a in enumerate(arrays):
        if a.ndim < 1:
            raise ValueError(
                f"broadcast_leading_axes: input {i} must have shape (*batch, d), got {a.shape}."
            )
    batch = check_batches("broadcast_leading_axes", "batch axes", *(a.shape[:-1] for a in arrays))
    out = tuple(
        type(x)(jnp.broadcast_to(a, (*batch, a.shape[-1])))
        if isinstance(x, MatrixLieGroup)
        else jnp.broadcast_to(a, (*batch, a.shape[-1]))
        for x, a in zip(inputs, arrays)
    )
    return cast(TupleOfBroadcastable, out)


__all__ = ["get_epsilon", "register_lie_group", "broadcast_leading_axes"]
