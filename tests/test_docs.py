"""The documentation: the site builds in strict mode, the API reference covers the public
surface, the code on its pages runs, and the README's links resolve (its length is a
repository rule, ``tests/check_repository.py``).

The site is built once per module with ``mkdocs build --strict`` into a temporary folder, so
a broken link, a page missing from the nav, or a docstring griffe cannot parse fails here.
"""

from __future__ import annotations

import html
import importlib.util
import json
import os
import re
import subprocess
import sys
import types
from pathlib import Path
from urllib.parse import unquote

import pytest
import yaml
from mkdocs.exceptions import PluginError

import jaxlie_geo

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site, built in strict mode (warnings are errors)."""
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", "mkdocs.yml", "-d", str(out)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
        # mkdocs-material prints a banner about its successor on every build; it is no warning.
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONDONTWRITEBYTECODE": "1"},
    )
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    return out


def _pages(site: Path) -> dict[Path, str]:
    return {p: p.read_text(encoding="utf-8") for p in site.rglob("*.html")}


_RESOURCE = re.compile(r"<(script|link|img|iframe|source)\b[^>]*?\b(?:src|href)=\"([^\"]*)\"", re.I)
_HREF = re.compile(r"<a\b[^>]*?\bhref=\"([^\"#?]*)[^\"]*\"", re.I)


def test_site_loads_nothing_from_the_network(site: Path) -> None:
    """No script, stylesheet, image or frame comes from another host: the site, maths
    included, reads the same offline (hyperlinks to other sites are fine)."""
    remote = {
        (page.relative_to(site).as_posix(), url)
        for page, text in _pages(site).items()
        for _, url in _RESOURCE.findall(text)
        if re.match(r"^([a-z][a-z0-9+.-]*:)?//", url, re.I) and not url.startswith("data:")
    }
    assert not remote, sorted(remote)[:10]
    # Nor a module a script would import at run time.
    imported = {
        page.relative_to(site).as_posix()
        for page, text in _pages(site).items()
        if re.search(r"""import\(\s*["'](https?:)?//""", text)
    }
    assert not imported, sorted(imported)


# TeX a reader would see as such: a command, a delimiter, a braced sub- or superscript.
_TEX = re.compile(r"\\[A-Za-z]+|\\[()\[\]|]|\^\{|_\{|\$")
_MATH_ELEMENT = re.compile(r"<math\b.*?</math>", re.S)


def _prose(text: str) -> str:
    """The text of a page outside its maths and code, as a reader sees it: without the
    ``<math>`` elements, scripts, styles, code blocks and the hidden copy of each notebook
    cell's source that the copy button reads."""
    text = _MATH_ELEMENT.sub("", text)
    text = re.sub(r'<div class="clipboard-copy-txt"[^>]*>.*?</div>', "", text, flags=re.S)
    text = re.sub(r"<(script|style|code|pre)\b.*?</\1>", "", text, flags=re.S | re.I)
    return html.unescape(re.sub(r"<[^>]*>", " ", text))


def test_maths_is_mathml_with_no_tex_left(site: Path) -> None:
    """Every formula is MathML, and no TeX survives on any page (notebooks, design notes,
    API reference, nav and titles included): no command, delimiter, ``^{``, ``_{`` or ``$``
    in the text outside ``<math>`` and code, and no command left as text inside a
    ``<math>`` element."""
    pages = _pages(site)
    assert any("<math " in text for text in pages.values())
    assert {site / "api" / "sim3.html", site / "notebooks" / "02_numerics.html"} <= set(pages)
    found = {}
    for page, text in pages.items():
        name = page.relative_to(site).as_posix()
        prose = _prose(text)
        for match in _TEX.finditer(prose):
            found.setdefault(name, prose[max(match.start() - 40, 0) : match.end() + 40].strip())
        for math in _MATH_ELEMENT.findall(text):
            if re.search(r">[^<]*\\", math):
                found.setdefault(name, math)
    assert not found, found


def test_a_tex_command_mathml_cannot_show_fails_the_build() -> None:
    """The hooks render what latex2mathml can show and raise, naming the page, on a
    command it would leave as text or an operator name it cannot read."""
    hooks = _hooks()
    assert "<msub>" in hooks.to_mathml(r"T_{p,m}", "inline", "page.md")
    assert "<mo>argmin</mo>" in hooks.to_mathml(r"\operatorname{argmin}_T", "inline", "page.md")
    for tex in (r"\arg\min_T f", r"\big\| x \big\|", r"\operatorname{atan2}(y, x)", r"\unknown x"):
        with pytest.raises(PluginError, match="page.md"):
            hooks.to_mathml(tex, "inline", "page.md")


def test_links_resolve_to_files(site: Path) -> None:
    """Every relative link names a file of the site (pages are files, not folders), so the
    navigation works from disk (``file://``) as from a server. (Not the 404 page: only a
    server shows it, at any address, so its links are absolute.)"""
    missing = set()
    for page, text in _pages(site).items():
        if page.name == "404.html":
            continue
        for target in _HREF.findall(text):
            if not target or re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):
                continue
            path = (page.parent / target).resolve()
            if not path.is_file():
                missing.add((page.relative_to(site).as_posix(), target))
    assert not missing, sorted(missing)[:10]


_ID = re.compile(r"\bid=\"([^\"]+)\"")
_ANCHOR = re.compile(r"<a\b[^>]*?\bhref=\"([^\"]*#[^\"]*)\"", re.I)


def test_anchors_lead_to_an_id(site: Path) -> None:
    """Every link to a place in a page of the site (``#name`` in the same page,
    ``page.html#name`` in another) names an id that page has: contents lists, permalinks,
    cross-references and the API's autorefs all lead somewhere."""
    pages = _pages(site)
    ids = {page.resolve(): set(_ID.findall(text)) for page, text in pages.items()}
    checked, missing = 0, set()
    for page, text in pages.items():
        if page.name == "404.html":
            continue
        for href in _ANCHOR.findall(text):
            path, _, anchor = html.unescape(href).partition("#")
            if not anchor or re.match(r"^[a-z][a-z0-9+.-]*:", path, re.I):
                continue
            target = (page.parent / path).resolve() if path else page.resolve()
            checked += 1
            if anchor not in ids.get(target, ()) and unquote(anchor) not in ids.get(target, ()):
                missing.add((page.relative_to(site).as_posix(), href))
    assert checked > 1000, checked
    assert not missing, sorted(missing)[:20]


def _nav_titles() -> dict[str, str]:
    """The title mkdocs.yml's nav gives each page, by its path under docs/."""
    config = yaml.safe_load((REPO / "mkdocs.yml").read_text(encoding="utf-8"))
    titles: dict[str, str] = {}

    def walk(items: list) -> None:
        for item in items:
            if isinstance(item, dict):
                for title, value in item.items():
                    walk(value) if isinstance(value, list) else titles.setdefault(value, title)

    walk(config["nav"])
    return titles


def test_notebook_pages_keep_titles_and_headings(site: Path) -> None:
    """A notebook page has the nav's title, and its contents list has every heading of the
    notebook below the first (the theme lists the title heading's children), inline code
    kept, linked to the heading's id on the page."""
    titles = _nav_titles()
    for notebook in sorted((REPO / "notebooks").glob("*.ipynb")):
        text = (site / "notebooks" / f"{notebook.stem}.html").read_text(encoding="utf-8")
        title = titles[f"notebooks/{notebook.name}"]
        assert f"<title>{html.escape(title)} - jaxlie_geo</title>" in text, notebook.name
        cells = json.loads(notebook.read_text(encoding="utf-8"))["cells"]
        headings = [
            line.lstrip("#").strip()
            for cell in cells
            if cell["cell_type"] == "markdown"
            for line in "".join(cell["source"]).splitlines()
            if re.match(r"#{2,6} ", line)
        ]
        link = r'<a href="#([^"]+)" class="md-nav__link">\s*<span class="md-ellipsis">'
        contents = re.findall(link + r"\s*(.*?)\s*</span>", text, flags=re.S)
        assert len({anchor for anchor, _ in contents}) == len(headings), notebook.name
        shown = [
            html.unescape(re.sub(r"<[^>]*>", " ", _MATH_ELEMENT.sub(" ", title))).split()
            for _, title in contents
        ]
        for heading in headings:
            words = re.sub(r"\$[^$]*\$", " ", heading).replace("`", " ").split()
            assert any(all(w in s for w in words) for s in shown), (notebook.name, heading)
            for code in re.findall(r"`([^`]+)`", heading):
                assert any(f"<code>{html.escape(code)}</code>" in t for _, t in contents), code


_CONFIG = re.compile(r'<script id="__config" type="application/json">(.*?)</script>', re.S)
_SCRIPT = re.compile(r'<script src="([^"]+)"')


def test_search_works_from_disk(site: Path) -> None:
    """Search works with the site opened from disk (``file://``), with nothing to download:
    every page has the search form; the theme's script reads the index from
    ``search/search_index.js`` (a script, which a file page may load, unlike JSON); the
    search worker it names is a file of the site, and the iframe-worker shim, a local
    script loaded before the theme's, starts it where a browser will not start a Worker
    from a file page. The index covers the pages in every part of the site, in English
    (no language script for the worker to import)."""
    for page in (site / "index.html", site / "api" / "so3.html", site / "design" / "index.html"):
        text = page.read_text(encoding="utf-8")
        assert '<form class="md-search__form" name="search">' in text, page
        match = _CONFIG.search(text)
        assert match, page
        config = json.loads(match.group(1))
        assert (page.parent / config["base"] / "search" / "search_index.js").is_file(), page
        assert (page.parent / config["search"]).is_file(), config["search"]
        scripts = _SCRIPT.findall(text)
        shim = [s for s in scripts if "iframe-worker" in s]
        bundle = [s for s in scripts if "/bundle." in s or s.startswith("bundle.")]
        assert len(shim) == 1 and len(bundle) == 1, scripts
        assert scripts.index(shim[0]) < scripts.index(bundle[0]), scripts
        assert not re.match(r"^([a-z][a-z0-9+.-]*:)?//", shim[0], re.I), shim
        code = (page.parent / shim[0]).read_text(encoding="utf-8")
        assert 'location.protocol==="file:"&&(window.Worker=' in code, shim
    prefix = "var __index = "
    script = (site / "search" / "search_index.js").read_text(encoding="utf-8")
    assert script.startswith(prefix)
    index = json.loads(script[len(prefix) :])
    assert index == json.loads((site / "search" / "search_index.json").read_text(encoding="utf-8"))
    assert index["config"]["lang"] == ["en"]
    located = {doc["location"].split("#")[0] for doc in index["docs"]}
    assert all((site / location).is_file() for location in located if location), located
    parts = ("quickstart", "api/so3", "notebooks/02_numerics", "design/index", "benchmarks/RESULTS")
    assert {f"{part}.html" for part in parts} <= located


def test_group_pages_list_members_in_one_order(site: Path) -> None:
    """The members every group has appear in the same order on every group's API page."""
    groups = ("SO2", "SE2", "SO3", "SE3", "Sim3", "SE23")
    members = {
        g: re.findall(
            rf'id="jaxlie_geo\.{g}\.(\w+)"', (site / "api" / f"{g.lower()}.html").read_text()
        )
        for g in groups
    }
    common = set.intersection(*(set(m) for m in members.values()))
    assert len(common) > 20
    orders = {g: [m for m in ms if m in common] for g, ms in members.items()}
    assert all(order == orders["SO3"] for order in orders.values()), orders


def _public() -> dict[str, object]:
    return {name: getattr(jaxlie_geo, name) for name in jaxlie_geo.__all__}


def _api_html(site: Path) -> str:
    return "\n".join(p.read_text(encoding="utf-8") for p in (site / "api").rglob("*.html"))


def test_site_builds_with_the_benchmark_results(site: Path) -> None:
    assert (site / "index.html").is_file()
    # benchmarks/RESULTS.md and its plot, added by docs/_hooks.py, not copied into docs/.
    assert (site / "benchmarks" / "RESULTS.html").is_file()
    assert (site / "benchmarks" / "results.png").is_file()
    assert not (DOCS / "benchmarks").exists()


def test_notebooks_are_pages_executed_at_build_time(site: Path) -> None:
    """Every notebook in ``notebooks/`` is a page of the site with the outputs of its
    execution during the build (figures included, no error), its Markdown maths as MathML
    and a link to its ``.ipynb``. The committed notebooks carry no outputs
    (``test_notebooks``), so every output here comes from the build."""
    notebooks = sorted((REPO / "notebooks").glob("*.ipynb"))
    assert notebooks
    for notebook in notebooks:
        page = site / "notebooks" / f"{notebook.stem}.html"
        text = page.read_text(encoding="utf-8")
        assert "data:image/png;base64," in text, f"{page.name}: no figure in the outputs"
        assert "jp-OutputArea-output" in text, f"{page.name}: no output"
        assert "Traceback" not in text and "jp-OutputArea-error" not in text, page.name
        assert (site / "notebooks" / notebook.name).is_file()
        assert f'href="{notebook.name}"' in text, f"{page.name}: no link to {notebook.name}"
        cells = _markdown_cells(text)
        prose = [re.sub(r"<(math|code|pre)\b.*?</\1>", "", c, flags=re.S) for c in cells]
        assert cells and not any("$" in c for c in prose), f"{page.name}: TeX left in the prose"
        assert "<math" in "".join(cells), f"{page.name}: no maths rendered"


def _hooks() -> types.ModuleType:
    """``docs/_hooks.py``, the site's build hooks, as a module."""
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "_hooks.py")
    assert spec is not None and spec.loader is not None
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    return hooks


def _markdown_cells(text: str) -> list[str]:
    """The body of every rendered Markdown cell of a notebook page, nested divs included."""
    return [text[start:end] for start, end in _hooks().markdown_cells(text)]


def test_notebook_maths_after_a_nested_block_is_rendered() -> None:
    """A Markdown cell whose code block renders as a nested ``div``: the maths on both sides
    of it becomes MathML, the code keeps its dollar signs, and text outside the cell is left
    as it is."""
    cell = (
        '<div class="jp-RenderedMarkdown"><p>Before: $x^2$.</p>'
        '<div class="highlight"><pre><code>cost = "$5"</code></pre></div>'
        "<p>After: $$\\theta$$ and $y$.</p></div><p>Outside: $1 and $2</p>"
    )
    out = _hooks()._notebook_content(cell, "notebooks/tour.ipynb")
    assert out.count("<math") == 3, out
    assert 'cost = "$5"' in out
    assert out.endswith("</div><p>Outside: $1 and $2</p>")


def test_notebook_contents_are_read_from_the_rendered_headings() -> None:
    """A notebook page's contents: one entry per heading, nested by level, each linking to
    the heading's id and showing its HTML, inline code included."""
    permalink = '<a class="headerlink" href="#{0}">¶</a>'
    page = "".join(
        f'<h{level} id="{anchor}">{title}{permalink.format(anchor)}</h{level}><p>text</p>'
        for level, anchor, title in [
            (1, "a-tour", "A tour of <code>jaxlie_geo</code>"),
            (2, "1-exp-and-log", "1. <code>exp</code> and <code>log</code>"),
            (3, "11-at-zero", "1.1 At zero"),
            (2, "2-next", "2. Next"),
        ]
    )
    (top,) = _hooks().notebook_toc(page)
    assert (top.id, top.title) == ("a-tour", "A tour of <code>jaxlie_geo</code>")
    first, second = top.children
    assert (first.url, first.title) == (
        "#1-exp-and-log",
        "1. <code>exp</code> and <code>log</code>",
    )
    assert [c.id for c in first.children] == ["11-at-zero"] and second.id == "2-next"


def test_every_public_module_has_its_own_api_page(site: Path) -> None:
    modules = [n for n, obj in _public().items() if isinstance(obj, types.ModuleType)]
    assert modules, "jaxlie_geo.__all__ lists no module"
    for name in modules:
        page = DOCS / "api" / f"{name}.md"
        assert page.is_file(), f"no API page docs/api/{name}.md for jaxlie_geo.{name}"
        assert f"::: jaxlie_geo.{name}" in page.read_text(encoding="utf-8"), page
        html = (site / "api" / f"{name}.html").read_text(encoding="utf-8")
        for member in getattr(jaxlie_geo, name).__all__:
            assert f'id="jaxlie_geo.{name}.{member}"' in html, f"jaxlie_geo.{name}.{member}"


def test_every_public_class_and_function_is_in_the_api_reference(site: Path) -> None:
    sources = "\n".join(p.read_text(encoding="utf-8") for p in (DOCS / "api").glob("*.md"))
    html = _api_html(site)
    for name, obj in _public().items():
        if isinstance(obj, types.ModuleType):
            continue
        assert re.search(rf"^::: jaxlie_geo\.{name}$", sources, re.M), f"jaxlie_geo.{name}"
        assert f'id="jaxlie_geo.{name}"' in html, f"jaxlie_geo.{name} not rendered"


@pytest.mark.parametrize("group", ["SO2", "SE2", "SO3", "SE3"])
def test_each_group_page_shows_every_public_method(site: Path, group: str) -> None:
    """Inherited and docstring-less overrides included (they take the base's docstring)."""
    html = (site / "api" / f"{group.lower()}.html").read_text(encoding="utf-8")
    cls = getattr(jaxlie_geo, group)
    names = [n for n in dir(cls) if not n.startswith("_")]
    missing = [n for n in names if f'id="jaxlie_geo.{group}.{n}"' not in html]
    assert not missing, f"{group} page lacks {missing}"


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_python_blocks_on_the_pages_run() -> None:
    """Each page's ```python blocks run as written, in order, in a fresh namespace (one
    process for all pages). A ```py block is shown, not run: it needs a package outside the
    extras (a library built on jaxlie), and what it shows is tested elsewhere."""
    pages = {
        str(p.relative_to(DOCS)): "\n".join(_python_blocks(p.read_text(encoding="utf-8")))
        for p in sorted(DOCS.rglob("*.md"))
        if p.parts[len(DOCS.parts)] != "design"
    }
    pages = {name: code for name, code in pages.items() if code}
    assert "quickstart.md" in pages
    runner = (
        "import sys, json\n"
        "for name, code in json.loads(sys.stdin.read()).items():\n"
        "    print('page', name, flush=True)\n"
        "    exec(compile(code, name, 'exec'), {'__name__': '__main__'})\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", runner],
        input=json.dumps(pages),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]


def test_readme_links_resolve() -> None:
    """README.md is not part of the site, so its relative links are checked here."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)\s]+)\)", text)
    local = [t.split("#", 1)[0] for t in targets if not re.match(r"^[a-z]+:", t)]
    assert local
    missing = [t for t in local if t and not (REPO / t).exists()]
    assert not missing, f"README.md links to missing files: {missing}"


def test_results_page_is_generated_from_the_raw_results() -> None:
    """benchmarks/RESULTS.md is exactly what ``python -m benchmarks.report`` renders from
    benchmarks/raw/: nobody edits the page by hand, and a new raw result regenerates it."""
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks.report", "--check"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_results_page_names_the_files_of_a_modified_tree() -> None:
    """A run measured on a tree with uncommitted changes is shown as such, with the files
    that differed where the run recorded them, never as a bare ``-dirty`` commit."""
    from benchmarks import report

    assert report._commit({"commit": "abc1234"}) == "abc1234"
    assert report._commit({"commit": "abc1234-dirty", "dirty_files": ["a.py", "b.py"]}) == (
        "abc1234 with uncommitted changes (`a.py`, `b.py`)"
    )
    assert "files not recorded" in report._commit({"commit": "abc1234-dirty"})
    assert "-dirty" not in (REPO / "benchmarks" / "RESULTS.md").read_text(encoding="utf-8")
