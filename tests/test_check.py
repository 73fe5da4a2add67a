"""`mitsuba-lab check` (src/mitsuba_lab/check.py), driven through add_arguments / run."""
import argparse
import csv
import io
import os

import numpy as np
import pytest

from mitsuba_lab import check
from mitsuba_lab.errors import LabError
from mitsuba_lab.scene_xml import scene_defaults

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STIFF = os.path.join(ROOT, "scenes", "stiff")
SMALL = ["--res", "16", "--spp", "16", "--ref-spp", "64", "--splits", "4", "--max-depth", "6"]


@pytest.fixture(autouse=True)
def _private_reference_cache(tmp_path, monkeypatch):
    """References go to a cache of the test's own (``--cache`` defaults to $MITSUBA_LAB_CACHE)."""
    monkeypatch.setenv("MITSUBA_LAB_CACHE", str(tmp_path / "cache"))


def run_check(argv):
    parser = argparse.ArgumentParser(prog="mitsuba-lab check")
    check.add_arguments(parser)
    out = io.StringIO()
    status = check.run(parser.parse_args(argv), out)
    return status, out.getvalue()


def read_rows(prefix):
    with open(f"{prefix}.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def test_passing_scenes_write_csv_and_html(tmp_path):
    prefix = str(tmp_path / "report")
    scenes = [os.path.join(STIFF, n) for n in ("delta_lights_only.xml", "all_specular.xml")]
    status, text = run_check([*scenes, *SMALL, "-o", prefix])
    assert status == 0, text
    rows = read_rows(prefix)
    by = {(r["scene"], r["strategy"]): r for r in rows}
    naive = by[("delta_lights_only.xml", "lab_naive")]
    assert naive["status"] == "skipped" and "cannot reach delta lights" in naive["note"]
    assert by[("delta_lights_only.xml", "lab_mis_power")]["status"] == "same"
    assert "the same estimator as lab_nee" in by[("delta_lights_only.xml", "lab_mis_power")]["note"]
    for strategy in ("lab_nee", "lab_mis_power", "lab_mis_balance"):
        row = by[("all_specular.xml", strategy)]
        assert row["status"] == "same" and float(row["shadow_rays_per_pixel"]) == 0
    ran = [r for r in rows if r["status"] == "ok"]
    assert ran and all(float(r["finite_fraction"]) == 1 and int(r["negative_pixels"]) == 0 for r in ran)
    assert float(by[("all_specular.xml", "lab_naive")]["camera_rays_per_pixel"]) == 16
    html = open(f"{prefix}.html").read()
    assert "<table>" in html and "firefly" in html.lower()
    assert "lab_naive cannot reach delta lights" in text


def test_an_unconverged_strategy_fails(tmp_path):
    # BSDF sampling never hits a light of radius 5e-4: lab_naive's mean is 0 with no spread.
    prefix = str(tmp_path / "report")
    status, text = run_check([os.path.join(STIFF, "tiny_bright_light.xml"), *SMALL, "-o", prefix])
    assert status == 1
    rows = {r["strategy"]: r for r in read_rows(prefix)}
    assert rows["lab_naive"]["status"].startswith("FAIL: mean off")
    assert "no spread" in rows["lab_naive"]["note"]
    assert rows["lab_nee"]["status"] == "ok"


def test_scene_warnings(tmp_path):
    prefix = str(tmp_path / "report")
    status, text = run_check([os.path.join(STIFF, "scaled_1e4.xml"), *SMALL, "-D", "far_clip=1e4",
                              "-o", prefix])
    assert "beyond far_clip = 1e+04" in text
    status, text = run_check([os.path.join(STIFF, "zero_emitters.xml"), *SMALL, "-o", prefix])
    assert text.count("emits nothing") == 2


USER_SCENE = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="300"/><integer name="height" value="200"/></film>
    </sensor>
    <shape type="sphere"><float name="radius" value="0.8"/><bsdf type="diffuse"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.5"/><rotate x="1" angle="90"/><translate y="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="10"/></emitter>
    </shape>
</scene>
"""


def test_a_user_scene_without_a_res_default(tmp_path):
    # No <default name="res">: --res sets the film's width and height instead of failing with
    # "unused parameters: $res".
    scene = tmp_path / "my_scene.xml"
    scene.write_text(USER_SCENE)
    assert set(scene_defaults(str(scene))) == set()
    assert set(scene_defaults(os.path.join(STIFF, "all_specular.xml"))) >= {"res", "spp"}
    prefix = str(tmp_path / "report")
    status, text = run_check([str(scene), "--res", "8", "--spp", "16", "--ref-spp", "32", "--splits", "4",
                              "--max-depth", "3", "-o", prefix])
    assert status == 0, text
    rows = {r["strategy"]: r for r in read_rows(prefix)}
    assert {"lab_naive", "lab_nee", "lab_mis_power", "lab_mis_balance"} <= set(rows)
    assert float(rows["lab_nee"]["camera_rays_per_pixel"]) == 16      # rays / (8 x 8 pixels): the film is 8x8
    assert float(rows["lab_nee"]["mean"]) > 0
    film = check.load_check_scene(str(scene), 8, {}).sensors()[0].film().size()
    assert (film[0], film[1]) == (8, 8)


def test_firefly_rule():
    image = np.full((9, 9, 3), 0.1, dtype=np.float32)
    image[4, 4] = 1.5          # 15 x the local median: a firefly at k = 10
    image[1, 1] = 0.9          # 9 x: not one
    assert check.firefly_count(image, 10.0, floor=1e-3) == 1
    black = np.zeros((9, 9, 3), dtype=np.float32)
    black[2, 2] = 0.005        # below k x floor
    assert check.firefly_count(black, 10.0, floor=1e-3) == 0


def test_z_score_limits():
    """z of the splits' mean luminance against the reference's (metrics.z_score): equal means
    give 0 with or without spread, a difference without any spread is infinite."""
    ones = np.ones((2, 4, 4, 3))                        # luminance 1 (the weights sum to 1)
    ref = {"mean": 1.0, "mean_variance": 0.0, "finite": True}
    assert check.measure(ones, {}, 0.0, ref, 10.0)["z"] == 0.0
    assert check.measure(0 * ones, {}, 0.0, ref, 10.0)["z"] == -np.inf
    spread = np.concatenate([0.5 * ones[:1], 1.5 * ones[:1]])
    assert check.measure(spread, {}, 0.0, ref, 10.0)["z"] == 0.0
    z = check.measure(spread, {}, 0.0, {**ref, "mean": 0.5, "mean_variance": 0.25}, 10.0)["z"]
    assert z == pytest.approx(0.5 / np.sqrt(0.5 / 2 + 0.25))       # split variance 0.5 over 2 splits


def test_reference_standard_error_from_its_pixel_variance():
    """The reference's variance of its mean luminance, from the per-pixel variance of its mean
    image: exact for independent pixels whose channels move together (here proportional), an
    upper bound when they do not (here independent)."""
    rng = np.random.default_rng(3)
    chunks = 8
    together = rng.gamma(0.5, size=(chunks, 6, 5, 1)) * np.array([1.0, 0.4, 0.1])
    apart = rng.gamma(0.5, size=(chunks, 6, 5, 3))
    for stack in (together, apart):
        variance_of_mean = stack.var(axis=0, ddof=1) / chunks
        exact = check.luminance(stack).var(axis=0, ddof=1).sum() / chunks / 30 ** 2
        estimate = check.reference_mean_variance(variance_of_mean)
        if stack is together:
            assert estimate == pytest.approx(exact, rel=1e-12)
        else:
            assert estimate > exact


def test_the_reference_comes_from_the_cache(tmp_path):
    """The second check of a scene reuses the cached path reference: same numbers, note says so."""
    scene = os.path.join(STIFF, "all_specular.xml")
    small = ["--res", "8", "--spp", "8", "--ref-spp", "16", "--splits", "2", "--max-depth", "4"]
    first, second = str(tmp_path / "first"), str(tmp_path / "second")
    run_check([scene, *small, "--cache", str(tmp_path / "refs"), "-o", first])
    run_check([scene, *small, "--cache", str(tmp_path / "refs"), "-o", second])
    a, b = read_rows(first), read_rows(second)
    assert "rendered into the cache" in a[0]["note"] and "from the cache" in b[0]["note"]
    assert a[0]["mean"] == b[0]["mean"] and [r["z"] for r in a] == [r["z"] for r in b]
    assert len(os.listdir(tmp_path / "refs")) == 3              # mean, variance, metadata


@pytest.mark.parametrize("argv, message", [
    (["no/such/scene.xml"], "scene file not found: no/such/scene.xml"),
    (["--spp", "10", "--splits", "4"], "--spp 10 is not a multiple of --splits 4"),
    (["--splits", "1", "--spp", "4", "--ref-spp", "4"], "--splits must be >= 2"),
    (["-o", "/no/such/folder/x"], "output folder does not exist"),
])
def test_bad_input_is_one_line_error(argv, message):
    with pytest.raises(LabError, match=message.replace("(", r"\(")):
        run_check(argv)
