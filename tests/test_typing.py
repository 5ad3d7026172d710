"""Static types: what a user's type checker infers from jaxlie_geo.

jaxlie users type-check their code (mypy, or pyright in their editors); jaxlie_geo ships
``py.typed``, so its annotations are part of the API. ``_typing_usage.py`` holds user code
with ``assert_type`` on every public entry point. mypy must accept it and the package with
no error, and the same file must run, where ``assert_type`` checks the values' classes.
"""

from __future__ import annotations

import pathlib
import runpy
import subprocess
import sys

HERE = pathlib.Path(__file__).parent


def test_mypy_accepts_the_package_and_infers_user_types(tmp_path: pathlib.Path) -> None:
    """mypy accepts the package and ``_typing_usage.py``, whose ``assert_type`` lines state the
    types a user's checker must infer."""
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            "--cache-dir",
            str(tmp_path),
            "--no-error-summary",
            "--python-version",
            "3.11",
            str(HERE.parent / "jaxlie_geo"),
            str(HERE / "_typing_usage.py"),
        ],
        capture_output=True,
        text=True,
        cwd=HERE.parent,
    )
    assert out.returncode == 0, out.stdout + out.stderr


def test_usage_runs_with_the_types_it_asserts() -> None:
    """``_typing_usage.py`` also runs: the types it asserts are those of the values."""
    runpy.run_path(str(HERE / "_typing_usage.py"))
