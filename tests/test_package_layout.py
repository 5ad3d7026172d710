"""The package's import structure: leaf modules import no group code, the import graphs of
the package and of each subpackage have no cycle, and no module imports inside a function
body to hide one. The benchmarks package too has no cycle, and its shared modules import
none of the scripts.

Read from the source with ``ast`` (independent of Python's import machinery, which tolerates
cycles as long as the names exist when they are read).
"""

from __future__ import annotations

import ast
import inspect
import pathlib
from typing import Dict, Set

import pytest

import jaxlie_geo

PACKAGE = pathlib.Path(jaxlie_geo.__file__).parent
BENCHMARKS = pathlib.Path(__file__).resolve().parents[1] / "benchmarks"

LEAVES = {
    "hints", "_checks", "_xla", "_pytree", "_jit", "_batch", "_scalar", "_scalar_sim3",
    "_projection", "_sparse", "_record",
}  # fmt: skip
"""Modules with no knowledge of the group classes: the base imports them, never the reverse."""


def _package_imports(node: ast.AST, module: str, folder: pathlib.Path) -> Set[str]:
    """The modules of the package in ``folder`` that the import statements under ``node``
    name (``__init__`` for a name the package itself exports)."""
    package = folder.name
    modules = {p.stem for p in folder.glob("*.py")} | {
        p.parent.name for p in folder.glob("*/__init__.py")
    }
    out = set()
    for n in ast.walk(node):
        if not isinstance(n, ast.ImportFrom):
            continue
        name = n.module or ""
        if n.level == 1 and name:  # from .a import b
            out.add(name.split(".")[0])
        elif (n.level == 1 and not name) or (n.level == 0 and name == package):
            # from . import a, b / from package import a, b
            out.update(a.name if a.name in modules else "__init__" for a in n.names)
        elif n.level == 0 and name.startswith(package + "."):
            out.add(name.split(".")[1])
    out.discard(module)
    return out


def _graph(folder: pathlib.Path = PACKAGE) -> Dict[str, Set[str]]:
    graph = {}
    for path in folder.glob("*.py"):
        name = path.stem
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        graph[name] = _package_imports(tree, name, folder)
    return graph


def test_leaf_modules_import_only_leaves() -> None:
    graph = _graph()
    assert LEAVES <= set(graph), sorted(LEAVES - set(graph))
    for leaf in sorted(LEAVES):
        upward = graph[leaf] - LEAVES
        assert not upward, f"{leaf} imports {sorted(upward)}"


SUBPACKAGES = sorted(p.parent for p in PACKAGE.glob("*/__init__.py"))
"""The package's subpackages (``splines``, ``pose_graph``): their modules import each other
too, and must not cycle either."""


@pytest.mark.parametrize(
    "folder",
    [PACKAGE, *SUBPACKAGES, BENCHMARKS],
    ids=lambda f: f"jaxlie_geo.{f.name}" if f.parent == PACKAGE else f.name,
)
def test_import_graph_has_no_cycle(folder: pathlib.Path) -> None:
    graph = _graph(folder)
    done: Set[str] = set()

    def visit(name: str, path: tuple) -> None:
        if name in path:
            raise AssertionError("import cycle: " + " -> ".join(path[path.index(name) :] + (name,)))
        if name in done:
            return
        for dep in sorted(graph.get(name, ())):
            if dep != "__init__":
                visit(dep, path + (name,))
        done.add(name)

    for name in sorted(graph):
        visit(name, ())


def test_benchmarks_shared_modules_are_leaves() -> None:
    """``benchmarks.common`` (machine facts, labels, timing, raw files) and ``benchmarks.mpref``
    (the mpmath references) import no other benchmark module; the page (``report``) imports
    only them and the figures (``plot``)."""
    graph = _graph(BENCHMARKS)
    assert graph["common"] == graph["mpref"] == set()
    assert graph["plot"] == {"common"}
    assert graph["report"] == {"common", "plot", "mpref"}
    users = {name for name, deps in graph.items() if "common" in deps}
    assert users >= {"run", "report", "plot", "jacobians", "accuracy", "pose_graphs"}


def test_no_import_inside_a_function() -> None:
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                inner = [n for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))]
                assert not inner, f"{path.name}: {fn.name} imports at line {inner[0].lineno}"


def test_public_modules_list_their_names() -> None:
    """Every public module has an ``__all__`` naming only attributes that exist and every
    public function and class it defines; the package's ``__all__`` names every public
    attribute it exports."""
    for name in jaxlie_geo.__all__:
        assert hasattr(jaxlie_geo, name), name
    exported = {n for n in vars(jaxlie_geo) if not n.startswith("_")}
    assert exported == set(jaxlie_geo.__all__), sorted(exported ^ set(jaxlie_geo.__all__))
    for mod in ("hints", "interop", "jacobians", "manifold", "motion", "uncertainty", "utils"):
        module = getattr(jaxlie_geo, mod)
        assert hasattr(module, "__all__"), mod
        missing = [n for n in module.__all__ if not hasattr(module, n)]
        assert not missing, (mod, missing)
        defined = {
            n
            for n, v in vars(module).items()
            if not n.startswith("_")
            and (inspect.isfunction(v) or inspect.isclass(v))
            and v.__module__ == module.__name__
        }
        assert defined <= set(module.__all__), (mod, sorted(defined - set(module.__all__)))
