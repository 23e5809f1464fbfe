"""The web edition as a reader sees it: pages of ``site/`` opened in headless Chromium.

Needs the built site (``python tools/build_site.py``), Debian's ``chromium`` and ``chromium-driver``
(``apt-get install -y chromium chromium-driver``) and selenium (the ``docs`` extra). Without them the
test is skipped with the reason, unless ``IBC_TUTORIAL_SITE_TEST=1`` (as CI sets it): then it fails.

``site/`` is served on 127.0.0.1 by a thread of this process; the browser reaches nothing else. Each
page is checked for: every image loaded (natural width > 0), the equations typeset by MathJax (no
raw ``$$``, ``\\(`` or ``\\[`` left in the visible text, MathJax's output elements present where the
page has math), no console errors, and on chapter pages a "Live in Jupyter" note before each widget
cell of the notebook. Every chapter page is read at a laptop's width (1,280 px): its title comes before its
first code cell; no figure is drawn at less than 60 % of its natural width unless it stays at least 700 px
wide; at most ``MAX_OVERFLOWING`` code or output blocks scroll sideways; one search box is in view.
Screenshots go to a temporary folder (printed; ``IBC_TUTORIAL_SCREENSHOTS`` chooses it).
"""

from __future__ import annotations

import functools
import http.server
import json
import os
import shutil
import tempfile
import threading
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "site"
CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
WIDGET_MIME = "application/vnd.jupyter.widget-view+json"

# the landing page, every chapter and one exercise page; found by number, not by full name
CHAPTERS = sorted(p.stem for p in (ROOT / "book").glob("[0-9][0-9]_*.ipynb"))
PAGES = ["index.html", *(f"book/{c[:2]}_*.html" for c in CHAPTERS), "exercises/03_*.html"]
WIDTH = 1280
"""The browser window's width, px: the narrow end of a laptop's."""
MIN_SCALE, MIN_WIDE = 0.6, 700
"""A figure drawn at less than MIN_SCALE of its natural width must stay at least MIN_WIDE px wide."""
MAX_OVERFLOWING = 3
"""Code or output blocks a page may have that scroll sideways."""


def _missing() -> str | None:
    if not (SITE / "index.html").is_file():
        return "site/ is not built (python tools/build_site.py)"
    for path in (CHROMIUM, CHROMEDRIVER):
        if not Path(path).is_file():
            return f"{path} is missing (apt-get install -y chromium chromium-driver)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (the docs extra)"
    return None


@pytest.fixture(scope="module")
def browser():
    reason = _missing()
    if reason:
        if os.environ.get("IBC_TUTORIAL_SITE_TEST") == "1":
            pytest.fail(f"IBC_TUTORIAL_SITE_TEST=1 but {reason}")
        pytest.skip(reason)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="ibc-site-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-dev-shm-usage",
        f"--window-size={WIDTH},1000",
        f"--user-data-dir={profile}",
    ):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(60)
    driver.set_script_timeout(60)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="module")
def server():
    handler = functools.partial(_QuietHandler, directory=str(SITE))
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format, *args):  # noqa: A002 (the base class's name)
        pass


@pytest.fixture(scope="module")
def shots():
    folder = Path(os.environ.get("IBC_TUTORIAL_SCREENSHOTS") or tempfile.mkdtemp(prefix="ibc-site-shots-"))
    folder.mkdir(parents=True, exist_ok=True)
    print(f"\nscreenshots: {folder}")
    return folder


def _page(pattern: str) -> str:
    found = sorted(SITE.glob(pattern))
    assert found, f"site/ has no page {pattern}"
    return found[0].relative_to(SITE).as_posix()


def _widget_cells(page: str) -> int | None:
    """How many widget cells the page's notebook holds (None for a page made from no notebook)."""
    notebook = ROOT / Path(page).with_suffix(".ipynb")
    if not notebook.is_file():
        return None
    cells = json.loads(notebook.read_text())["cells"]
    return sum(
        cell["cell_type"] == "code"
        and "".join(cell["source"]).lstrip().startswith("# NBVAL_IGNORE_OUTPUT")
        and any(WIDGET_MIME in out.get("data", {}) for out in cell.get("outputs", []))
        for cell in cells
    )


# the visible text outside code blocks (code may hold "$" or "\(" legitimately)
_VISIBLE_TEXT = """
const clone = document.querySelector('main') ? document.querySelector('main').cloneNode(true)
                                              : document.body.cloneNode(true);
clone.querySelectorAll('pre, code, script, style, mjx-container, mjx-assistive-mml').forEach(e => e.remove());
return clone.textContent;
"""

_MATHJAX_DONE = """
const done = arguments[arguments.length - 1];
if (!window.MathJax || !MathJax.startup || !MathJax.startup.promise) { done('no MathJax'); return; }
MathJax.startup.promise.then(() => done('ok'), e => done('failed: ' + e));
"""

_IMAGES = """
const done = arguments[arguments.length - 1];
const imgs = Array.from(document.images);
imgs.forEach(i => { i.loading = 'eager'; });
Promise.all(imgs.map(i => i.complete ? null : new Promise(r => { i.onload = i.onerror = r; })))
  .then(() => done(imgs.map(i => [i.getAttribute('src'), i.naturalWidth, i.getBoundingClientRect().width,
                                  i.closest('div.cell_output') !== null])));
"""

# where the title and the first code cell are, in document order (-1: none)
_ORDER = """
const all = Array.from(document.querySelectorAll('main h1, main div.cell'));
return [all.findIndex(e => e.tagName === 'H1'), all.findIndex(e => e.tagName !== 'H1')];
"""

# code and output blocks wider than their box (they scroll sideways)
_OVERFLOWING = """
return Array.from(document.querySelectorAll('main div.cell pre'))
  .filter(p => p.scrollWidth > p.clientWidth + 1).map(p => p.textContent.slice(0, 60));
"""


@pytest.mark.parametrize("pattern", PAGES)
def test_page_renders(browser, server, shots, pattern):
    page = _page(pattern)
    browser.get(f"{server}/{page}")
    math = browser.execute_script("return document.querySelectorAll('.math').length")
    if math:  # Sphinx loads MathJax only on pages with equations
        assert browser.execute_async_script(_MATHJAX_DONE) == "ok", f"{page}: MathJax did not typeset"

    images = browser.execute_async_script(_IMAGES)
    broken = [src for src, width, _, _ in images if not width]
    assert not broken, f"{page}: images that did not load: {broken}"
    shrunk = [
        f"{src}: {drawn:.0f} of {width} px"
        for src, width, drawn, figure in images
        if figure and drawn < MIN_SCALE * width and drawn < MIN_WIDE
    ]
    assert not shrunk, f"{page}: figures drawn too small to read at {WIDTH} px: {shrunk}"

    typeset = browser.execute_script("return document.querySelectorAll('mjx-container').length")
    assert typeset >= math, f"{page}: {math} equations in the page, {typeset} typeset by MathJax"
    text = browser.execute_script(_VISIBLE_TEXT)
    for raw in ("$$", "\\(", "\\["):
        assert raw not in text, (
            f"{page}: raw {raw!r} in the visible text: {text[text.index(raw) - 80 :][:200]!r}"
        )

    widgets = _widget_cells(page)
    if page.startswith("book/"):
        title, code = browser.execute_script(_ORDER)
        assert title >= 0 and (code < 0 or title < code), (
            f"{page}: the first code cell comes before the title"
        )
        wide = browser.execute_script(_OVERFLOWING)
        assert len(wide) <= MAX_OVERFLOWING, f"{page}: {len(wide)} blocks scroll sideways: {wide}"
    searches = browser.execute_script(
        "return Array.from(document.querySelectorAll('.search-button-field, .search-button'))"
        ".filter(e => e.offsetParent !== null).length"
    )
    assert searches == 1, f"{page}: {searches} search boxes in view, one expected"
    if widgets is not None:
        notes = browser.execute_script(
            "return Array.from(document.querySelectorAll('.admonition-title'))"
            ".filter(e => e.textContent.trim() === 'Live in Jupyter').length"
        )
        assert notes == widgets, f"{page}: {widgets} widget cells, {notes} 'Live in Jupyter' notes"
        assert browser.find_elements("partial link text", Path(page).with_suffix(".ipynb").name), (
            f"{page}: no link to the notebook file"
        )

    errors = [entry for entry in browser.get_log("browser") if entry["level"] == "SEVERE"]
    assert not errors, f"{page}: console errors: {errors}"

    stem = page.replace("/", "_").removesuffix(".html")
    browser.save_screenshot(str(shots / f"{stem}_top.png"))
    for what, selector in (
        ("figure", "div.cell_output img"),
        ("equation", "mjx-container[display='true'], mjx-container"),
        ("widget_note", "div.admonition.important"),
    ):
        found = browser.find_elements("css selector", selector)
        if found:
            browser.execute_script("arguments[0].scrollIntoView({block: 'center'})", found[0])
            browser.save_screenshot(str(shots / f"{stem}_{what}.png"))
    print(f"{page}: {len(images)} images, {math} equations ({typeset} typeset), widgets: {widgets}")
