"""The built site as a reader sees it: served on 127.0.0.1 to Debian's headless Chromium.

Search works (it runs in a web worker, which a page opened as a file cannot start: served, it
finds "rosbag" on the ROS 2 page), and a 1280 px wide window shows the whole of every page: no
page is wider, no code or output line runs out of its block, no table out of the text column,
and no line of code lies under a block's copy button. Chromium resolves no name but 127.0.0.1,
so the pages' requests (fonts, the repository's figures) never leave the machine.
"""

from __future__ import annotations

import functools
import http.server
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest

REPO = Path(__file__).resolve().parent.parent
CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
WIDTH = 1280

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

# what a page shows beyond the window or its column, and code under a copy button
MEASURE = r"""
const out = {page: document.documentElement.scrollWidth, problems: []};
const column = document.querySelector('.md-content__inner').getBoundingClientRect();
for (const code of document.querySelectorAll('.md-content pre > code')) {
  if (code.scrollWidth > code.clientWidth + 1)
    out.problems.push(`a line runs out of its block (${code.scrollWidth} px in ` +
                      `${code.clientWidth}): ${code.textContent.slice(0, 60)}`);
}
for (const table of document.querySelectorAll('.md-content table')) {
  const right = table.getBoundingClientRect().right;
  if (right > column.right + 1)
    out.problems.push(`a table ends at ${right} px, the column at ${column.right}: ` +
                      table.textContent.trim().slice(0, 60));
}
const buttons = '.md-content .md-code__button, .md-content .md-clipboard';  // Material 9.8, older
for (const button of document.querySelectorAll(buttons)) {
  const code = button.closest('pre') && button.closest('pre').querySelector('code');
  if (!code) continue;
  const b = button.getBoundingClientRect();
  const walk = document.createTreeWalker(code, NodeFilter.SHOW_TEXT);
  let covered = null;
  while (!covered && walk.nextNode()) {
    const node = walk.currentNode;
    for (const word of node.data.matchAll(/\S+/g)) {  // spaces a wrapped line hangs are no text
      const text = document.createRange();
      text.setStart(node, word.index);
      text.setEnd(node, word.index + word[0].length);
      for (const r of text.getClientRects()) {
        const across = r.left < b.right && r.right > b.left;
        if (r.width > 0 && across && r.top < b.bottom && r.bottom > b.top) covered = word[0];
      }
      if (covered) break;
    }
  }
  if (covered)
    out.problems.push(`the copy button covers "${covered}" in: ` + code.textContent.slice(0, 60));
}
out.buttons = document.querySelectorAll(buttons).length;
return out;
"""


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site as `make docs` builds it, strict."""
    out = tmp_path_factory.mktemp("site")
    env = {"NO_MKDOCS_2_WARNING": "1", "DISABLE_MKDOCS_2_WARNING": "true", "PATH": ""}
    mkdocs = Path(sys.executable).parent / "mkdocs"
    subprocess.run(
        [str(mkdocs), "build", "--strict", "--quiet", "--site-dir", str(out)],
        cwd=REPO,
        env=env,
        check=True,
        capture_output=True,
        timeout=300,
    )
    return out


@pytest.fixture(scope="module")
def served(site: Path) -> Iterator[str]:
    """The site over http on 127.0.0.1, as `python -m http.server -d site` serves it."""

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, format: str, *args: Any) -> None:
            pass

    handler = functools.partial(Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()
    server.server_close()
    thread.join()


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """Debian's chromium through Debian's chromedriver, headless, 1280 px wide."""
    if not CHROMIUM.is_file() or not CHROMEDRIVER.is_file():
        pytest.skip("Debian's chromium and chromium-driver are absent (.ci/run installs them)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path_factory.mktemp('chromium')}",
        f"--window-size={WIDTH},900",
        "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1",
    ):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    try:
        yield driver
    finally:
        driver.quit()


def _pages(site: Path) -> list[str]:
    return sorted(
        "" if p.parent == site else f"{p.parent.relative_to(site).as_posix()}/"
        for p in site.rglob("index.html")
        if "assets" not in p.relative_to(site).parts
    )


def test_search_finds_rosbag_on_the_ros2_page(browser: Any, served: str) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get(served + "how-to/ros2/")
    box = browser.find_element(By.CSS_SELECTOR, "input.md-search__input")
    box.click()
    box.send_keys("rosbag")

    def found(driver: Any) -> list[str]:
        links = driver.find_elements(By.CSS_SELECTOR, ".md-search-result__item a")
        return [str(a.get_attribute("href")) for a in links]

    links = WebDriverWait(browser, 60).until(found)
    meta = browser.find_element(By.CSS_SELECTOR, ".md-search-result__meta").text
    assert "Initializing" not in meta and "matching" in meta, meta
    pages = {urlsplit(link).path for link in links}  # a result's link carries ?h=rosbag#part
    assert "/how-to/ros2/" in pages, links


def test_every_page_fits_a_1280_px_window(browser: Any, served: str, site: Path) -> None:
    pages = _pages(site)
    assert "how-to/ros2/" in pages and "performance/" in pages and "" in pages
    problems = []
    buttons = 0
    for page in pages:
        browser.get(served + page)
        measured = browser.execute_script(MEASURE)
        buttons += measured["buttons"]
        if measured["page"] > WIDTH:
            problems.append(f"/{page}: the page is {measured['page']} px wide")
        problems += [f"/{page}: {p}" for p in measured["problems"]]
    assert buttons > 50  # the copy buttons were there to be looked at
    assert problems == [], "\n".join(problems)
