"""Run-time validity checks inside ``jit``, through ``jax.experimental.checkify``.

``MatrixLieGroup.is_valid`` gives a boolean per element; ``check_valid`` turns it into a
checkify error, so that a jitted program reports a non-unit or non-finite element where it
enters, instead of carrying wrong rotations or NaN to its outputs.
"""

from __future__ import annotations

from typing import Optional

import jax.numpy as jnp
from jax.experimental import checkify

from . import hints
from ._base import MatrixLieGroup, valid_atol
from ._checks import check_type, default_float

_ROTATION_NAMES = {2: "unit complex number", 4: "unit quaternion"}


def check_valid(x: MatrixLieGroup, atol: Optional[hints.Scalar] = None) -> None:
    """Check ``x.is_valid(atol)`` with ``checkify.check``: a failure names the group, how
    many elements are invalid, the first one's batch index and its parameters.

    Under ``jit``, ``vmap`` or ``grad``, wrap the outermost function in
    ``jax.experimental.checkify.checkify``, which returns ``(error, out)``;
    ``error.throw()`` raises ``JaxRuntimeError`` when an element is invalid, and
    ``error.get()`` gives the message (``None`` when all are valid). Without
    ``checkify``, an eager call raises at once for an invalid element, and ``jit`` refuses
    to trace the check (checkify's rule for every ``checkify.check``).

    Args:
        x: an element of any group, of any batch shape.
        atol: as in ``is_valid``: the tolerance on | ‖rotation part‖ − 1 |; default √ε of
            the parameters' dtype.

    Returns:
        None; the check is recorded in checkify's error value.

    Raises:
        TypeError: ``x`` is not a group element (at trace time).
    """
    check_type("check_valid", "x", x, MatrixLieGroup)
    valid = x.is_valid(atol)
    flat = valid.reshape(-1)
    if flat.size == 0:  # an empty batch: nothing to check
        return
    first = jnp.argmin(flat)  # the first False; 0 when all are valid
    index = jnp.unravel_index(first, valid.shape)
    params = x.parameters()
    params = jnp.broadcast_to(params, (*valid.shape, params.shape[-1]))
    params = params.reshape(-1, params.shape[-1])
    rotation = _ROTATION_NAMES.get(x._unit_part().shape[-1], "unit rotation part")
    floating = jnp.issubdtype(params.dtype, jnp.floating)  # integers: the default float
    tol = jnp.asarray(
        valid_atol(params.dtype if floating else default_float()) if atol is None else atol
    )
    at = f", at batch index [{', '.join('{}' for _ in index)}]," if index else ""
    checkify.check(
        jnp.all(valid),
        f"check_valid: {{}} of {flat.size} {type(x).__name__} elements are invalid (a valid "
        f"element has finite parameters and a {rotation} of norm within atol={{}} of 1); "
        f"the first invalid one{at} has parameters {{}}.",
        jnp.sum(~flat),
        tol,
        *index,
        params[first],
    )


__all__ = ["check_valid"]
