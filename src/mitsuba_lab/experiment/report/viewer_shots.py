"""Drive a report's comparison viewer in a real browser: Playwright (a dev dependency) with
Debian's Chromium through ``executable_path`` (no browser download).

``ViewerPage`` opens a report, collects page errors and failed console messages, and offers
what the tests need: keys, wheel zoom, drag, the exposure slider, the split view's divider,
one canvas pixel or the whole canvas, element screenshots. ``python -m
mitsuba_lab.experiment.report.viewer_shots OUTDIR/report/index.html DIR [N]`` writes the screenshots
of viewer N (default 0) shown in notes and issues: initial, after key 2, zoomed, error map on,
signed difference on, split view, split view of the signed difference with the divider moved
(the last two only where the comparison holds two strategies).
"""
from __future__ import annotations

import base64
import os
import sys

import numpy as np

from .browser import chromium

#: Chromium flags for a headless run inside containers (no sandbox, no GPU).
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"]


class ViewerPage:
    def __init__(self, html_path: str, viewport=(1400, 1000)):
        self.html_path = os.path.abspath(html_path)
        self.viewport = viewport
        self.errors: list[str] = []

    def __enter__(self) -> "ViewerPage":
        from playwright.sync_api import sync_playwright

        browser_path = chromium()
        if browser_path is None:
            raise FileNotFoundError("no chromium found: apt-get install chromium")
        self._pw = sync_playwright().start()
        self.browser = self._pw.chromium.launch(executable_path=browser_path, args=ARGS)
        self.page = self.browser.new_page(viewport={"width": self.viewport[0], "height": self.viewport[1]})
        self.page.on("pageerror", lambda err: self.errors.append(f"page error: {err}"))
        self.page.on("console", lambda msg: self.errors.append(f"console: {msg.text}") if msg.type == "error" else None)
        self.page.goto("file://" + self.html_path)
        self.page.wait_for_function("document.documentElement.dataset.viewers !== undefined", timeout=30_000)
        return self

    def __exit__(self, *exc) -> None:
        self.browser.close()
        self._pw.stop()

    # -- what the page holds ---------------------------------------------------------------
    def viewer_count(self) -> int:
        return int(self.page.evaluate("document.documentElement.dataset.viewers"))

    def broken_images(self) -> int:
        return self.page.evaluate("Array.from(document.images).filter(i => !i.complete || i.naturalWidth === 0).length")

    def viewer(self, n: int = 0):
        return self.page.locator(".viewer").nth(n)

    def canvas(self, n: int = 0):
        return self.viewer(n).locator(".vw-canvas")

    def pixel(self, x: int, y: int, n: int = 0) -> tuple[int, int, int]:
        """The main canvas's RGB at canvas pixel (x, y)."""
        return tuple(self.page.evaluate(
            "([n, x, y]) => Array.from(document.querySelectorAll('.vw-canvas')[n].getContext('2d')"
            ".getImageData(x, y, 1, 1).data).slice(0, 3)", [n, x, y]))

    def canvas_rgb(self, n: int = 0) -> np.ndarray:
        """The main canvas as a height x width x 3 uint8 array (what it holds, not a screenshot)."""
        b64, width, height = self.page.evaluate(
            """n => { const c = document.querySelectorAll('.vw-canvas')[n];
                      const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
                      let s = ''; for (let i = 0; i < px.length; i++) s += String.fromCharCode(px[i]);
                      return [btoa(s), c.width, c.height]; }""", n)
        return np.frombuffer(base64.b64decode(b64), np.uint8).reshape(height, width, 4)[..., :3]

    def divider(self, n: int = 0) -> float:
        """The split view's divider as a fraction of the image area's width (its slider)."""
        return float(self.viewer(n).locator(".vw-divider").input_value()) / 100

    def text(self, selector: str, n: int = 0) -> str:
        return self.viewer(n).locator(selector).first.inner_text()

    # -- what a person does ---------------------------------------------------------------
    def hover(self, n: int = 0, fx: float = 0.5, fy: float = 0.5) -> None:
        """Move the mouse over viewer n's image (keys go to the viewer under the mouse)."""
        self.viewer(n).scroll_into_view_if_needed()
        box = self.canvas(n).bounding_box()
        self.page.mouse.move(box["x"] + fx * box["width"], box["y"] + fy * box["height"])

    def press(self, key: str, n: int = 0) -> None:
        self.hover(n)
        self.page.keyboard.press(key)

    def zoom(self, clicks: int, n: int = 0, fx: float = 0.5, fy: float = 0.5) -> None:
        """Mouse-wheel zoom at a point of the image (positive clicks zoom in)."""
        self.hover(n, fx, fy)
        for _ in range(abs(clicks)):
            self.page.mouse.wheel(0, -120 if clicks > 0 else 120)

    def drag(self, dx: float, dy: float, n: int = 0) -> None:
        self.hover(n)
        self.page.mouse.down()
        box = self.canvas(n).bounding_box()
        self.page.mouse.move(box["x"] + box["width"] / 2 + dx, box["y"] + box["height"] / 2 + dy, steps=4)
        self.page.mouse.up()

    def drag_divider(self, fraction: float, n: int = 0) -> None:
        """Drag the split view's divider with the mouse (grabbed at its handle, mid-height)
        to ``fraction`` of the image area's width."""
        self.hover(n, self.divider(n), 0.5)
        self.page.mouse.down()
        box = self.canvas(n).bounding_box()
        self.page.mouse.move(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2, steps=5)
        self.page.mouse.up()

    def set_exposure(self, ev: float, n: int = 0) -> None:
        """Move the slider as a person would: a new value, then its input event."""
        self.viewer(n).locator(".vw-exposure").evaluate(
            "(el, v) => { el.value = v; el.dispatchEvent(new Event('input', {bubbles: true})); }", ev)

    def shot(self, path: str | None = None, n: int = 0, canvas_only: bool = False) -> bytes:
        """PNG of viewer n (or only its image area), written to ``path`` when given."""
        target = self.canvas(n) if canvas_only else self.viewer(n)
        return target.screenshot(path=path)


def take_shots(html_path: str, out_dir: str, n: int = 0) -> dict:
    """The screenshots of viewer n: initial, after key 2, zoomed in (4 wheel clicks at the
    image centre), error map on (key e), signed difference on (view reset, key d), split
    view of the first two strategies (key s, image mode), and the split view's signed
    difference with the divider dragged to a third. Returns their paths (the split views'
    left out where the comparison holds one strategy), the page's errors and its number of
    broken images."""
    os.makedirs(out_dir, exist_ok=True)
    paths = []
    with ViewerPage(html_path) as page:
        def shot(name):
            paths.append(os.path.join(out_dir, name))
            page.shot(paths[-1], n)

        page.hover(n)
        shot("1_initial.png")
        page.press("2", n)
        shot("2_after_key_2.png")
        page.zoom(4, n)
        shot("3_zoomed.png")
        page.press("e", n)
        shot("4_error_map.png")
        page.press("0", n)
        page.press("d", n)
        shot("5_signed_difference.png")
        if page.viewer(n).locator(".vw-split-on").is_enabled():
            page.press("d", n)
            page.press("s", n)
            shot("6_split.png")
            page.press("d", n)
            page.drag_divider(1 / 3, n)
            shot("7_split_signed_difference.png")
        return {"shots": paths, "errors": list(page.errors), "broken_images": page.broken_images(),
                "viewers": page.viewer_count()}


if __name__ == "__main__":
    if len(sys.argv) < 3:
        print("usage: python -m mitsuba_lab.experiment.report.viewer_shots REPORT.html OUT_DIR [VIEWER_INDEX]")
        sys.exit(2)
    result = take_shots(sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 0)
    print("\n".join(result["shots"]))
    print(f"{result['viewers']} viewers, {result['broken_images']} broken images, {len(result['errors'])} errors")
    for line in result["errors"]:
        print(line)
    sys.exit(1 if result["errors"] or result["broken_images"] else 0)
