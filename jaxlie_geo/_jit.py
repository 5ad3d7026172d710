"""``jax.jit`` around every public method and function, with the trace-time element checks.

An eager call then costs one dispatch instead of one per primitive (the benchmark results
page times an eager ``SE3.exp``); inside a user's ``jit`` the wrapper is inlined. A leaf
module: it imports only the checks.
"""

from __future__ import annotations

import functools
import inspect
import warnings
from typing import Any, Callable, Dict, Optional, TypeVar, cast

import jax

from ._checks import check_elements, check_same_group, is_element

_NOT_JITTED = frozenset({"get_batch_axes", "parameters", "reshape"})
_JITTED_PRIVATE = {"_between": "relative element (a⁻¹ @ b)"}
"""Private methods that public functions call eagerly (``manifold.rminus``, ``geodesic``),
jitted too, with the name their error messages use."""
_STATIC_NAMES = ("batch_axes", "dtype", "project")


def _inherited_doc(cls: type, name: str) -> Any:
    """The docstring of ``name`` in the nearest base class that documents it."""
    for base in cls.__mro__[1:]:
        raw = base.__dict__.get(name)
        fn = getattr(raw, "__func__", raw)
        if fn is not None and getattr(fn, "__doc__", None):
            return fn.__doc__
    return None


def _checking_elements(fn: Any, where: str) -> Any:
    """``fn`` preceded by ``check_elements`` on its arguments (``self``, ``other``).
    Constructors cannot check (JAX rebuilds pytrees with shapes, tracers, None, and
    ``jax.jacfwd`` of a group-valued function returns an element holding a Jacobian), so
    the operations do. A method's other elements (``multiply``, ``interpolate``) must be of
    ``self``'s group: ``TypeError`` (an SE3 passed to ``SO3.multiply`` raised
    ``AttributeError: 'SE3' object has no attribute 'wxyz'``). Runs at trace time only."""

    @functools.wraps(fn)
    def checked(*args: Any, **kwargs: Any) -> Any:
        if args and is_element(args[0]):
            check_same_group(where, *args, *kwargs.values())
        check_elements(where, *args, *kwargs.values())
        return fn(*args, **kwargs)

    return checked


def jit_public_methods(cls: type) -> None:
    """Wrap every public method of ``cls`` (inherited ones included) in ``jax.jit``, each
    preceded by the trace-time element checks. ``batch_axes``, ``dtype`` and ``project``
    are static.

    A classmethod becomes, on each concrete class, a ``jax.jit`` of the function with
    ``cls`` bound (stored as a staticmethod, its signature without ``cls``), as in jaxlie:
    so ``SO3.exp`` is itself a jitted function and ``SO3.exp.lower(tangent)``,
    ``.trace`` and ``.eval_shape`` work (ahead-of-time compilation). A subclass rebinds it.
    """
    for name in dir(cls):
        if (name.startswith("_") and name not in _JITTED_PRIVATE) or name in _NOT_JITTED:
            continue
        raw = inspect.getattr_static(cls, name)
        bound_of = getattr(getattr(raw, "__func__", None), "_classmethod", None)
        if bound_of is not None:  # a classmethod bound to a base class: bind it to cls
            raw = classmethod(bound_of)
        kind = type(raw) if isinstance(raw, (classmethod, staticmethod)) else None
        fn = raw.__func__ if kind else raw
        if not inspect.isfunction(fn) or getattr(fn, "_jitted", False):
            continue
        if getattr(fn, "_deprecated_alias", False):  # warns on every call: never traced
            continue
        if getattr(fn, "__isabstractmethod__", False):
            continue
        sig = inspect.signature(fn)
        names = list(sig.parameters)
        static = tuple(n for n in _STATIC_NAMES if n in names)
        where = f"{cls.__name__}.{name}"
        if name in _JITTED_PRIVATE:
            where = f"{cls.__name__} {_JITTED_PRIVATE[name]}"
        checked = _checking_elements(fn, where)
        if kind is classmethod:
            checked = functools.partial(checked, cls)
            sig = sig.replace(parameters=list(sig.parameters.values())[1:])
            names = names[1:]
        argnums = tuple(names.index(n) for n in static)
        jitted = jax.jit(checked, static_argnums=argnums, static_argnames=static)
        if "batch_axes" in names:
            pos = names.index("batch_axes")

            def call(*args: Any, _jitted: Any = jitted, _pos: int = pos, **kwargs: Any) -> Any:
                # Lists are unhashable: make batch_axes a tuple before jit sees it.
                if len(args) > _pos and not isinstance(args[_pos], tuple):
                    args = (*args[:_pos], tuple(args[_pos]), *args[_pos + 1 :])
                elif not isinstance(kwargs.get("batch_axes", ()), tuple):
                    kwargs["batch_axes"] = tuple(kwargs["batch_axes"])
                return _jitted(*args, **kwargs)

            for stage in ("lower", "trace", "eval_shape"):  # AOT, as on a jax.jit
                if hasattr(jitted, stage):
                    setattr(call, stage, getattr(jitted, stage))
            call.__signature__ = sig  # type: ignore[attr-defined]  # (a jax.jit has its own)
        else:
            call = jitted  # type: ignore[assignment]
        wrapper = functools.wraps(fn)(call)
        wrapper._jitted = True  # type: ignore[attr-defined]
        if not fn.__doc__:  # an override documented in the base class: show the base's text
            wrapper.__doc__ = _inherited_doc(cls, name)
        if kind is classmethod:
            wrapper._classmethod = fn  # type: ignore[attr-defined]
            setattr(cls, name, staticmethod(wrapper))
        else:
            setattr(cls, name, kind(wrapper) if kind else wrapper)


_F = TypeVar("_F", bound=Callable[..., Any])


def jit_function(*static_argnames: str) -> Callable[[_F], _F]:
    """Decorator: wrap a module-level public function in ``jax.jit`` (the named arguments
    static), as the group methods are, so that an eager call is one dispatch. Group
    elements among the arguments are checked at trace time (``_checks.check_elements``)."""

    def wrap(fn: _F) -> _F:
        where = f"{fn.__module__.rsplit('.', 1)[-1]}.{fn.__name__}"
        jitted = jax.jit(_checking_elements(fn, where), static_argnames=static_argnames)
        return cast(_F, functools.wraps(fn)(lambda *args, **kwargs: jitted(*args, **kwargs)))

    return wrap


def deprecated_alias(
    old: str, new: str, *, on_class: bool = False, renamed: Optional[Dict[str, str]] = None
) -> Any:
    """The method ``old``, a deprecated name of the method ``new`` of the same class (a
    classmethod where ``on_class``): it calls ``new``, with the keyword arguments in
    ``renamed`` (old name → new name) passed under their new names. Every call warns
    (``DeprecationWarning`` naming ``new``): the alias itself is not jitted."""
    renamed = renamed or {}

    def alias(owner: Any, *args: Any, **kwargs: Any) -> Any:
        group = owner.__name__ if isinstance(owner, type) else type(owner).__name__
        warnings.warn(
            f"{group}.{old} is deprecated: use {group}.{new}.",
            DeprecationWarning,
            stacklevel=2,
        )
        kwargs = {renamed.get(k, k): v for k, v in kwargs.items()}
        return getattr(owner, new)(*args, **kwargs)

    alias.__name__ = alias.__qualname__ = old
    alias.__doc__ = f"Deprecated alias of ``{new}``, kept for one release."
    alias._deprecated_alias = True  # type: ignore[attr-defined]
    return classmethod(alias) if on_class else alias
