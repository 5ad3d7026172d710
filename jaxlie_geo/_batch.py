"""Stacking group elements along a new batch axis."""

from __future__ import annotations

from typing import Sequence, TypeVar

import jax.numpy as jnp

from ._base import MatrixLieGroup

GroupT = TypeVar("GroupT", bound=MatrixLieGroup)


def stack(elements: Sequence[GroupT], axis: int = 0) -> GroupT:
    """Stack elements of one group (equal batch shapes) along a new batch axis ``axis``
    (counted among the batch axes, so the parameter axis stays last)."""
    elements = list(elements)
    if not elements:
        raise ValueError("stack: need at least one element.")
    G = type(elements[0])
    if any(type(e) is not G for e in elements):
        raise TypeError("stack: all elements must be of the same group.")
    ndim = len(elements[0].get_batch_axes()) + 1
    if not -ndim <= axis < ndim:
        raise ValueError(f"stack: axis {axis} out of range for {ndim} batch axes.")
    axis = axis % ndim
    return G(jnp.stack([e.parameters() for e in elements], axis=axis))
