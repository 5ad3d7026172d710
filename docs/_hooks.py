"""MkDocs hooks: the maths rendered at build time, and the benchmark pages from
``benchmarks/`` published without copying them.

``pymdownx.arithmatex`` (generic mode) leaves each formula as TeX in a ``span`` (inline,
``\\( … \\)``) or ``div`` (display, ``\\[ … \\]``) of class ``arithmatex``.
``on_page_content`` replaces it by MathML from ``latex2mathml``, which browsers render
natively: the pages need no script, font or network to show their formulas, also when
opened from disk. A formula that does not convert fails the build, naming the page.

The notebooks in ``notebooks/`` are added the same way, as ``notebooks/<name>.ipynb``, before
``mkdocs-jupyter`` (which executes and renders them) looks at the files. Their Markdown cells
keep TeX between ``$ … $`` and ``$$ … $$``, and the notebook template loads MathJax from a
CDN (and Mermaid, for diagrams); ``on_page_content`` removes those scripts and renders the
formulas as MathML too, and gives the page a table of contents read from its rendered
headings.

The benchmark scripts generate ``benchmarks/RESULTS.md``, with its plot
``benchmarks/results.png`` beside it. ``on_files`` adds every Markdown and PNG file under
``benchmarks/`` to the site at the same relative path: ``benchmarks/RESULTS.md`` is the
"Benchmark results" page of the nav and ``benchmarks/README.md`` "How the benchmarks run";
any other Markdown file there is published too, reachable by link but kept out of the nav.

Those pages are written for the repository, so they may link to files that are not part of
the site (``../jaxlie_geo/_so3.py``) or reach the site's pages through ``../docs/``.
``on_page_markdown`` points the second kind at the page's place in the site and turns the
first into its text followed by the repository path in code, so a strict build fails only on
the site's own pages.
"""

from __future__ import annotations

import html
import posixpath
import re
from pathlib import Path

from latex2mathml.converter import convert
from mkdocs.exceptions import PluginError
from mkdocs.plugins import event_priority
from mkdocs.structure.files import File, Files, InclusionLevel
from mkdocs.structure.toc import TableOfContents, get_toc

SOURCE = "benchmarks"
NOTEBOOKS = "notebooks"
IN_NAV = {"benchmarks/RESULTS.md", "benchmarks/README.md"}
SUFFIXES = {".md", ".png"}

# [text](target) and ![alt](target), with an optional "title"; target without spaces.
_LINK = re.compile(r"(!?)\[([^\]\n]*)\]\(([^)\s]+)(\s+\"[^\"]*\")?\)")


# arithmatex's generic output: the formula, HTML-escaped, inside its delimiters.
_MATH = re.compile(r'<(span|div) class="arithmatex">\s*\\([(\[])(.*?)\\[)\]]\s*</\1>', re.DOTALL)


# latex2mathml writes a command it does not know as text (<mi>\arg</mi>, <mo>\|</mo> after
# \big) and an \operatorname it cannot read as an empty <mo />.
_UNRENDERED = re.compile(r">[^<]*\\|<mo\s*/>")


def to_mathml(tex: str, display: str, where: str) -> str:
    """``tex`` as a MathML element (``display`` "inline" or "block"); a formula that
    latex2mathml rejects, or one with a command it would leave as text, raises
    ``PluginError`` naming ``where``."""
    try:
        math = convert(tex, display=display)
    except Exception as error:  # latex2mathml raises its own exceptions for unknown TeX
        raise PluginError(f"{where}: cannot render {tex!r} as MathML: {error}") from error
    if _UNRENDERED.search(math):
        raise PluginError(f"{where}: {tex!r} has a command MathML cannot show: {math}")
    return math


def _mathml(match: re.Match, where: str) -> str:
    tag, opening, tex = match.groups()
    display = "block" if opening == "[" else "inline"
    math = to_mathml(html.unescape(tex).strip(), display, where)
    return f'<{tag} class="arithmatex">{math}</{tag}>'


# A notebook's rendered Markdown cell (its opening tag; the cell ends at the matching
# </div>), and the TeX in it: $$ … $$ (display) or $ … $ (inline).
_MARKDOWN_CELL = re.compile(r'<div class="[^"]*jp-RenderedMarkdown[^"]*"[^>]*>')
_DIV_TAG = re.compile(r"<div\b|</div>")
_NOTEBOOK_MATH = re.compile(r"\$\$(.+?)\$\$|(?<![\\$])\$(?!\s)([^$]+?)(?<!\s)\$", re.DOTALL)
# The notebook template's scripts that would load from a CDN: MathJax (its tag and its
# configuration) and the Mermaid loader (the notebooks draw no Mermaid diagrams).
_REMOTE_SCRIPTS = re.compile(
    r"<!-- Load mathjax -->.*?<!-- End of mathjax configuration -->"
    r'|<script type="module">(?:(?!</script>).)*?mermaid(?:(?!</script>).)*?</script>',
    re.DOTALL | re.IGNORECASE,
)


def _notebook_mathml(match: re.Match, where: str) -> str:
    display, inline = match.groups()
    tex = html.unescape(display if display is not None else inline).strip()
    return to_mathml(tex, "block" if display is not None else "inline", where)


def _notebook_content(content: str, where: str) -> str:
    content = _REMOTE_SCRIPTS.sub("", content)
    # nbconvert's heading permalinks as the theme's, which it shows on hover and the search
    # index leaves out of the section titles.
    content = content.replace('<a class="anchor-link" href="#', '<a class="headerlink" href="#')
    name = posixpath.basename(where)
    content = (
        f'<p><em>The notebook: <a href="{name}"><code>{name}</code></a>. This page shows it as '
        "executed when the site was built.</em></p>\n" + content
    )

    def render(body: str) -> str:
        parts = re.split(r"(<pre.*?</pre>|<code.*?</code>)", body, flags=re.DOTALL)
        parts[::2] = [
            _NOTEBOOK_MATH.sub(lambda m: _notebook_mathml(m, where), t) for t in parts[::2]
        ]
        return "".join(parts)

    out, done = [], 0
    for start, end in markdown_cells(content):
        out += [content[done:start], render(content[start:end])]
        done = end
    return "".join(out) + content[done:]


def markdown_cells(content: str) -> list[tuple[int, int]]:
    """Where the body of each rendered Markdown cell of a notebook page lies in ``content``:
    ``(start, end)``, from its opening tag to the matching ``</div>``, nested divs included;
    a cell inside another is part of the outer one."""
    spans: list[tuple[int, int]] = []
    for opening in _MARKDOWN_CELL.finditer(content):
        if spans and opening.start() < spans[-1][1]:
            continue
        depth, end = 1, len(content)
        for tag in _DIV_TAG.finditer(content, opening.end()):
            depth += 1 if tag.group(0) == "<div" else -1
            if depth == 0:
                end = tag.start()
                break
        spans.append((opening.end(), end))
    return spans


# A heading of a notebook page: its id, its HTML and its permalink (nbconvert's, with the
# theme's class).
_NOTEBOOK_HEADING = re.compile(
    r'<h([1-6]) id="([^"]+)">(.*?)<a class="headerlink" href="#\2">¶</a></h\1>', re.DOTALL
)


def notebook_toc(content: str) -> TableOfContents:
    """The table of contents of a rendered notebook page, read from its headings: each
    entry links to the heading's own id and shows its HTML (inline code and maths kept)."""
    tokens: list = []
    stack: list = []
    for level, anchor, title in _NOTEBOOK_HEADING.findall(content):
        token = {"level": int(level), "id": anchor, "name": title.strip(), "children": []}
        while stack and stack[-1]["level"] >= token["level"]:
            stack.pop()
        (stack[-1]["children"] if stack else tokens).append(token)
        stack.append(token)
    return get_toc(tokens)


def on_page_content(content: str, page, config, files: Files) -> str:
    if page.file.src_uri.endswith(".ipynb"):
        content = _notebook_content(content, page.file.src_uri)
    content = _MATH.sub(lambda m: _mathml(m, page.file.src_uri), content)
    if page.file.src_uri.endswith(".ipynb"):
        # mkdocs-jupyter's own contents read the Markdown without its inline code, so
        # their titles lose it and their links name ids the page does not have.
        page.toc = notebook_toc(content)
    return content


def _root(config) -> Path:
    return Path(config["config_file_path"]).resolve().parent


@event_priority(100)  # before mkdocs-jupyter's, which turns the notebooks into pages
def on_files(files: Files, config) -> Files:
    root = _root(config)
    # A file under the repository root (not generated): mkdocs-jupyter's wrapper reads the
    # source path from it.
    for path in sorted((root / NOTEBOOKS).glob("*.ipynb")):
        src = path.relative_to(root).as_posix()
        files.append(File(src, str(root), config["site_dir"], config["use_directory_urls"]))
    for path in sorted((root / SOURCE).rglob("*")):
        if not path.is_file() or path.suffix not in SUFFIXES:
            continue
        src_uri = path.relative_to(root).as_posix()
        if files.get_file_from_path(src_uri) is not None:
            continue
        file = File.generated(config, src_uri, abs_src_path=str(path))
        if path.suffix == ".md" and src_uri not in IN_NAV:
            file.inclusion = InclusionLevel.NOT_IN_NAV
        files.append(file)
    return files


def on_page_markdown(markdown: str, page, config, files: Files) -> str:
    src_uri = page.file.src_uri
    if not src_uri.startswith(SOURCE + "/"):
        return markdown
    here = posixpath.dirname(src_uri)
    docs = Path(config["docs_dir"]).resolve().relative_to(_root(config)).as_posix()

    def fix(match: re.Match) -> str:
        bang, text, target, title = match.groups()
        if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith(("#", "/")):
            return match.group(0)
        path, hash_, anchor = target.partition("#")
        resolved = posixpath.normpath(posixpath.join(here, path)) if path else src_uri
        if files.get_file_from_path(resolved) is not None:
            return match.group(0)
        # A link into docs/ from outside it (../docs/design/x.md): the page's place in the site.
        if resolved.startswith(docs + "/") and files.get_file_from_path(resolved[len(docs) + 1 :]):
            relative = posixpath.relpath(resolved[len(docs) + 1 :], here)
            return f"{bang}[{text}]({relative}{hash_}{anchor}{title or ''})"
        label = text or posixpath.basename(resolved)
        shown = resolved if not resolved.startswith("../") else path
        return label if label == f"`{shown}`" else f"{label} (`{shown}`)"

    return _LINK.sub(fix, markdown)
