"""Docstrings are contracts: shapes, conventions, formulas and their sources, accuracy bounds.
Timings and the history of the code (what it was, what changed) belong in docs/design/,
which a docstring may point to.

Every docstring of the package (module, class, function, and the attribute docstrings that
follow an assignment) is read with ``ast``: nothing is imported.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import Iterator, Tuple

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "jaxlie_geo"

_DIGIT = r"[\d⁰¹²³⁴⁵⁶⁷⁸⁹]"
FORBIDDEN = {
    "a timing": re.compile(
        rf"{_DIGIT}\s?(?:µs|us|ms|ns|s)\b|\b(?:µs|ms|ns)\b|\bseconds\b|\bminutes\b"
    ),
    "a before/after measurement": re.compile(rf"{_DIGIT}\s*→\s*{_DIGIT}"),
    "history": re.compile(
        r"\b(?:was|were|previously|formerly|used to|no longer|now|anymore|any more)\b", re.I
    ),
}

ALLOWED = {
    # The record of a solve returns wall-clock times: the unit is part of its contract.
    ("_record.py", "Solve", "a timing"),
}
"""(file, docstring's owner, rule) triples exempt from a rule, each with its reason above."""


def _docstrings(tree: ast.Module) -> Iterator[Tuple[str, int, str]]:
    """(owner's name, line, text) of every docstring under ``tree``."""
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        name = getattr(node, "name", "<module>")
        for i, stmt in enumerate(node.body):
            first = i == 0
            after_assignment = i > 0 and isinstance(node.body[i - 1], (ast.Assign, ast.AnnAssign))
            if (
                (first or after_assignment)
                and isinstance(stmt, ast.Expr)
                and isinstance(stmt.value, ast.Constant)
                and isinstance(stmt.value.value, str)
            ):
                yield name, stmt.lineno, stmt.value.value


MODULES = sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.relative_to(PACKAGE).as_posix())
def test_docstrings_hold_no_timing_or_history(path: Path) -> None:
    found = []
    for name, line, text in _docstrings(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        for rule, pattern in FORBIDDEN.items():
            if (path.name, name, rule) in ALLOWED:
                continue
            for m in pattern.finditer(text):
                context = text[max(0, m.start() - 40) : m.end() + 40].replace("\n", " ")
                found.append(f"{path.name}:{line} {name}: {rule}: ...{context}...")
    assert not found, "\n".join(found)


def test_the_rules_catch_what_they_name() -> None:
    """Each rule matches a sentence of its kind and leaves the contract's words alone."""
    cases = {
        "a timing": ["an eager call about 5 µs", "at 10⁶: 82 ms", "a few seconds", "10⁵ s"],
        "a before/after measurement": ["431 → 172 per element"],
        "history": ["the residual was off by 1e-3", "now ≤ 1.5 ulp", "it used to clamp"],
    }
    for rule, texts in cases.items():
        for text in texts:
            assert FORBIDDEN[rule].search(text), (rule, text)
    contract = "s = ‖M‖_F/√3, θ → 0, (*batch, 3), sin θ = 2 c s, measured within 4 ulp"
    hits = [rule for rule, pattern in FORBIDDEN.items() if pattern.search(contract)]
    assert not hits, hits


def test_allowed_entries_are_used() -> None:
    """Every allow-list entry names a docstring that still needs it."""
    for file, owner, rule in ALLOWED:
        (path,) = [p for p in MODULES if p.name == file]
        tree = ast.parse(path.read_text(encoding="utf-8"))
        texts = [t for n, _, t in _docstrings(tree) if n == owner]
        assert any(FORBIDDEN[rule].search(t) for t in texts), (file, owner, rule)
