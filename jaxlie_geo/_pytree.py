"""Pytree registration of the library's frozen dataclasses (group elements, geodesics,
motions), with ``jax_dataclasses.copy_and_mutate`` and ``flax.serialization`` support.

A leaf module: it imports nothing from the package.
"""

from __future__ import annotations

import dataclasses
import importlib
from typing import Any, Iterable, Tuple, TypeVar

import jax
import numpy as onp
from typing_extensions import dataclass_transform

_C = TypeVar("_C", bound=type)


@dataclass_transform(frozen_default=True, eq_default=False)
def pytree_dataclass(cls: _C) -> _C:
    """Make ``cls`` a frozen dataclass (``eq=False``) and register it as a pytree whose
    structure records the class: every field is a child, with ``GetAttrKey`` key paths,
    except fields declared with ``dataclasses.field(metadata={"static": True})``, which
    are part of the structure (hashable, compared by ``==``: a spline's degree and knot
    spacing), so a jitted function compiles once per value.

    A class that inherits a ``__repr__`` keeps it (group elements print rounded values, as
    jaxlie's do); others get the dataclass's.

    Not ``jax.tree_util.register_dataclass``: up to jax 0.10.2 the treedefs of two classes
    registered that way compare *equal* whenever their fields have the same layout
    (``tree_structure(SO3(x)) == tree_structure(SE2(x))`` is True; only the hashes differ),
    so ``jax.jit``'s cache can return the computation compiled for one class when called
    with the other (400 distinct one-field classes through one jitted function gave 64
    results computed for another class). ``tests/test_transforms.py`` checks that no two of
    our pytree classes (and no user dataclass of the same layout) share a structure.
    """
    own_repr = cls.__repr__ is object.__repr__
    cls = dataclasses.dataclass(frozen=True, eq=False, repr=own_repr)(cls)  # type: ignore[assignment]
    cls.__setattr__ = _setattr_if_mutable  # type: ignore[assignment,method-assign]
    fields = dataclasses.fields(cls)
    names = tuple(f.name for f in fields if not f.metadata.get("static", False))
    static = tuple(f.name for f in fields if f.metadata.get("static", False))
    keys = tuple(jax.tree_util.GetAttrKey(n) for n in names)

    def flatten_with_keys(x: Any) -> Tuple[Tuple[Any, ...], Tuple[Any, ...]]:
        aux = tuple(getattr(x, n) for n in static)
        return tuple((k, getattr(x, n)) for k, n in zip(keys, names)), aux

    def flatten(x: Any) -> Tuple[Tuple[Any, ...], Tuple[Any, ...]]:
        return tuple(getattr(x, n) for n in names), tuple(getattr(x, n) for n in static)

    def unflatten(aux: Tuple[Any, ...], children: Iterable[Any]) -> Any:
        # Bypass the frozen dataclass's __init__ (one object.__setattr__ per field either
        # way; this saves the call): unflattening runs on every jitted call's outputs.
        obj: Any = object.__new__(cls)
        for n, c in zip(names, children):
            object.__setattr__(obj, n, c)
        for n, a in zip(static, aux):
            object.__setattr__(obj, n, a)
        return obj

    jax.tree_util.register_pytree_with_keys(cls, flatten_with_keys, unflatten, flatten)
    _register_flax_state(cls, names)
    return cls


def _setattr_if_mutable(self: Any, name: str, value: Any) -> None:
    """Frozen (``dataclasses.FrozenInstanceError``), except on the copies that
    ``jax_dataclasses.copy_and_mutate`` yields, which it marks with ``__mutability__``:
    there a field may be reassigned, as on jaxlie's jax_dataclasses elements. With
    ``validate=True`` (its default) the new value must have the old one's tree structure
    and shapes, and a dtype of the same kind (jax_dataclasses' rule); else ``ValueError``."""
    mode = getattr(self.__dict__.get("__mutability__"), "name", "FROZEN")
    if mode == "FROZEN":
        raise dataclasses.FrozenInstanceError(
            f"cannot assign to field {name!r}: {type(self).__name__} is frozen (build a new "
            f"element, use dataclasses.replace, or jax_dataclasses.copy_and_mutate)."
        )
    if mode == "MUTABLE":
        old, new = getattr(self, name), value
        old_leaves, old_def = jax.tree_util.tree_flatten(old)
        new_leaves, new_def = jax.tree_util.tree_flatten(new)
        same = bool(old_def == new_def) and all(  # type: ignore[operator]
            onp.shape(a) == onp.shape(b) and onp.result_type(a).kind == onp.result_type(b).kind
            for a, b in zip(old_leaves, new_leaves)
        )
        if not same:
            shown = [(onp.shape(x), str(onp.result_type(x))) for x in new_leaves]
            want = [(onp.shape(x), str(onp.result_type(x))) for x in old_leaves]
            raise ValueError(
                f"{type(self).__name__}.{name}: copy_and_mutate needs the same structure, "
                f"shapes and kind of dtype: got {shown}, had {want}."
            )
    object.__setattr__(self, name, value)


try:  # flax is optional: serialization is registered only where it imports
    _flax_serialization: Any = importlib.import_module("flax.serialization")
except Exception:  # absent, or broken against this jax: then there is nothing to register
    _flax_serialization = None


def _register_flax_state(cls: type, names: Tuple[str, ...]) -> None:
    """Register ``cls`` with ``flax.serialization`` (when flax is installed), as jaxlie's
    jax_dataclasses does: the state dict is ``{field name: state of the field}``, e.g.
    ``{"wxyz_xyz": array}``, so ``to_bytes``/``from_bytes`` and ``to_state_dict`` work and
    a file written by either library loads in the other (same field names). Restoring
    raises ``ValueError`` naming a missing or unknown field."""
    if _flax_serialization is None:
        return
    ser = _flax_serialization

    def to_state(x: Any) -> dict:
        return {n: ser.to_state_dict(getattr(x, n)) for n in names}

    def from_state(x: Any, state: dict) -> Any:
        missing = [n for n in names if n not in state]
        unknown = sorted(set(state) - set(names))
        if missing or unknown:
            raise ValueError(
                f"{cls.__name__} state dict: missing field(s) {missing}, unknown field(s) "
                f"{unknown}; expected exactly {list(names)}."
            )
        return dataclasses.replace(
            x, **{n: ser.from_state_dict(getattr(x, n), state[n]) for n in names}
        )

    ser.register_serialization_state(cls, to_state, from_state)
