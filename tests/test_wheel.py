"""The wheel is the library: built from a copy of the source tree, it holds every module of
``jaxlie_geo`` and ``py.typed``, nothing else besides its dist-info (no reference
implementations, benchmarks, tests or docs), and its modules import nothing outside the
standard library and the wheel's unconditional requirements.

Built with the running interpreter's setuptools (``--no-build-isolation``: no network), which
must satisfy the build system's requirement (the ``test`` extra declares it). No jax is
imported.
"""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# What a build of the checkout must not see: version control, environments, build outputs.
_NOT_SOURCE = (".git", ".venv", "out", "build", "dist", "*.egg-info", "__pycache__")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> zipfile.ZipFile:
    tmp = tmp_path_factory.mktemp("wheel")
    src, out = tmp / "src", tmp / "out"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(*_NOT_SOURCE))
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"]
    run = subprocess.run([*cmd, "-w", str(out), str(src)], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    (path,) = out.glob("jaxlie_geo-*.whl")
    return zipfile.ZipFile(path)


def _dist_info(wheel: zipfile.ZipFile) -> str:
    (name,) = {n.split("/")[0] for n in wheel.namelist() if n.split("/")[0].endswith(".dist-info")}
    return name


def test_wheel_holds_the_package_modules_and_py_typed(wheel: zipfile.ZipFile) -> None:
    dist_info = _dist_info(wheel)
    assert re.fullmatch(r"jaxlie_geo-[^-/]+\.dist-info", dist_info), dist_info
    files = {n for n in wheel.namelist() if not n.startswith(dist_info + "/")}
    package = ROOT / "jaxlie_geo"
    expected = {p.relative_to(ROOT).as_posix() for p in package.rglob("*.py")}
    expected.add("jaxlie_geo/py.typed")
    assert files == expected, (sorted(files - expected), sorted(expected - files))


def test_wheel_modules_import_only_the_requirements(wheel: zipfile.ZipFile) -> None:
    """Every import statement, at any depth, names the standard library, the package itself
    or a requirement without an extra marker (optional backends are loaded by name, on
    demand, through ``importlib``)."""
    metadata = Parser().parsestr(wheel.read(_dist_info(wheel) + "/METADATA").decode())
    required = {
        re.split(r"[\s<>=!~;\[]", r, maxsplit=1)[0].lower().replace("-", "_")
        for r in metadata.get_all("Requires-Dist") or []
        if "extra ==" not in r
    }
    allowed = set(sys.stdlib_module_names) | required | {"jaxlie_geo"}
    found = {}
    for name in wheel.namelist():
        if not name.endswith(".py"):
            continue
        for node in ast.walk(ast.parse(wheel.read(name), name)):
            if isinstance(node, ast.Import):
                tops = [a.name.split(".")[0] for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                tops = [node.module.split(".")[0]]
            else:
                continue
            for top in tops:
                if top not in allowed:
                    found.setdefault(top, []).append(f"{name}:{node.lineno}")
    assert not found, found
