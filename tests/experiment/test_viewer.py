"""The report's comparison viewer: its data (which renders are compared, half-float HDR
encoding, crops and their relMSE) and, in Debian's Chromium driven by Playwright, what a
person sees: keys, labels, exposure, error and variance maps, zoom and drag, no page errors.

Everything runs on a synthetic stored sweep (tests/synthetic_sweep.py: numpy images, nothing
rendered), so these tests take a few seconds.
"""
import base64
import json
import os
import re

import numpy as np
import pytest
import synthetic_sweep as synth

from mitsuba_lab.experiment.report import browser
from mitsuba_lab.experiment.report.comparisons import comparison_sets, group_points
from mitsuba_lab.experiment.report.build import Report, build_report
from mitsuba_lab.experiment.report.viewer import HALF_MAX, encode_half


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    folder = tmp_path_factory.mktemp("viewer_sweep")
    synth.write_sweep(folder)
    build_report(str(folder))
    return folder


def page_data(html: str) -> list[dict]:
    blocks = re.findall(r'<script type="application/json" class="vw-data">(.*?)</script>', html, re.S)
    return [json.loads(b.replace("<\\/", "</")) for b in blocks]


def decode(b64: str) -> np.ndarray:
    return np.frombuffer(base64.b64decode(b64), dtype="<f2").astype(np.float64)


def srgb8(v: float) -> int:
    v = min(max(v, 0.0), 1.0)
    return round(255 * (12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055))


# -- the data, without a browser --------------------------------------------------------------

def test_half_float_encoding_keeps_hdr_values():
    values = np.array([0.0, 1e-3, 0.5, 4.0, 1234.5, 1e6, np.inf, -np.inf, np.nan])
    back = decode(encode_half(values))
    np.testing.assert_allclose(back[:5], values[:5], rtol=2 ** -11)       # half: 11 significant bits
    assert back[5] == back[6] == HALF_MAX and back[7] == -HALF_MAX and back[8] == 0.0


def test_block_markers_and_the_page_script():
    from mitsuba_lab.reporting import block_marker, html_page, md_to_html

    text = f"# T\n{block_marker('x')}\n{block_marker('missing')}\nend"
    assert md_to_html(text, blocks={"x": "<div id=x></div>"}).splitlines() == \
        ["<h1>T</h1>", "<div id=x></div>", "", "<p>end</p>"]
    assert html_page("t", "b", script="let a = 1;").endswith("<script>\nlet a = 1;\n</script>\n</body></html>\n")
    with pytest.raises(ValueError, match="</script"):
        html_page("t", "b", script="s = '</SCRIPT>'")


@pytest.mark.slow
def test_comparison_sets_pair_equal_time_and_equal_spp(sweep):
    groups, label = group_points(Report(str(sweep)).stats["s"])
    sets = comparison_sets(groups, label)
    assert [s.name for s in sets] == ["equal time 0.1 s (0.1 s measured)", "equal time 0.2 s (0.2 s measured)",
                                       "equal spp 4", "equal spp 16"]
    for s in sets:
        assert [name for name, _ in s.entries] == ["good", "noisy"]
    assert {p.budget_s for _, p in sets[1].entries} == {0.2}
    assert {(p.spp, p.budget_s) for _, p in sets[3].entries} == {(16, None)}


def test_spp_ladder_only_gives_nearest_points_at_about_equal_time(tmp_path):
    synth.write_sweep(tmp_path, budgets=())
    groups, label = group_points(Report(str(tmp_path)).stats["s"])
    sets = comparison_sets(groups, label)
    timed = [s for s in sets if s.kind == "time"]
    assert timed and all(s.name.startswith("about equal time") for s in timed)
    # "good" takes 0.004 s per spp, "noisy" 0.002: the common range is 0.032 .. 0.064 s
    for s in timed:
        times = {name: p.time_s for name, p in s.entries}
        assert max(times.values()) / min(times.values()) < 4.1


def test_report_page_embeds_one_viewer_per_scene_offline(sweep):
    html = (sweep / "report" / "index.html").read_text()
    md = (sweep / "report" / "summary.md").read_text()
    assert "<!-- block:viewer-s -->" in md and "vw-data" not in md
    assert not re.search(r'(src|href)="(https?:)?//', html) and "<link" not in html    # nothing fetched
    (data,) = page_data(html)
    assert (data["width"], data["height"]) == (synth.WIDTH, synth.HEIGHT)
    assert data["regions"] == synth.REGIONS
    assert data["sets"][data["start"]]["name"] == "equal time 0.2 s (0.2 s measured)"
    ref = decode(data["images"]["ref"]).reshape(synth.HEIGHT, synth.WIDTH, 3)
    np.testing.assert_allclose(ref, synth.reference_image(), rtol=2 ** -11)   # HDR: 4.0 stays 4.0
    assert ref.max() == synth.BRIGHT
    entry = data["sets"][data["start"]]["entries"][1]
    image = decode(data["images"][entry["rgb"]]).reshape(synth.HEIGHT, synth.WIDTH, 3)
    err = decode(data["images"][entry["err"]]).reshape(synth.HEIGHT, synth.WIDTH)
    r = synth.reference_image().astype(np.float64)
    expected = np.log10(np.sqrt(np.mean((image - r) ** 2 / (r ** 2 + 0.01), axis=-1)))
    np.testing.assert_allclose(err, expected, atol=0.02)   # half rounding of image and map
    x0, y0, x1, y1 = synth.REGIONS["light"]
    crop = np.mean((image[y0:y1, x0:x1] - r[y0:y1, x0:x1]) ** 2 / (r[y0:y1, x0:x1] ** 2 + 0.01))
    assert entry["crops"]["light"]["text"].startswith("relMSE ")
    shown = float(entry["crops"]["light"]["text"].split()[1])
    assert shown == pytest.approx(crop, rel=0.05)          # printed with 2 digits
    assert data["crop_exposure"]["light"] == -2.5          # 4.0 shown at 0.8: log2(0.2) ~ -2.3 -> half stops


# -- in a real browser ------------------------------------------------------------------------

def open_page(path):
    reason = None
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        reason = "the playwright Python package is not installed (pip install -e '.[dev]')"
    if browser.chromium() is None:
        reason = "Debian's chromium is not installed (apt-get install chromium)"
    if reason:
        if os.environ.get("CI"):
            pytest.fail(f"{reason}: CI must run the browser tests (.ci/bootstrap installs both)")
        pytest.skip(reason)
    from mitsuba_lab.experiment.report.viewer_shots import ViewerPage

    return ViewerPage(str(path))


SCALE = 21                                      # floor(512 / 24): screen pixels per image pixel


def at(x, y):
    """Canvas coordinates of image pixel (x, y)'s centre at the initial view."""
    return int((x + 0.5) * SCALE), int((y + 0.5) * SCALE)


@pytest.mark.slow
def test_keys_labels_and_sets_switch_the_image(sweep, tmp_path):
    with open_page(sweep / "report" / "index.html") as page:
        assert page.viewer_count() == 1 and page.broken_images() == 0
        page.hover()
        initial = page.shot(canvas_only=True)
        page.press("2")
        assert page.text(".vw-labels .vw-on") == "2 good"
        assert page.text(".vw-status").startswith("equal time 0.2 s (0.2 s measured) \u2014 good:")
        after_2 = page.shot(canvas_only=True)
        assert after_2 != initial
        page.press("1")
        assert page.shot(canvas_only=True) == initial          # back to the reference, same pixels
        page.viewer().get_by_role("button", name="3 noisy").click()
        assert page.text(".vw-labels .vw-on") == "3 noisy"
        page.press("ArrowRight")                                # wraps to the reference
        assert page.text(".vw-labels .vw-on") == "1 reference"
        page.press("ArrowLeft")
        page.press("ArrowDown")                                 # next set, same strategy
        assert page.text(".vw-row button.vw-on") == "equal spp 4"
        assert page.text(".vw-labels .vw-on") == "3 noisy"
        # the crops beside the image: one per region and image, each with its relMSE
        assert page.viewer().locator(".vw-crops canvas").count() == 3 * len(synth.REGIONS)
        assert page.viewer().locator(".vw-crops td", has_text="relMSE").count() == 2 * len(synth.REGIONS)
        assert page.errors == [] and page.broken_images() == 0


def test_exposure_is_applied_to_hdr_data(sweep):
    bright, dim = at(4, 3), at(16, 11)                  # inside "light" (4.0) and "dim" (0.05)
    with open_page(sweep / "report" / "index.html") as page:
        page.hover()
        assert page.pixel(*bright) == (255, 255, 255)
        assert page.pixel(*dim) == (srgb8(0.05),) * 3
        page.set_exposure(-3)                           # 4.0 / 8 = 0.5: the clipped value was kept
        assert page.pixel(*bright) == (srgb8(0.5),) * 3
        page.set_exposure(2)
        assert page.pixel(*dim) == (srgb8(0.2),) * 3
        page.press("-")
        assert page.text(".vw-ev") == "+1.5 EV"
        assert page.pixel(*dim) == (srgb8(0.05 * 2 ** 1.5),) * 3
        assert page.errors == []


@pytest.mark.slow
def test_error_and_variance_maps(sweep):
    (data,) = page_data((sweep / "report" / "index.html").read_text())
    entry = data["sets"][data["start"]]["entries"][1]
    x, y = 10, 8
    value = decode(data["images"][entry["err"]])[y * synth.WIDTH + x]
    lo, hi = data["err_range"]
    t = round(255 * min(max((value - lo) / (hi - lo), 0), 1)) / 255 * (len(data["colormaps"]["err"]) - 1)
    k = min(int(t), len(data["colormaps"]["err"]) - 2)
    stops = np.array(data["colormaps"]["err"], dtype=float)
    expected = stops[k] * (1 - (t - k)) + stops[k + 1] * (t - k)
    with open_page(sweep / "report" / "index.html") as page:
        page.press("2")
        image = page.shot(canvas_only=True)
        page.press("e")
        assert page.viewer().locator(".vw-err").is_checked()
        np.testing.assert_allclose(page.pixel(*at(x, y)), expected, atol=1)
        error_map = page.shot(canvas_only=True)
        page.press("v")
        assert page.viewer().locator(".vw-var").is_checked() and not page.viewer().locator(".vw-err").is_checked()
        variance = page.shot(canvas_only=True)
        page.press("v")
        assert len({image, error_map, variance}) == 3 and page.shot(canvas_only=True) == image
        assert page.errors == []


@pytest.mark.slow
def test_zoom_and_drag_keep_one_view_for_all_images(sweep):
    with open_page(sweep / "report" / "index.html") as page:
        page.hover()
        plain = page.shot(canvas_only=True)
        white = lambda: sum(page.pixel(x, 84) == (255, 255, 255) for x in range(0, 504, 6))  # noqa: E731
        before = white()                        # canvas row 84: image row 4, through the bright block
        page.zoom(6, fx=0.25, fy=0.25)          # about canvas (126, 84), which stays in place
        zoomed_ref = page.shot(canvas_only=True)
        assert zoomed_ref != plain and white() > 1.5 * before     # 6 clicks: 1.2^6 ~ 2.9x, left part off-canvas
        page.press("2")
        page.press("1")
        assert page.shot(canvas_only=True) == zoomed_ref         # switching keeps the view
        page.drag(-60, -30)
        assert page.shot(canvas_only=True) != zoomed_ref
        page.press("0")
        assert page.shot(canvas_only=True) == plain
        assert page.errors == []


# -- the signed difference and the split view ---------------------------------------------------

#: "biased" over-estimates by 30% left of the image's middle column and under-estimates by 30%
#: right of it (little noise); "good" is unbiased.
BIAS = np.where(np.arange(synth.WIDTH) < synth.WIDTH // 2, 0.3, -0.3)[None, :] * np.ones((synth.HEIGHT, 1))


@pytest.fixture(scope="module")
def biased(tmp_path_factory):
    folder = tmp_path_factory.mktemp("viewer_biased")
    synth.write_sweep(folder, strategies={"biased": 0.1, "good": 0.3}, bias={"biased": BIAS})
    build_report(str(folder))
    return folder


@pytest.fixture(scope="module")
def single(tmp_path_factory):
    folder = tmp_path_factory.mktemp("viewer_single")
    synth.write_sweep(folder, strategies={"biased": 0.1}, bias={"biased": BIAS})
    build_report(str(folder))
    return folder


@pytest.mark.slow
def test_signed_difference_has_a_symmetric_range_and_costs_no_data(biased, sweep):
    from mitsuba_lab.experiment.report.viewer import signed_difference

    (data,) = page_data((biased / "report" / "index.html").read_text())
    lo, hi = data["diff_range"]
    assert lo == -hi and 0.2 < hi < 0.5                 # 30% bias, shrunk by sqrt(ref^2 + 0.01) where dim
    assert data["colormaps"]["diff"][8] == [247, 246, 246]   # RdBu_r: white at zero
    assert not any(k.endswith(":diff") for k in data["images"])   # computed in the browser
    image, ref = synth.reference_image() * 1.3, synth.reference_image()
    np.testing.assert_allclose(signed_difference(image, ref),
                               np.mean(0.3 * ref / np.sqrt(ref.astype(np.float64) ** 2 + 0.01), axis=-1), rtol=1e-6)
    (plain,) = page_data((sweep / "report" / "index.html").read_text())
    assert set(plain["images"]) == {k for k in plain["images"] if not k.endswith(":diff")}


def expected_diff_colour(data, entry, x, y):
    """The colour the signed view gives image pixel (x, y) of ``entry``, from the page's data."""
    from mitsuba_lab.experiment.report.viewer import signed_difference

    shape = (synth.HEIGHT, synth.WIDTH, 3)
    image = decode(data["images"][entry["rgb"]]).reshape(shape)
    ref = decode(data["images"]["ref"]).reshape(shape)
    value = signed_difference(image, ref)[y, x]
    lo, hi = data["diff_range"]
    stops = np.array(data["colormaps"]["diff"], dtype=float)
    t = round(255 * min(max((value - lo) / (hi - lo), 0), 1)) / 255 * (len(stops) - 1)
    k = min(int(t), len(stops) - 2)
    return stops[k] * (1 - (t - k)) + stops[k + 1] * (t - k)


@pytest.mark.slow
def test_signed_difference_is_red_where_brighter_and_blue_where_darker(biased):
    (data,) = page_data((biased / "report" / "index.html").read_text())
    entry = data["sets"][data["start"]]["entries"][1]
    assert entry["label"] == "biased"
    left = [(x, y) for x in range(0, synth.WIDTH // 2 - 1, 3) for y in range(0, synth.HEIGHT, 3)]
    right = [(x, y) for x in range(synth.WIDTH // 2 + 1, synth.WIDTH, 3) for y in range(0, synth.HEIGHT, 3)]
    with open_page(biased / "report" / "index.html") as page:
        page.press("2")
        image = page.shot(canvas_only=True)
        page.press("d")
        assert page.viewer().locator(".vw-diff").is_checked() and not page.viewer().locator(".vw-err").is_checked()
        assert "red brighter than the reference" in page.text(".vw-help")
        # rows and columns away from the region outlines and their names
        shown = page.canvas_rgb().astype(int)
        for x, y in left:
            r, g, b = shown[at(x, y)[1], at(x, y)[0]]
            assert r > b + 60 and r > g + 60, (x, y, r, g, b)        # over-estimation: red
        for x, y in right:
            r, g, b = shown[at(x, y)[1], at(x, y)[0]]
            assert b > r + 60 and b > g + 20, (x, y, r, g, b)        # under-estimation: blue
        np.testing.assert_allclose(page.pixel(*at(10, 8)), expected_diff_colour(data, entry, 10, 8), atol=1)
        np.testing.assert_allclose(page.pixel(*at(18, 8)), expected_diff_colour(data, entry, 18, 8), atol=1)
        page.press("1")                                 # the reference minus itself: white throughout
        assert page.pixel(*at(10, 8)) == page.pixel(*at(18, 8))
        np.testing.assert_allclose(page.pixel(*at(10, 8)), (247, 246, 246), atol=1)
        page.press("2")
        page.hover(fx=(18.5 / synth.WIDTH), fy=(8.5 / synth.HEIGHT))
        assert re.search(r"signed difference -0\.\d+", page.text(".vw-status >> nth=1"))
        page.press("e")                                 # the |error| map beside it: no sign
        assert page.viewer().locator(".vw-err").is_checked() and not page.viewer().locator(".vw-diff").is_checked()
        error_map = page.shot(canvas_only=True)
        page.press("e")
        assert page.shot(canvas_only=True) == image and error_map != image
        assert page.errors == []


@pytest.mark.slow
def test_split_view_shows_a_left_of_the_divider_and_b_right(biased):
    with open_page(biased / "report" / "index.html") as page:
        page.press("2")
        single_a = page.canvas_rgb()
        page.press("3")
        single_b = page.canvas_rgb()
        assert (single_a != single_b).any()
        page.press("2")
        split = page.viewer().locator(".vw-split-on")
        assert split.is_enabled() and not split.is_checked()
        page.press("s")
        assert split.is_checked()
        assert page.text(".vw-split-note") == "left of the divider: A biased; right: B good"
        assert page.text(".vw-labels .vw-on") == "2 biased" and page.text(".vw-labels .vw-b") == "3 good"
        assert page.viewer().get_by_role("button", name="1 reference").is_disabled()

        def sides():
            """Canvas columns that show A and that show B (the divider, its handle and the
            side labels along the bottom left out)."""
            shown = page.canvas_rgb()
            height, width = shown.shape[:2]
            xd = round(page.divider() * width)
            rows = slice(0, height - 30)
            is_a = (shown[rows] == single_a[rows]).all(axis=(0, 2))
            is_b = (shown[rows] == single_b[rows]).all(axis=(0, 2))
            far = np.abs(np.arange(width) - xd) > 8
            return xd, width, is_a, is_b, far

        xd, width, is_a, is_b, far = sides()
        assert xd == width // 2
        assert is_a[:xd][far[:xd]].all() and is_b[xd:][far[xd:]].all()
        assert not is_b[:xd][far[:xd]].any() and not is_a[xd:][far[xd:]].any()

        page.drag_divider(0.25)                         # the mouse moves the divider, the image stays
        assert page.divider() == 0.25
        xd2, width, is_a, is_b, far = sides()
        assert xd2 == round(0.25 * width)
        assert is_a[:xd2][far[:xd2]].all() and is_b[xd2:][far[xd2:]].all()
        assert is_b[xd2 + 9:xd - 8].all()               # these columns changed sides
        page.press("]")
        assert page.divider() == 0.3
        page.press("b")                                 # two strategies: b swaps the sides
        assert page.text(".vw-split-note") == "left of the divider: A good; right: B biased"
        single_a, single_b = single_b, single_a
        xd3, width, is_a, is_b, far = sides()
        assert is_a[:xd3][far[:xd3]].all() and is_b[xd3:][far[xd3:]].all()
        page.viewer().locator(".vw-side-a").select_option("biased")   # the lists pick the sides too
        assert page.text(".vw-split-note") == "left of the divider: A biased; right: B good"
        page.press("1")                                 # the reference is no side
        assert page.text(".vw-split-note").startswith("the split view compares two strategies")
        assert page.text(".vw-labels .vw-on") == "2 biased"
        page.press("ArrowRight")                        # A steps onto B: the sides swap
        assert page.text(".vw-split-note") == "left of the divider: A good; right: B biased"
        page.press("ArrowRight")                        # past the reference, back to biased
        assert page.text(".vw-split-note") == "left of the divider: A biased; right: B good"
        page.hover(fx=0.1)
        assert page.text(".vw-status >> nth=1").startswith("A biased, pixel")
        page.press("s")
        assert not split.is_checked() and (page.canvas_rgb() == single_b).all()   # A (biased) alone
        assert page.errors == []


@pytest.mark.slow
def test_one_strategy_signed_view_works_and_split_is_disabled(single):
    with open_page(single / "report" / "index.html") as page:
        split = page.viewer().locator(".vw-split-on")
        assert split.is_disabled() and not split.is_checked()
        assert page.text(".vw-split-note") == "the split view needs two strategies; this comparison has one"
        page.press("s")
        assert not split.is_checked()
        page.press("2")
        page.press("d")
        shown = page.canvas_rgb().astype(int)
        r, g, b = shown[at(10, 8)[1], at(10, 8)[0]]
        assert r > b + 60
        r, g, b = shown[at(18, 8)[1], at(18, 8)[0]]
        assert b > r + 60
        assert page.errors == [] and page.broken_images() == 0
