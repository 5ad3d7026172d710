"""Type aliases (same names as jaxlie.hints)."""

from typing import NamedTuple, Union

import jax
import numpy as onp

Array = Union[onp.ndarray, jax.Array]
"""A JAX or NumPy array."""

Scalar = Union[float, Array]
"""A Python float or an array."""


class RollPitchYaw(NamedTuple):
    """Euler angles in radians, ZYX mobile-robot convention."""

    roll: Scalar
    pitch: Scalar
    yaw: Scalar


__all__ = ["Array", "Scalar", "RollPitchYaw"]
