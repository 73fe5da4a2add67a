"""Open a generated report in headless Chromium: screenshot, broken images, console errors.

A copy of the page gets a small script that, once everything has loaded,
writes the number of images that failed to decode and the JavaScript errors
into the document title; Chromium's ``--dump-dom`` then shows it. Used by the
tests (skipped where Debian's ``chromium`` is not installed) and by anyone
who wants a picture of a report: ``python -m mitsuba_lab.experiment.report.browser
OUTDIR/report/index.html shot.png``.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass

CHECK_SCRIPT = """<script>
window.__errors = [];
window.addEventListener('error', e => window.__errors.push(String(e.message || e.type)), true);
window.addEventListener('load', () => {
  const imgs = Array.from(document.images);
  const broken = imgs.filter(i => !i.complete || i.naturalWidth === 0).length;
  document.title = 'LABCHECK images=' + imgs.length + ' broken=' + broken +
                   ' errors=' + window.__errors.length;
});
</script>"""

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--hide-scrollbars", "--virtual-time-budget=10000")


@dataclass
class PageCheck:
    images: int
    broken: int
    errors: int
    screenshot: str | None


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def check_page(html_path: str, screenshot: str | None = None, timeout: int = 120) -> PageCheck:
    browser = chromium()
    if browser is None:
        raise FileNotFoundError("no chromium found: apt-get install chromium")
    with tempfile.TemporaryDirectory() as tmp:
        page = os.path.join(tmp, "page.html")
        with open(html_path) as f:
            text = f.read()
        with open(page, "w") as f:
            f.write(text.replace("<head>", "<head>" + CHECK_SCRIPT, 1))
        base = [browser, *FLAGS, f"--user-data-dir={os.path.join(tmp, 'profile')}"]
        dom = subprocess.run(base + ["--dump-dom", "file://" + page], capture_output=True, text=True,
                             timeout=timeout).stdout
        match = re.search(r"LABCHECK images=(\d+) broken=(\d+) errors=(\d+)", dom)
        if not match:
            raise RuntimeError("the page did not finish loading in headless Chromium")
        if screenshot:
            subprocess.run(base + ["--window-size=1400,2400", f"--screenshot={os.path.abspath(screenshot)}",
                                   "file://" + os.path.abspath(html_path)],
                           capture_output=True, text=True, timeout=timeout, check=True)
        images, broken, errors = (int(v) for v in match.groups())
        return PageCheck(images, broken, errors, screenshot)


if __name__ == "__main__":
    result = check_page(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else None)
    print(f"{result.images} images, {result.broken} broken, {result.errors} script errors")
    sys.exit(1 if result.broken or result.errors or not result.images else 0)
