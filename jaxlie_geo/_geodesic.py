"""Geodesic paths between group elements (Eberly, *Lie Groups and Lie Algebras*, 2024, §4,
and the two ``GeodesicPath`` variants of §6), and the relative element
``between(a, b) = a⁻¹ @ b`` they start from."""

from __future__ import annotations

from typing import Generic

import jax

from . import hints
from ._base import GroupT, MatrixLieGroup
from ._pytree import pytree_dataclass


@pytree_dataclass
class Geodesic(Generic[GroupT]):
    """The geodesic ``t ↦ start @ exp(t · tangent)``, a pytree (jit/vmap friendly).

    Built by ``geodesic(a, b)``, which computes ``tangent = log(a⁻¹ b)`` once (Eberly's
    ``LogM1M0Inv`` + ``GeodesicPath(t, M0, log)`` variant, in the body form); calling it
    costs one exp and one compose per time.
    """

    start: GroupT
    """Element at t = 0, batch ``B``."""
    tangent: jax.Array
    """Body velocity ``log(start⁻¹ end)``, shape ``(*B', tangent_dim)``."""

    def __call__(self, t: hints.Scalar) -> GroupT:
        """Element at time(s) ``t``; ``t`` broadcasts numpy-style against the batch axes
        (shape ``broadcast(B, t.shape)``)."""
        return self.start._along(self.tangent, t)


def geodesic(start: GroupT, end: GroupT) -> Geodesic[GroupT]:
    """Geodesic path from ``start`` (t = 0) to ``end`` (t = 1): ``start @ exp(t log(start⁻¹ end))``.

    Uses the principal log (relative rotation angle ≤ π); at exactly π the log's
    tie-break decides the direction (see ``SO3.log``). Batch axes of the endpoints
    broadcast, to ``B``; the returned ``Geodesic`` maps times ``t`` to elements of batch
    ``broadcast(B, t.shape)``.
    """
    if type(start) is not type(end):
        raise TypeError(
            f"geodesic: endpoints must be the same group, got {type(start).__name__} "
            f"and {type(end).__name__}."
        )
    return Geodesic(start, start._between(end).log())


def between(a: GroupT, b: GroupT) -> GroupT:
    """The relative element ``a⁻¹ @ b`` (a pose-graph measurement's prediction; the step of
    ``geodesic(a, b)``), batch axes broadcast.

    For SE(2)/SE(3) it is formed as (R_a⁻¹ R_b, R_a⁻¹(t_b − t_a)): the difference of nearby
    translations is exact, where ``a.inverse() @ b`` cancels ε·|t_a| (poses 10⁴ from the
    origin and ~1 apart: 10⁴ ulp of the log, against ~1 here). ``manifold.rminus(a, b)`` is
    its log."""
    if not isinstance(a, MatrixLieGroup):
        raise TypeError(f"between: expected a group element, got {type(a).__name__}.")
    return a._between(b)
