"""Type aliases: jaxlie.hints' names, and one ``Literal`` per set of string options the
package's functions take."""

from typing import Literal, NamedTuple, Union

import jax
import numpy as onp

Array = Union[onp.ndarray, jax.Array]
"""A JAX or NumPy array."""

Scalar = Union[float, Array]
"""A Python float or an array."""


SolverMethod = Literal["lm", "gn"]
"""A least-squares solver's iteration: Levenberg–Marquardt or Gauss–Newton."""

LinearSolver = Literal["auto", "cholesky", "cholmod", "qdldl", "banded", "dense", "pcg", "schur"]
"""How a least-squares step's normal equations are solved (``pose_graph.solve``)."""

Frame = Literal["body", "world"]
"""The frame a spline's velocity, acceleration or jerk is expressed in."""

PoseGraphFormat = Literal["g2o", "toro"]
"""A pose-graph file format, and the order of the information matrix it stores."""


class RollPitchYaw(NamedTuple):
    """Euler angles in radians, ZYX mobile-robot convention."""

    roll: Scalar
    pitch: Scalar
    yaw: Scalar


__all__ = [
    "Array",
    "Scalar",
    "RollPitchYaw",
    "SolverMethod",
    "LinearSolver",
    "Frame",
    "PoseGraphFormat",
]
