"""Repository rules that are not properties of the library, checked by ``make lint``.

* README.md stays a short user document (``README_MAX_BYTES``; detail goes to docs/).
* The committed notebooks are stripped: valid JSON notebooks of the python3 kernel with
  code cells that carry no outputs, execution counts or timing metadata (the docs build
  and the test suite execute them; ``notebooks/README.md``).

Run as ``python tests/check_repository.py``; it prints each broken rule and exits 1.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Iterator

REPO = Path(__file__).resolve().parents[1]
README_MAX_BYTES = 12_000


def readme_problems() -> Iterator[str]:
    size = len((REPO / "README.md").read_bytes())
    if size >= README_MAX_BYTES:
        yield f"README.md is {size} bytes (limit {README_MAX_BYTES}); move detail to docs/"


def notebook_problems() -> Iterator[str]:
    for path in sorted((REPO / "notebooks").glob("*.ipynb")):
        name = path.relative_to(REPO).as_posix()
        nb = json.loads(path.read_text(encoding="utf-8"))
        if nb.get("nbformat") != 4:
            yield f"{name}: not an nbformat 4 notebook"
        if nb.get("metadata", {}).get("kernelspec", {}).get("name") != "python3":
            yield f"{name}: its kernel is not python3"
        code = [c for c in nb.get("cells", []) if c.get("cell_type") == "code"]
        if not code:
            yield f"{name}: no code cells"
        for i, cell in enumerate(code):
            if cell.get("outputs"):
                yield f"{name}: code cell {i} has outputs"
            if cell.get("execution_count") is not None:
                yield f"{name}: code cell {i} has an execution count"
            if "execution" in cell.get("metadata", {}):
                yield f"{name}: code cell {i} has timing metadata"


def main() -> int:
    problems = [*readme_problems(), *notebook_problems()]
    for p in problems:
        print(p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
