"""Optimisation on the manifold (jaxlie.manifold's API): right ⊕/⊖ on pytrees, tangent-space
gradients, and the Jacobian of ⊕ with respect to the parameters.

In every function, a pytree may mix group elements (handled on their tangent spaces) and
plain arrays (handled with ordinary + and −).
"""

from __future__ import annotations

from typing import Any, Callable, Sequence, TypeVar, Union

import jax
import jax.numpy as jnp

from ._base import MatrixLieGroup
from ._checks import check_elements

TangentPytree = Any
"""The pytree of tangents of a pytree of elements (arrays in place of groups)."""

_PytreeT = TypeVar("_PytreeT")  # rplus and normalize_all return their argument's type


def _is_group(x: Any) -> bool:
    return isinstance(x, MatrixLieGroup)


def _map(f_group: Callable[..., Any], f_array: Callable[..., Any], tree: Any, *rest: Any) -> Any:
    return jax.tree.map(
        lambda x, *r: f_group(x, *r) if _is_group(x) else f_array(x, *r),
        tree,
        *rest,
        is_leaf=_is_group,
    )


def rplus(transform: _PytreeT, delta: TangentPytree) -> _PytreeT:
    """Right plus, ``T ⊕ δ = T @ exp(δ)`` for each group leaf, ``x + δ`` for arrays.

    Args:
        transform: a group element, or a pytree of elements and arrays.
        delta: ``transform``'s tree structure, with a ``(*batch, tangent_dim)`` array in
            place of each element (batch axes broadcast); integer increments take the
            element's dtype.

    Returns:
        A pytree of ``transform``'s structure.
    """

    def plus(T: Any, d: Any) -> Any:
        d = T._check_tangent(d, "manifold.rplus", like=T.parameters(), name="delta")
        return T.multiply(type(T).exp(d))

    return _map(plus, jnp.add, transform, delta)


def rminus(a: Any, b: Any) -> TangentPytree:
    """Right minus, ``b ⊖ a = log(a⁻¹ @ b)`` for each group leaf, ``a − b`` for arrays
    (jaxlie 1.5's convention, kept for drop-in use).

    Args:
        a: a group element, or a pytree of elements and arrays.
        b: a pytree of the same structure and groups.

    Returns:
        A pytree δ of ``a``'s structure with a ``(*batch, tangent_dim)`` array per element,
        the principal log on group leaves, so that ``rplus(a, δ) = b`` there. On array
        leaves δ = a − b, as in jaxlie, so ``rplus(a, δ)`` gives ``2a − b`` for them: negate
        the array leaves of δ where ``rplus`` must invert ``rminus`` on a mixed pytree.
    """
    return _map(lambda A, B: A._between(B).log(), lambda x, y: x - y, a, b)


def zero_tangents(pytree: Any) -> TangentPytree:
    """Zero tangents shaped like each leaf's tangent space (arrays: ``zeros_like``)."""
    return _map(
        lambda T: jnp.zeros((*T.get_batch_axes(), T.tangent_dim), T.parameters().dtype),
        jnp.zeros_like,
        pytree,
    )


def normalize_all(pytree: _PytreeT) -> _PytreeT:
    """``normalize()`` every group element of a pytree (same structure, batch axes and
    dtypes); arrays pass through."""
    return _map(lambda T: T.normalize(), lambda x: x, pytree)


def value_and_grad(
    fun: Callable[..., Any],
    argnums: Union[int, Sequence[int]] = 0,
    has_aux: bool = False,
    holomorphic: bool = False,
    allow_int: bool = False,
    reduce_axes: Sequence[Any] = (),
) -> Callable[..., Any]:
    """Like ``jax.value_and_grad`` (same parameters, in jaxlie's positional order), but
    gradients of group arguments are taken with respect to a right perturbation δ in the
    tangent space, ``d f(T ⊕ δ)/dδ`` at δ = 0: an element of batch ``batch`` gets a
    ``(*batch, tangent_dim)`` array in the gradient pytree."""

    def wrapped(*args: Any, **fkwargs: Any) -> Any:
        def tangent_fun(*deltas: Any, **kdeltas: Any) -> Any:
            return fun(*rplus(args, deltas), **{k: rplus(fkwargs[k], kdeltas[k]) for k in fkwargs})

        zeros = tuple(zero_tangents(a) for a in args)
        kzeros = {k: zero_tangents(v) for k, v in fkwargs.items()}
        return jax.value_and_grad(
            tangent_fun,
            argnums=argnums,
            has_aux=has_aux,
            holomorphic=holomorphic,
            allow_int=allow_int,
            reduce_axes=reduce_axes,
        )(*zeros, **kzeros)

    return wrapped


def grad(
    fun: Callable[..., Any],
    argnums: Union[int, Sequence[int]] = 0,
    has_aux: bool = False,
    holomorphic: bool = False,
    allow_int: bool = False,
    reduce_axes: Sequence[Any] = (),
) -> Callable[..., Any]:
    """Like ``jax.grad``, with tangent-space gradients for group arguments: a
    ``(*batch, tangent_dim)`` array per element (see ``value_and_grad``)."""
    vg = value_and_grad(fun, argnums, has_aux, holomorphic, allow_int, reduce_axes)

    def wrapped(*args: Any, **fkwargs: Any) -> Any:
        out = vg(*args, **fkwargs)
        return (out[1], out[0][1]) if has_aux else out[1]

    return wrapped


def rplus_jacobian_parameters_wrt_delta(transform: MatrixLieGroup) -> jax.Array:
    """Closed-form ``d parameters(T ⊕ δ) / dδ`` at δ = 0, shape
    ``(*batch, parameters_dim, tangent_dim)`` (cheaper to compile than autodiff)."""
    if not _is_group(transform):
        raise TypeError(
            f"rplus_jacobian_parameters_wrt_delta: expected a group element, got "
            f"{type(transform).__name__}."
        )
    check_elements("manifold.rplus_jacobian_parameters_wrt_delta", transform)
    return transform._rplus_jacobian()


__all__ = [
    "rplus",
    "rminus",
    "zero_tangents",
    "normalize_all",
    "grad",
    "value_and_grad",
    "rplus_jacobian_parameters_wrt_delta",
]
