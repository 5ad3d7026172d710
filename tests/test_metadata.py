"""The package as users meet it on an index: ``pyproject.toml``'s ``[project]`` table (authors,
keywords, classifiers PyPI accepts, a long description whose links resolve there) and the
extras table of ``docs/installation.md``, which must list what each extra installs."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import trove_classifiers
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: tomllib's origin (the test extra installs it there)
    import tomli as tomllib

REPO = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
NAME = canonicalize_name(PROJECT["name"])


def test_classifiers_are_ones_pypi_accepts() -> None:
    """Every classifier is a current trove classifier (PyPI rejects an upload with an unknown
    one), none is deprecated, and no ``License ::`` classifier stands beside the SPDX
    ``license`` expression (a build backend rejects the pair)."""
    classifiers = PROJECT["classifiers"]
    assert classifiers and len(set(classifiers)) == len(classifiers)
    unknown = [c for c in classifiers if c not in trove_classifiers.classifiers]
    assert not unknown, unknown
    deprecated = [c for c in classifiers if c in trove_classifiers.deprecated_classifiers]
    assert not deprecated, deprecated
    assert isinstance(PROJECT["license"], str)
    assert not [c for c in classifiers if c.startswith("License ::")]
    assert (REPO / "LICENSE").read_text(encoding="utf-8").startswith(f"{PROJECT['license']} ")
    # The package ships py.typed, which "Typing :: Typed" announces.
    assert "Typing :: Typed" in classifiers and (REPO / "jaxlie_geo" / "py.typed").is_file()


def test_authors_and_keywords() -> None:
    assert PROJECT["authors"] and all(author.get("name") for author in PROJECT["authors"])
    keywords = PROJECT["keywords"]
    assert "jax" in keywords and len(set(keywords)) == len(keywords) >= 5


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_long_description_links_are_absolute() -> None:
    """PyPI shows the ``readme`` file but resolves no relative link in it: every link and
    image of the long description names its scheme. Its code is the quick start's, which
    ``tests/test_docs.py`` runs."""
    readme = REPO / PROJECT["readme"]
    text = readme.read_text(encoding="utf-8")
    assert readme.suffix == ".md" and text.startswith(f"# {PROJECT['name']}\n")
    targets = re.findall(r"!?\[[^\]]*\]\(([^)\s]+)", text)
    targets += re.findall(r"""\b(?:href|src)=["']([^"']+)""", text)
    assert targets
    relative = [t for t in targets if not re.match(r"^https://", t)]
    assert not relative, relative
    quickstart = _python_blocks((REPO / "docs" / "quickstart.md").read_text(encoding="utf-8"))
    blocks = _python_blocks(text)
    assert blocks and all(block in quickstart for block in blocks)


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _extras_table() -> dict[str, tuple[set[str], dict[str, str]]]:
    """``docs/installation.md``'s extras table: for each extra, the extras it includes and
    the packages it adds, each with the version number written after it in parentheses
    ("" where none is)."""
    lines = (REPO / "docs" / "installation.md").read_text(encoding="utf-8").splitlines()
    start = lines.index("| extra | includes | adds | for |")
    table = {}
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        extra, includes, adds = _cells(line)[:3]
        (name,) = re.findall(r"`([^`]+)`", extra)
        packages = re.findall(r"`([^`]+)`(?: \((\d[\d.]*)\))?", adds)
        table[name] = (
            set(re.findall(r"`([^`]+)`", includes)),
            {canonicalize_name(package): version for package, version in packages},
        )
    return table


def test_extras_table_lists_what_each_extra_installs() -> None:
    """The table names every extra of ``pyproject.toml`` and no other; each row's "includes"
    is the set of the project's own extras the extra pulls in, its "adds" the set of the
    other packages it requires, and a version in parentheses is one the requirement allows
    only (``jaxlie`` (1.5) for ``jaxlie==1.5.*``)."""
    table = _extras_table()
    extras = PROJECT["optional-dependencies"]
    assert set(table) == set(extras)
    for extra, requirements in extras.items():
        includes, adds = set(), {}
        for requirement in map(Requirement, requirements):
            if canonicalize_name(requirement.name) == NAME:
                includes |= requirement.extras
            else:
                adds[canonicalize_name(requirement.name)] = requirement.specifier
        assert table[extra][0] == includes, (extra, table[extra][0], includes)
        assert set(table[extra][1]) == set(adds), (extra, set(table[extra][1]) ^ set(adds))
        for package, version in table[extra][1].items():
            if version:
                assert str(adds[package]) == f"=={version}.*", (extra, package, adds[package])
