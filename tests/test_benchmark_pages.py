"""The figures the README and the guides copy from the results page are blocks that
``benchmarks/report.py`` renders from the raw results: an edited figure is found and
rewritten, an unknown or unused block fails (``test_docs`` runs ``report --check`` itself).
Rendering reads JSON and writes Markdown; it compiles nothing."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from benchmarks import common as C
from benchmarks import report as R


@pytest.fixture(scope="module")
def raw() -> dict:
    return C.load(C.RAW_DIR)


def test_every_copy_holds_rendered_blocks_and_every_block_is_used(raw: dict) -> None:
    used = {
        m[2]
        for rel in R.COPIES
        for m in R._BLOCK.finditer((C.REPO_ROOT / rel).read_text(encoding="utf-8"))
    }
    assert used == set(R.excerpts(raw)), "a rendered block is missing from its page, or unused"


def test_an_edited_figure_is_found_and_rewritten(raw: dict, tmp_path: Path) -> None:
    for rel in R.COPIES:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(C.REPO_ROOT / rel, tmp_path / rel)
    readme = tmp_path / "README.md"
    text = readme.read_text(encoding="utf-8")
    block = R.excerpts(raw)["readme-speed"]
    row = next(line for line in block.splitlines() if line.startswith("| SE3 exp |"))
    readme.write_text(text.replace(row, "| SE3 exp | 9.99 | 9.99 | 9.99 |"), encoding="utf-8")
    assert R.stale_copies(raw, root=tmp_path) == ["README.md"]
    assert R.stale_copies(raw, root=tmp_path, write=True) == ["README.md"]
    assert readme.read_text(encoding="utf-8") == text


def test_an_unknown_block_name_is_an_error(raw: dict) -> None:
    text = (
        "<!-- rendered by benchmarks/report.py: no-such-block -->\n"
        "x\n"
        "<!-- end of rendered block -->"
    )
    with pytest.raises(KeyError, match="no-such-block"):
        R.render_copy(text, R.excerpts(raw), "page.md")
