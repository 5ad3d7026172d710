"""Conversion to and from jaxlie 1.5 objects, for libraries that check for jaxlie's types
(jaxls, pyroki, viser, ...).

Both libraries store the same parameters in the same layout (``SO2.unit_complex``,
``SE2.unit_complex_xy``, ``SO3.wxyz``, ``SE3.wxyz_xyz``), so a conversion re-wraps the
parameter array: no copy, no arithmetic, no sign change of a quaternion. Both functions take
a single element or any pytree (dicts, lists, tuples, dataclasses) and convert every group
element in it, leaving everything else as it is; they work inside ``jax.jit`` and ``vmap``.
jaxlie is an optional dependency: it is imported on first use, and its absence raises
``ImportError`` with the install command.
"""

from __future__ import annotations

import importlib
from typing import Any, Dict, Tuple

import jax

from ._base import MatrixLieGroup
from ._se2 import SE2
from ._se3 import SE3
from ._so2 import SO2
from ._so3 import SO3

_OURS: Tuple[type, ...] = (SO2, SE2, SO3, SE3)


def _jaxlie_types() -> Dict[type, type]:
    """Map each of our group classes to jaxlie's class of the same name."""
    try:  # optional: imported by name, so that type checkers need not find it
        jaxlie = importlib.import_module("jaxlie")
    except ImportError as e:  # pragma: no cover - the test extra installs jaxlie
        raise ImportError("jaxlie_geo.interop needs jaxlie: pip install 'jaxlie==1.5.*'") from e
    return {G: getattr(jaxlie, G.__name__) for G in _OURS}


def to_jaxlie(tree: Any) -> Any:
    """Replace every jaxlie_geo group element in ``tree`` by the jaxlie 1.5 element with
    the same parameters (``jaxlie.SE3(T.wxyz_xyz)`` for an ``SE3``; batch axes kept).

    Args:
        tree: a group element, or a pytree containing group elements.
    Returns:
        The same structure with jaxlie elements in place of ours.
    """
    ours_to_theirs = _jaxlie_types()

    def convert(x: Any) -> Any:
        if isinstance(x, MatrixLieGroup):
            if type(x) not in ours_to_theirs:
                raise TypeError(f"to_jaxlie: jaxlie has no counterpart of {type(x).__name__}.")
            return ours_to_theirs[type(x)](x.parameters())
        return x

    return jax.tree.map(convert, tree, is_leaf=lambda x: isinstance(x, MatrixLieGroup))


def from_jaxlie(tree: Any) -> Any:
    """Replace every jaxlie 1.5 group element in ``tree`` by the jaxlie_geo element with
    the same parameters; the inverse of ``to_jaxlie``.

    Args:
        tree: a jaxlie element, or a pytree containing jaxlie elements.
    Returns:
        The same structure with jaxlie_geo elements in place of jaxlie's.
    """
    theirs_to_ours = {v: k for k, v in _jaxlie_types().items()}
    base = importlib.import_module("jaxlie").MatrixLieGroup  # (imported by _jaxlie_types)

    def is_theirs(x: Any) -> bool:
        return isinstance(x, base)

    def convert(x: Any) -> Any:
        if is_theirs(x):
            if type(x) not in theirs_to_ours:
                raise TypeError(f"from_jaxlie: no jaxlie_geo counterpart of {type(x).__name__}.")
            return theirs_to_ours[type(x)](x.parameters())
        return x

    return jax.tree.map(convert, tree, is_leaf=is_theirs)


__all__ = ["to_jaxlie", "from_jaxlie"]
