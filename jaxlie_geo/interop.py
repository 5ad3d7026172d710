"""jaxlie_geo in place of jaxlie 1.5: under its name for libraries built on it, or by
conversion of the objects.

``install_as_jaxlie()`` makes ``import jaxlie`` give jaxlie_geo to everything imported after
it: libraries built on jaxlie (jaxls, pyroki, ...) then create, check
(``isinstance(x, jaxlie.SE3)``) and capture in closures jaxlie_geo's elements, with no change
to their code. The name follows PyMySQL's ``install_as_MySQLdb()``.

``to_jaxlie`` and ``from_jaxlie`` exchange data with a real jaxlie instead. Both libraries
store the same parameters in the same layout (``SO2.unit_complex``, ``SE2.unit_complex_xy``,
``SO3.wxyz``, ``SE3.wxyz_xyz``), so a conversion re-wraps the parameter array: no copy, no
arithmetic, no sign change of a quaternion. Both functions take a single element or any
pytree (dicts, lists, tuples, dataclasses) and convert every group element in it, leaving
everything else as it is; they work inside ``jax.jit`` and ``vmap``. They do not reach a
library's inside: the classes it checks for and the poses it keeps in closures stay
jaxlie's. jaxlie is an optional dependency: it is imported on first use, and its absence
raises ``ImportError`` with the install command.
"""

from __future__ import annotations

import importlib
import importlib.abc
import pkgutil
import sys
from typing import Any, Dict, Optional, Sequence, Tuple

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


class _NoOtherJaxlieModule(importlib.abc.MetaPathFinder):
    """After ``install_as_jaxlie``: ``import jaxlie.<name>`` of a module jaxlie_geo does not
    have fails, instead of loading a second copy of one of jaxlie_geo's files."""

    def find_spec(self, fullname: str, path: Optional[Sequence[str]], target: Any = None) -> None:
        if fullname.startswith("jaxlie."):
            raise ModuleNotFoundError(
                f"No module named {fullname!r}: `jaxlie` is jaxlie_geo here "
                "(jaxlie_geo.interop.install_as_jaxlie), which has no module "
                f"{'jaxlie_geo.' + fullname[len('jaxlie.') :]!r}.",
                name=fullname,
            )
        return None


def install_as_jaxlie() -> None:
    """Make ``import jaxlie`` resolve to jaxlie_geo for every import that follows.

    After the call, ``import jaxlie``, ``jaxlie.manifold``, ``jaxlie.hints`` and
    ``jaxlie.utils`` (and every other module of jaxlie_geo, under ``jaxlie.``) are
    jaxlie_geo's own module objects, so a library built on jaxlie and imported afterwards
    works on jaxlie_geo's elements throughout: its ``isinstance(x, jaxlie.SE3)`` checks, the
    poses it captures in closures under ``jit``, its pytrees. Call it first, before anything
    imports jaxlie::

        import jaxlie_geo.interop
        jaxlie_geo.interop.install_as_jaxlie()
        import jaxls  # sees jaxlie_geo as jaxlie

    A second call does nothing. ``to_jaxlie`` and ``from_jaxlie`` then return their argument:
    there is one library. Importing a ``jaxlie.<name>`` that jaxlie_geo does not have raises
    ``ModuleNotFoundError``.

    Raises:
        RuntimeError: jaxlie (or a module of it) is imported already: the objects
            made from it would not be jaxlie_geo's, so the call refuses rather than
            mix the two libraries.
    """
    ours = sys.modules[__package__]
    present = sorted(name for name in sys.modules if name == "jaxlie" or name.startswith("jaxlie."))
    if present and sys.modules.get("jaxlie") is ours:
        return
    if present:
        where = getattr(sys.modules.get(present[0]), "__file__", None) or "unknown location"
        raise RuntimeError(
            f"install_as_jaxlie: jaxlie is already imported ({present[0]} from {where}). "
            "Call jaxlie_geo.interop.install_as_jaxlie() before anything imports jaxlie."
        )
    for info in pkgutil.walk_packages(ours.__path__, ours.__name__ + "."):
        try:
            importlib.import_module(info.name)
        except ImportError:  # a module behind an optional dependency: left unaliased
            continue
    aliases = {
        "jaxlie" + name[len(ours.__name__) :]: module
        for name, module in list(sys.modules.items())
        if name == ours.__name__ or name.startswith(ours.__name__ + ".")
    }
    sys.modules.update(aliases)
    sys.meta_path.insert(0, _NoOtherJaxlieModule())


def _is_installed_as_jaxlie() -> bool:
    return sys.modules.get("jaxlie") is sys.modules[__package__]


def to_jaxlie(tree: Any) -> Any:
    """Replace every jaxlie_geo group element in ``tree`` by the jaxlie 1.5 element with
    the same parameters (``jaxlie.SE3(T.wxyz_xyz)`` for an ``SE3``; batch axes kept).

    Args:
        tree: a group element, or a pytree containing group elements.
    Returns:
        The same structure with jaxlie elements in place of ours; ``tree`` itself after
        ``install_as_jaxlie()``, when jaxlie's classes are ours.
    """
    if _is_installed_as_jaxlie():
        return tree
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
        The same structure with jaxlie_geo elements in place of jaxlie's; ``tree`` itself
        after ``install_as_jaxlie()``.
    """
    if _is_installed_as_jaxlie():
        return tree
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


__all__ = ["install_as_jaxlie", "to_jaxlie", "from_jaxlie"]
