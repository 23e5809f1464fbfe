"""Build the web edition of the book into ``site/`` (open ``site/index.html``), then check its links.

    python tools/build_site.py                 # build site/ and check every internal link
    python tools/build_site.py --check-only    # check the links of an existing site/

The site is built from the committed notebooks and their stored outputs: nothing is executed. The
pages are generated into a temporary folder and built there by Sphinx (myst-nb, sphinx-book-theme;
configuration in ``docs/site/conf.py``), strictly (``-W --keep-going``: any warning fails the build):

- ``index``: README.md, whose links to the chapters lead to their pages;
- one page per chapter (``book/*.ipynb``) and per exercise notebook (``exercises/*.ipynb``), in the
  README table's order; under each title: the table's one-line summary, a link to the notebook file
  and how to run it (the README's set-up command, then ``jupyter lab``); before each widget cell (a
  cell starting ``# NBVAL_IGNORE_OUTPUT`` that displays ipywidgets) a "Live in Jupyter" note, and the
  widget's output (a view that needs a kernel) left out: its static twin is the figure beside it;
- ``cli``: each sub-command's ``--help``, produced now by the command's own parser;
- ``library``: CONTRIBUTING.md's layout map (included from that file) and the API, from the
  docstrings, of every library module the chapters import (found by reading their code cells).

The link check opens every built HTML file and resolves every relative ``href`` and ``src`` (the file
must exist, and a ``#fragment`` must be an ``id`` in the target page); a script, style sheet or image
loaded from another host fails it too, since the site must work without a network.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import html.parser
import importlib
import io
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import unquote, urlsplit

import nbformat

ROOT = Path(__file__).resolve().parents[1]
CONF_DIR = ROOT / "docs" / "site"
SITE = ROOT / "site"
PACKAGE = "ibc_tutorial"

API_EXTRA: list[str] = []
"""Modules to document on the library page although no chapter imports them."""
API_EXCLUDE: list[str] = []
"""Modules a chapter imports that the library page leaves out."""

WIDGET_MIME = "application/vnd.jupyter.widget-view+json"
IGNORE_MARK = "# NBVAL_IGNORE_OUTPUT"


# -- what the README says -------------------------------------------------------------------------------


def chapter_summaries(readme: str) -> dict[str, tuple[str, str]]:
    """``{"book/01_the_tree.ipynb": (title, summary)}`` from the README's chapter table, in its order."""
    rows = {}
    for line in readme.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 3:
            continue
        link = re.fullmatch(r"\[(.+?)\]\((book/[^)]+\.ipynb)\)", cells[1])
        if link:
            rows[link.group(2)] = (link.group(1), cells[2])
    return rows


def setup_command(readme: str) -> str:
    """The README's set-up command: the first line of a shell block that installs the lock file."""
    for block in re.findall(r"```bash\n(.*?)```", readme, re.S):
        for line in block.splitlines():
            if "pip install" in line and "environment.lock" in line:
                return line.split("  #")[0].strip()
    raise SystemExit("README.md: no shell block with the set-up command (pip install -r environment.lock)")


# -- the pages ----------------------------------------------------------------------------------------


def run_note(nb_path: str, srcdir: Path, setup: str, kind: str) -> str:
    """What a static page cannot do, said on the page: how to run it, and the notebook file."""
    install = setup.split("&&")[0].strip()
    lab = "jupyter lab"
    rel = os.path.relpath(ROOT / nb_path, (srcdir / nb_path).parent)  # the original, from the page's folder
    return (
        f":::{{admonition}} Run this {kind}\n:class: tip\n\n"
        f"This page shows the outputs stored in the notebook: it runs nothing, and its widgets are "
        f"static pictures. To run the {kind}, change it or move a slider, install the book once "
        f"(in a fresh virtual environment, from the repository's root) and open JupyterLab:\n\n"
        f"```bash\n{install}\n{lab}\n```\n\n"
        f"then open `{nb_path}` in JupyterLab. The notebook file: {{download}}`{nb_path} <{rel}>`.\n"
        f":::\n"
    )


WIDGET_NOTE = (
    ":::{admonition} Live in Jupyter\n:class: important\n\n"
    "The next cell displays an interactive explorer (ipywidgets): it needs a running kernel, so this page "
    "shows the cell without it. Its static twin, the same picture at fixed settings, is the figure beside "
    "it. Run the notebook in JupyterLab (see above) to use the explorer.\n:::\n"
)


def is_widget_cell(cell) -> bool:
    """A cell that displays an ipywidgets explorer: marked ``# NBVAL_IGNORE_OUTPUT``, a widget view output."""
    if cell.cell_type != "code" or not cell.source.lstrip().startswith(IGNORE_MARK):
        return False
    return any(WIDGET_MIME in out.get("data", {}) for out in cell.get("outputs", []))


def insert_after_title(nb, text: str) -> None:
    """Put ``text`` right under the notebook's title (its first level-1 heading)."""
    for cell in nb.cells:
        if cell.cell_type != "markdown":
            continue
        lines = cell.source.splitlines()
        for i, line in enumerate(lines):
            if line.startswith("# "):
                cell.source = "\n".join(lines[: i + 1] + ["", text, ""] + lines[i + 1 :])
                return
    raise SystemExit(f"{nb.metadata.get('_site_path')}: no level-1 heading (# Title) to put the notes under")


LONG_CELL = 40
"""A code cell of more source lines than this shows collapsed on its page (its outputs stay in view)."""
EXERCISE_PATH = re.compile(r"`(exercises/[\w.-]+\.ipynb)`")


def title_first(nb) -> None:
    """The page opens with its title: the set-up code cells (those before the title's cell, and an import
    cell right after it) follow the title, collapsed with their output (myst-nb's ``hide-cell`` tag)."""
    index = next(
        (
            i
            for i, c in enumerate(nb.cells)
            if c.cell_type == "markdown" and any(line.startswith("# ") for line in c.source.splitlines())
        ),
        None,
    )
    if index is None:
        return  # insert_after_title has already said what is missing
    setup = [c for c in nb.cells[:index] if c.cell_type == "code"]
    rest = [c for c in nb.cells[:index] if c.cell_type != "code"]
    title = nb.cells[index]
    after = nb.cells[index + 1 :]
    if not setup and after and after[0].cell_type == "code" and after[0].source.lstrip().startswith("import"):
        setup, after = [after[0]], after[1:]
    for cell in setup:
        _tag(cell, "hide-cell")
    nb.cells = [*rest, title, *setup, *after]


def _tag(cell, tag: str) -> None:
    tags = cell.metadata.setdefault("tags", [])
    if tag not in tags:
        tags.append(tag)


def page_notebook(src: Path, dest: Path, nb_path: str, header: str) -> int:
    """Copy a notebook as a page: the title first, the notes added, set-up and long code cells collapsed,
    exercise notebooks' paths made links, widget views left out. Returns its widget cells."""
    nb = nbformat.read(src, as_version=4)
    nb.metadata["_site_path"] = nb_path
    insert_after_title(nb, header)
    del nb.metadata["_site_path"]
    title_first(nb)
    depth = "../" * nb_path.count("/")
    for cell in nb.cells:
        if cell.cell_type == "code" and len(cell.source.splitlines()) > LONG_CELL:
            if "hide-cell" not in cell.metadata.get("tags", []):
                _tag(cell, "hide-input")
        elif cell.cell_type == "markdown":
            cell.source = EXERCISE_PATH.sub(lambda m: f"[{m.group(1)}]({depth}{m.group(1)})", cell.source)
    cells, widgets = [], 0
    for cell in nb.cells:
        if is_widget_cell(cell):
            widgets += 1
            cells.append(nbformat.v4.new_markdown_cell(WIDGET_NOTE))
            cell.outputs = [out for out in cell.outputs if WIDGET_MIME not in out.get("data", {})]
        cells.append(cell)
    nb.cells = cells
    nb.metadata.pop("widgets", None)
    dest.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, dest)
    return widgets


def notebook_order(folder: str, summaries: dict[str, tuple[str, str]]) -> list[str]:
    """The folder's notebooks: the README table's order, then any it does not list, by name."""
    found = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / folder).glob("*.ipynb"))
    listed = [p.replace("book/", f"{folder}/", 1) for p in summaries]
    return [p for p in listed if p in found] + [p for p in found if p not in listed]


def landing_page(readme: str, chapters: list[str], exercises: list[str], docs: list[str]) -> str:
    """README.md as the landing page, with the site's navigation (chapters, exercises, reference)."""
    text = readme.replace("](CONTRIBUTING.md)", "](library.md)")
    stems = [p.removesuffix(".ipynb") for p in chapters]
    toc = "\n".join(
        [
            "```{toctree}\n:hidden:\n:caption: Chapters\n\n" + "\n".join(stems) + "\n```",
            "```{toctree}\n:hidden:\n:caption: Exercises\n\n"
            + "\n".join(p.removesuffix(".ipynb") for p in exercises)
            + "\n```",
            "```{toctree}\n:hidden:\n:caption: Reference\n\ncli\nlibrary\n"
            + "".join(d.removesuffix(".md") + "\n" for d in docs)
            + "```",
        ]
    )
    return text.rstrip() + "\n\n" + toc + "\n"


def cli_page() -> str:
    """Every sub-command's ``--help``, as ``ibc-tutorial COMMAND --help`` prints it now."""
    from ibc_tutorial import cli

    def help_of(argv: list[str]) -> str:
        out = io.StringIO()
        columns = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = "80"  # argparse's width: the page's code column, whatever the terminal
        try:
            with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
                cli.main(argv)
        finally:
            if columns is None:
                del os.environ["COLUMNS"]
            else:
                os.environ["COLUMNS"] = columns
        text = out.getvalue().rstrip()
        if not text.startswith("usage:"):
            raise SystemExit(f"ibc-tutorial {' '.join(argv)} printed no usage:\n{text}")
        return text

    parts = [
        "# The command line\n",
        "Work too heavy for a notebook runs from the `ibc-tutorial` command, installed with the book "
        "(see the [landing page](index.md) for examples). Each sub-command's help below is the output of "
        "`ibc-tutorial COMMAND --help`, produced when this site was built.\n",
        "```text\n$ ibc-tutorial --help\n" + help_of(["--help"]) + "\n```\n",
    ]
    for name in cli.SUBCOMMANDS:
        parts.append(f"## `{name}`\n")
        parts.append(f"```text\n$ ibc-tutorial {name} --help\n" + help_of([name, "--help"]) + "\n```\n")
    return "\n".join(parts)


def imported_modules(notebooks: list[Path]) -> list[str]:
    """The library modules the notebooks' code cells import: for ``from M import x``, the module x is,
    or the module that defines x; for ``import M``, M."""
    found: set[str] = set()
    for path in notebooks:
        for cell in nbformat.read(path, as_version=4).cells:
            if cell.cell_type != "code":
                continue
            source = "\n".join(
                line for line in cell.source.splitlines() if not line.lstrip().startswith(("%", "!"))
            )
            try:
                tree = ast.parse(source)
            except SyntaxError:
                continue
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    found.update(a.name for a in node.names if a.name.split(".")[0] == PACKAGE)
                elif (
                    isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == PACKAGE
                ):
                    for alias in node.names:
                        found.add(_defining_module(node.module, alias.name))
    return sorted((found | set(API_EXTRA)) - set(API_EXCLUDE))


def _defining_module(module: str, name: str) -> str:
    with contextlib.suppress(ImportError):
        return importlib.import_module(f"{module}.{name}").__name__
    obj = getattr(importlib.import_module(module), name, None)
    owner = getattr(obj, "__module__", None)
    return owner if isinstance(owner, str) and owner.split(".")[0] == PACKAGE else module


def library_page(modules: list[str], srcdir: Path) -> str:
    """CONTRIBUTING.md's layout map (included, not copied) and the modules' API."""
    contributing = os.path.relpath(ROOT / "CONTRIBUTING.md", srcdir)
    text = (ROOT / "CONTRIBUTING.md").read_text()
    start, end = "## Layout (one concern per module)", "**Conventions the whole book shares.**"
    if start not in text or end not in text:
        raise SystemExit(f"CONTRIBUTING.md: the layout map between {start!r} and {end!r} is not there")
    parts = [
        "# The library\n",
        "`src/ibc_tutorial/` holds everything the chapters rely on, tested in `tests/`. Below: the map of "
        "its modules from CONTRIBUTING.md, then the API of every module the chapters import, from the "
        "docstrings.\n",
        f'```{{include}} {contributing}\n:start-after: "{start}"\n:end-before: "{end}"\n```\n',
        "## API of the modules the chapters import\n",
        "Found by reading the chapters' code cells (`import` and `from ... import`); each module's own "
        "members, in the order of its source.\n",
    ]
    for name in modules:
        shadowed = _shadowed(name, modules)
        options = f"   :exclude-members: {', '.join(shadowed)}\n" if shadowed else ""
        parts.append(f"### `{name}`\n\n```{{eval-rst}}\n.. automodule:: {name}\n{options}```\n")
    return "\n".join(parts)


def _shadowed(name: str, modules: list[str]) -> list[str]:
    """The documented submodules of package ``name``, by their last name: a member of the package named like
    one (``driving`` re-exports the function ``rollout`` of its module ``driving.rollout``) would be described
    as ``name.x`` twice, so it is left to its own module's section."""
    prefix = name + "."
    return sorted(m[len(prefix) :] for m in modules if m.startswith(prefix) and "." not in m[len(prefix) :])


def generate(srcdir: Path) -> dict[str, int]:
    """Write every page into ``srcdir``; returns what was generated, counted."""
    readme = (ROOT / "README.md").read_text()
    summaries = chapter_summaries(readme)
    setup = setup_command(readme)
    chapters = notebook_order("book", summaries)
    exercises = notebook_order("exercises", summaries)
    if not chapters:
        raise SystemExit("book/ holds no notebook")
    widgets = 0
    for nb_path in chapters:
        title, summary = summaries.get(nb_path, ("", ""))
        head = f":::{{admonition}} In this chapter\n:class: note\n\n{summary}\n:::\n\n" if summary else ""
        header = head + run_note(nb_path, srcdir, setup, "chapter")
        widgets += page_notebook(ROOT / nb_path, srcdir / nb_path, nb_path, header)
    for nb_path in exercises:
        chapter = nb_path.replace("exercises/", "book/", 1)
        title = summaries.get(chapter, ("", ""))[0]
        head = (
            f":::{{admonition}} Exercises of chapter {chapter[5:7]}\n:class: note\n\n"
            f"The exercises of [{chapter[5:7]} · {title}](../{chapter}). "
            'Each exercise cell ends with a checker that answers "not attempted", "correct", or a hint '
            "naming what is wrong; this page shows the notebook as stored, its stubs unanswered.\n:::\n\n"
            if (ROOT / chapter).exists()
            else ""
        )
        widgets += page_notebook(
            ROOT / nb_path, srcdir / nb_path, nb_path, head + run_note(nb_path, srcdir, setup, "notebook")
        )
    figures = ROOT / "book" / "figures"
    if figures.is_dir():
        shutil.copytree(figures, srcdir / "book" / "figures")
    docs = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))
    for doc in docs:  # docs/design.md: the chapters link to it
        (srcdir / doc).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / doc, srcdir / doc)
    (srcdir / "index.md").write_text(landing_page(readme, chapters, exercises, docs))
    (srcdir / "cli.md").write_text(cli_page())
    modules = imported_modules([ROOT / p for p in chapters])
    (srcdir / "library.md").write_text(library_page(modules, srcdir))
    return {
        "chapters": len(chapters),
        "exercises": len(exercises),
        "widget cells": widgets,
        "modules": len(modules),
    }


# -- the link check ---------------------------------------------------------------------------------


class _Links(html.parser.HTMLParser):
    """The ids of a page and the links it holds: (tag, attribute, value)."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.links: list[tuple[str, str, str]] = []

    def handle_starttag(self, tag, attrs):
        for key, value in attrs:
            if key in ("id", "name") and value and (key == "id" or tag == "a"):
                self.ids.add(value)
            if key in ("href", "src") and value is not None:
                self.links.append((tag, key, value))


def check_links(site: Path) -> tuple[int, list[str]]:
    """Resolve every relative href/src of every HTML page of ``site``; returns (links checked, problems)."""
    pages: dict[Path, _Links] = {}
    for path in sorted(site.rglob("*.html")):
        if path.relative_to(site).parts[0] == "_static":
            continue  # the theme's template files (Jinja), copied as they are, never pages
        parser = _Links()
        parser.feed(path.read_text(errors="replace"))
        pages[path.resolve()] = parser
    checked, problems = 0, []
    for page, parsed in pages.items():
        where = page.relative_to(site.resolve())
        for tag, attr, value in parsed.links:
            url = urlsplit(value.strip())
            if url.scheme in ("mailto", "javascript", "data"):
                continue
            if url.scheme or url.netloc:
                if tag in ("script", "img", "link", "iframe", "source") and not (
                    tag == "link" and attr == "href" and "stylesheet" not in value
                ):
                    problems.append(f"{where}: <{tag} {attr}={value!r}> loads from another host")
                continue
            checked += 1
            target = page if not url.path else (page.parent / unquote(url.path)).resolve()
            if target.is_dir():
                target = target / "index.html"
            if not target.is_file():
                problems.append(f"{where}: <{tag} {attr}={value!r}>: {target} does not exist")
                continue
            fragment = unquote(url.fragment)
            if fragment and target.suffix == ".html":
                ids = pages[target].ids if target in pages else set()
                if fragment not in ids:
                    problems.append(f"{where}: <{tag} {attr}={value!r}>: no id {fragment!r} in {target.name}")
    return checked, problems


def run_link_check(site: Path) -> None:
    start = time.perf_counter()
    checked, problems = check_links(site)
    for problem in problems:
        print("BROKEN LINK:", problem, file=sys.stderr)
    pages = sum(1 for p in site.rglob("*.html") if p.relative_to(site).parts[0] != "_static")
    print(
        f"link check: {checked} internal links in {pages} pages, {len(problems)} broken "
        f"({time.perf_counter() - start:.1f} s)"
    )
    if problems:
        raise SystemExit(1)


# -- main -------------------------------------------------------------------------------------------


def build(out: Path, jobs: str) -> None:
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="ibc-site-") as tmp:
        srcdir, doctrees = Path(tmp) / "src", Path(tmp) / "doctrees"
        srcdir.mkdir()
        counts = generate(srcdir)
        print(
            "generated:",
            ", ".join(f"{v} {k}" for k, v in counts.items()),
            f"({time.perf_counter() - start:.1f} s)",
        )
        # built inside the temporary folder: myst-nb writes its notebook copies beside the output folder
        staging = Path(tmp) / "html"
        command = [
            sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q", "-j", jobs,
            "-c", str(CONF_DIR), "-d", str(doctrees), str(srcdir), str(staging),
        ]  # fmt: skip
        result = subprocess.run(command, cwd=ROOT)
        if result.returncode:
            raise SystemExit(f"sphinx-build failed (exit code {result.returncode}); site/ left as it was")
        shutil.rmtree(out, ignore_errors=True)
        shutil.copytree(staging, out)  # the new site replaces the old one whole
    print(f"built {out} in {time.perf_counter() - start:.1f} s")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=SITE, help="where to write the site (default: site/)")
    parser.add_argument("--check-only", action="store_true", help="only check the links of an existing site")
    parser.add_argument("-j", "--jobs", default="auto", help="Sphinx's parallel jobs (default: auto)")
    args = parser.parse_args(argv)
    out = args.out.resolve()
    if not args.check_only:
        build(out, args.jobs)
    if not (out / "index.html").is_file():
        raise SystemExit(
            f"{out}/index.html does not exist: build the site first (python tools/build_site.py)"
        )
    run_link_check(out)
    print(f"open {out / 'index.html'} in a browser (or: python -m http.server -d {out} 8000)")


if __name__ == "__main__":
    os.environ.setdefault("TQDM_DISABLE", "1")
    main()
