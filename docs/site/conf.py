"""Sphinx configuration of the web edition (built by ``python tools/build_site.py``, never by hand).

The build script generates the pages (the landing page from README.md, the chapters and exercises
copied from the committed notebooks with notes added, the command-line and library pages) into a
temporary source folder and runs ``sphinx-build -c docs/site``: this file is the configuration of that
build, ``_static/`` its style sheet. Notebooks are never executed: every output is the one stored.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

from sphinx.util.fileutil import copy_asset

import ibc_tutorial

project = "ibc-tutorial"
author = "the ibc-tutorial authors"
copyright = "the ibc-tutorial authors"
release = ibc_tutorial.__version__
version = release

extensions = [
    "myst_nb",  # notebooks and Markdown (registers myst_parser)
    "sphinx.ext.autodoc",  # the library page's API, from the docstrings
    "sphinx.ext.napoleon",  # the library's docstrings are Google style (Args:, Returns:, Raises:)
    "sphinx.ext.mathjax",
]
# MathJax 3 served by the site itself (the files of the sphinx-mathjax-offline package, copied by
# ``setup`` below), so that equations render with no network
mathjax_path = "mathjax/tex-chtml.js"

# -- notebooks: the stored outputs, never re-executed ------------------------------------------------
nb_execution_mode = "off"
nb_merge_streams = True  # a cell's consecutive prints as one block, as JupyterLab shows them
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
myst_heading_anchors = 3
myst_dmath_double_inline = True

# -- the library page --------------------------------------------------------------------------------
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "description"
autodoc_class_signature = "separated"
autodoc_preserve_defaults = True
autodoc_inherit_docstrings = False  # a method without a docstring shows no other package's text
napoleon_google_docstring = True
napoleon_numpy_docstring = False

# -- HTML ------------------------------------------------------------------------------------------
html_theme = "sphinx_book_theme"
html_title = "ibc-tutorial"
html_static_path = ["_static"]
templates_path = ["_templates"]  # article-header-nosearch.html
html_favicon = "_static/favicon.svg"  # without one the browser asks for /favicon.ico, a 404
html_context = {"default_mode": "light"}  # unset, the theme logs "invalid theme mode" on a first visit
html_css_files = ["site.css"]
html_copy_source = False  # the notebook files are linked from each page (the original, not a copy)
html_show_sourcelink = False
html_last_updated_fmt = None
html_theme_options = {
    "use_download_button": False,
    "use_fullscreen_button": False,
    "show_toc_level": 2,
    "home_page_in_toc": True,
    # one search box: the primary sidebar's field; the article header keeps its other buttons
    "article_header_end": ["article-header-nosearch.html"],
    "navbar_persistent": [],  # the top bar's search field (the theme's default) would be a second one
}


# -- the two additions the build needs --------------------------------------------------------------

_SUBSTITUTION = re.compile(r"(?<!\\)\|(?=[^|\s`][^|`]*\|)")


def _escape_bars(app, what, name, obj, options, lines):
    """``|x|`` in a docstring is an absolute value, not a reStructuredText substitution."""
    lines[:] = [_SUBSTITUTION.sub(r"\\|", line) for line in lines]


def _copy_mathjax(app, exception):
    if exception is None and app.builder.format == "html":
        spec = importlib.util.find_spec("sphinx-mathjax-offline")
        if spec is None or not spec.submodule_search_locations:
            raise RuntimeError("the docs extra is not installed: sphinx-mathjax-offline (MathJax's files)")
        source = Path(next(iter(spec.submodule_search_locations))) / "static" / "mathjax"
        copy_asset(str(source), str(Path(app.outdir) / "_static" / "mathjax"))


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars)
    app.connect("build-finished", _copy_mathjax)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
