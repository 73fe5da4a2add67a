"""`mitsuba-lab check` (src/mitsuba_lab/check/, commands/check.py), driven through add_arguments / run."""
import argparse
import csv
import io
import os
import re

import mitsuba as mi
import numpy as np
import pytest

from mitsuba_lab import check
from mitsuba_lab.check import verdicts as check_verdicts
from mitsuba_lab.commands import check as check_command
from mitsuba_lab.check.verdicts import SKEW_MIN, BiasRung, Empty, Rung, Twin, Verdict, judge, judge_consistent
from mitsuba_lab.errors import LabError
from mitsuba_lab.scene import make_integrator
from mitsuba_lab.scene_xml import scene_defaults

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STIFF = os.path.join(ROOT, "scenes", "stiff")
SMALL = ["--res", "16", "--spp", "16", "--ref-spp", "64", "--splits", "4", "--max-depth", "6"]


@pytest.fixture(autouse=True)
def _private_reference_cache(tmp_path, monkeypatch):
    """References go to a cache of the test's own (``--cache`` defaults to $MITSUBA_LAB_CACHE)."""
    monkeypatch.setenv("MITSUBA_LAB_CACHE", str(tmp_path / "cache"))


@pytest.fixture(autouse=True)
def _path_tracers_unless_asked(request, monkeypatch):
    """The path tracers only (check's strategies before the bidirectional ones), unless a test
    is marked ``all_strategies``: the older tests' budgets and times stay as they were."""
    if "all_strategies" not in request.keywords:
        monkeypatch.setattr(check, "STRATEGIES", dict(check.PATH_STRATEGIES))


def run_check(argv):
    parser = argparse.ArgumentParser(prog="mitsuba-lab check")
    check_command.add_arguments(parser)
    out = io.StringIO()
    status = check_command.run(parser.parse_args(argv), out)
    return status, out.getvalue()


def read_rows(prefix):
    with open(f"{prefix}.csv", newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.mark.slow
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


@pytest.mark.slow
def test_a_light_never_found_is_a_heavy_tail_warning(tmp_path, monkeypatch):
    # BSDF sampling never hits a light of radius 5e-4 (about once in 1e7 paths): lab_naive's
    # mean is 0 at every budget. Unbiased but unconverged: a warning, not a failure.
    monkeypatch.setattr(check, "STRATEGIES", {k: check.STRATEGIES[k] for k in ("lab_naive", "lab_nee")})
    prefix = str(tmp_path / "report")
    status, text = run_check([os.path.join(STIFF, "tiny_bright_light.xml"), *SMALL, "-o", prefix])
    assert status == 0, text
    rows = {r["strategy"]: r for r in read_rows(prefix)}
    naive = rows["lab_naive"]
    assert naive["status"] == "WARN: heavy tail" and float(naive["mean"]) == 0 and float(naive["z"]) < -5
    assert naive["note"].startswith("unconverged: heavy-tailed estimator: no sample found the light")
    assert "every sample was 0 (the reference is not) carry 100% of the deficit" in naive["evidence"]
    assert "budget x1, x4, x16" in naive["evidence"]
    assert rows["lab_nee"]["status"] == "ok"
    assert "WARNING  tiny_bright_light.xml  lab_naive: unconverged: heavy-tailed estimator" in text
    assert "0 failure(s), 1 heavy-tail warning(s)" in text
    assert "class='warn'" in open(f"{prefix}.html").read()


@pytest.mark.slow
def test_nee_on_a_near_delta_lobe_is_a_heavy_tail_warning(tmp_path, monkeypatch):
    """An emitter sample lands in the GGX alpha 1e-4 lobe about once in 1e5: lab_nee is 60% low
    at 64 spp (z < -5), and its rare hits show at 16x the budget as split means of skewness
    >= 2 (check_verdicts.SKEW_MIN). Check's default budget, fixed seeds."""
    monkeypatch.setattr(check, "STRATEGIES", {"lab_nee": check.STRATEGIES["lab_nee"]})
    prefix = str(tmp_path / "report")
    status, text = run_check([os.path.join(STIFF, "near_delta_glossy.xml"), "-o", prefix])
    assert status == 0, text
    nee = {r["strategy"]: r for r in read_rows(prefix)}["lab_nee"]
    assert nee["status"] == "WARN: heavy tail" and float(nee["z"]) < -5, nee
    assert "a few seeds carry the sum" in nee["note"]
    skew = float(re.search(r"split means at x16: skewness ([-+0-9.]+)", nee["evidence"]).group(1))
    assert skew >= SKEW_MIN


def perturbed_mis(factor):
    """lab_mis with its result multiplied by ``factor``: a deliberate weight error."""
    base = type(make_integrator("lab_mis", {}))

    class Perturbed(base):
        def sample(self, scene, sampler, ray, medium=None, active=True):
            spec, valid, aovs = super().sample(scene, sampler, ray, medium, active)
            return spec * factor, valid, aovs
    return Perturbed


@pytest.fixture
def perturbed_strategies(monkeypatch):
    for name, factor in (("check_test_x103", 1.03), ("check_test_x097", 0.97)):
        cls = perturbed_mis(factor)
        mi.register_integrator(name, lambda props, cls=cls: cls(props))
    monkeypatch.setattr(check, "STRATEGIES", {"lab_mis_power": check.STRATEGIES["lab_mis_power"],
                                              "x1.03": ("check_test_x103", {}), "x0.97": ("check_test_x097", {})})


@pytest.mark.slow
def test_a_3_percent_weight_error_fails(tmp_path, perturbed_strategies):
    """The power of check's z-test with the tail classifier in the loop: lab_mis x1.03 and
    x0.97 on the environment-lit stage, 24x24, 64 spp against 256 spp: |z| > 5 and both fail
    as biased (the low one after 4x and 16x the budget: its deficit holds and |z| grows as a
    light-tailed bias's would, within 30%), while lab_mis itself passes."""
    prefix = str(tmp_path / "report")
    status, text = run_check([os.path.join(STIFF, "environment_only.xml"), "--res", "24", "--spp", "64",
                              "--ref-spp", "256", "--splits", "4", "--max-depth", "6", "-o", prefix])
    assert status == 1, text
    rows = {r["strategy"]: r for r in read_rows(prefix)}
    assert rows["lab_mis_power"]["status"] == "ok"
    high, low = rows["x1.03"], rows["x0.97"]
    assert high["status"].startswith("FAIL: mean off") and float(high["z"]) > 5
    assert "an unresolved tail only ever leaves a mean low" in high["note"]
    assert low["status"].startswith("FAIL: mean off") and float(low["z"]) < -5
    assert low["note"].startswith("bias: mean -") and "its deficit holds" in low["note"]
    # the deficit held and |z| grew as a light-tailed bias's does (capped by the reference's error)
    predicted, measured = map(float, re.search(r"would reach z ([-+0-9.]+) at x16 \(measured ([-+0-9.]+)\)",
                                               low["evidence"]).groups())
    assert measured < float(low["z"]) and abs(measured / predicted - 1) < 0.3, low["evidence"]
    assert "FAIL  environment_only.xml  x0.97: bias" in text


@pytest.mark.slow
def test_scene_warnings(tmp_path):
    prefix = str(tmp_path / "report")
    status, text = run_check([os.path.join(STIFF, "scaled_1e4.xml"), *SMALL, "-D", "far_clip=1e4",
                              "-o", prefix])
    assert "beyond far_clip = 1e+04" in text
    assert "not compared with its unscaled twin ../cornell_box.xml: it loses geometry beyond far_clip" in text
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


@pytest.mark.slow
def test_a_user_scene_without_a_res_default(tmp_path):
    # No <default name="res">: --res sets the film's larger side, keeping its aspect ratio (300x200
    # -> 8x5), instead of failing with "unused parameters: $res".
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
    assert float(rows["lab_nee"]["camera_rays_per_pixel"]) == 16      # rays / (8 x 5 pixels): the film is 8x5
    assert float(rows["lab_nee"]["mean"]) > 0
    film = check.load_check_scene(str(scene), 8, {}).sensors()[0].film().size()
    assert (film[0], film[1]) == (8, 5)
    # the output says what film it rendered (issue 42 follow-up, item 6: the header said "--res 8" only)
    print(text.splitlines()[:3])
    assert "my_scene.xml: film 8x5 pixels (width x height), as rendered" in text
    assert {r["film"] for r in rows.values()} == {"8x5"}


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
    (["-D", "twin=x.xml"], "-D twin=... is not a scene parameter"),
])
def test_bad_input_is_one_line_error(argv, message):
    with pytest.raises(LabError, match=message.replace("(", r"\(")):
        run_check(argv)


# -- Bias or heavy tail: the classifier on synthetic split means (check_verdicts.judge) ---------

def synthetic_ladder(rng, bias=0.0, tail_share=0.0, p=1e-6, n0=32768):
    """Split means of an estimator of mean 1 x (1 + bias) at 1x, 4x and 16x a budget of n0
    samples per split (8 splits, then 32, as check renders them): a light part (per sample
    Gamma(1/2), skewness 2.8) and a rare part (a sample worth tail_share / p, probability p)."""
    rungs = []
    for factor, splits in ((1, 8), (4, 32), (16, 32)):
        n = n0 * factor
        light = (1 - tail_share) * (1 + bias) * rng.gamma(n / 2, 2 / n, size=splits)
        rare = tail_share / p * rng.binomial(n, p, size=splits) / n
        rungs.append(Rung(factor, 8 * factor, light + rare))
    return rungs


REF_MEAN, REF_VARIANCE = 1.0, 0.002 ** 2


@pytest.mark.slow
def test_judge_tells_a_bias_from_a_heavy_tail():
    """300 trials each, fixed seed. A 3% low bias with a light tail is flagged (|z| > 5) in at
    least 95% of trials and then always called a bias, never a heavy tail; an unbiased estimator
    with 60% of its mean in events of probability 5e-7 (0.13 expected in the first budget) is
    flagged as often and called a heavy tail in at least 90% of those; a mean 3% high is a bias
    without larger budgets."""
    rng = np.random.default_rng(15)
    bias = [judge(synthetic_ladder(rng, bias=-0.03), REF_MEAN, REF_VARIANCE, 5.0).kind for _ in range(300)]
    assert bias.count("ok") <= 15 and bias.count("heavy tail") == 0
    tail = [judge(synthetic_ladder(rng, tail_share=0.6, p=5e-7), REF_MEAN, REF_VARIANCE, 5.0).kind
            for _ in range(300)]
    flagged = len(tail) - tail.count("ok")
    assert flagged >= 240 and tail.count("heavy tail") >= 0.9 * flagged
    high = judge(synthetic_ladder(rng, bias=0.03)[:1], REF_MEAN, REF_VARIANCE, 5.0)
    assert high.kind == "bias" and "above the reference" in high.summary


def test_judge_reasons_and_evidence():
    rng = np.random.default_rng(4)
    verdict = judge(synthetic_ladder(rng, tail_share=0.6, p=5e-7), REF_MEAN, REF_VARIANCE, 5.0)
    assert verdict.kind == "heavy tail" and verdict.summary.startswith(check_verdicts.HEAVY_TAIL)
    assert verdict.evidence[0].startswith("budget x1, x4, x16 (8, 32, 128 spp per split, 8, 32, 32 splits)")
    assert "would reach z" in verdict.evidence[1] and "split means at x16: skewness" in verdict.evidence[2]
    # never a single sample with light: only the empty pixels can tell (rule of three)
    dark = [Rung(f, 8 * f, np.zeros(n)) for f, n in ((1, 8), (4, 32), (16, 32))]
    verdict = judge(dark, REF_MEAN, REF_VARIANCE, 5.0, Empty(share=1.0, pixels=1024, samples=1024 * 5184))
    assert verdict.kind == "heavy tail" and "no sample found the light" in verdict.summary
    assert "events rarer than 1 in 1.8e+06" in verdict.evidence[-1]
    assert judge(dark, REF_MEAN, REF_VARIANCE, 5.0, Empty(share=0.3, pixels=9, samples=9 * 5184)).kind == "bias"
    # no larger budgets (--escalate 1): a light-tailed low mean is a bias
    assert judge(synthetic_ladder(rng, bias=-0.05)[:1], REF_MEAN, REF_VARIANCE, 5.0).kind == "bias"


def test_skewness_and_top_share():
    outlier = np.r_[np.zeros(31), 1.0]
    assert check_verdicts.skewness(outlier) == pytest.approx(30 / np.sqrt(31))
    assert check_verdicts.skewness(np.ones(5)) == 0.0
    assert Rung(16, 128, outlier).top_share() == (3, 1.0)
    assert check_verdicts.ladder_factors(16) == [4, 16] and check_verdicts.ladder_factors(1) == []


# -- A reference that is wrong: scaled scenes against their unscaled twin -------------------------

def test_twin_status_in_both_states():
    """Mitsuba's path 8% dark against the twin: a strategy that agrees with the twin is ok (before
    the lab's scale-robust offsets: it fails with path, 'both disagree'); one off both fails."""
    twin = Twin.compare("../cornell_box.xml", 0.1566, 1e-7, 0.1435, 1e-7)
    assert twin.path_off(5.0) and twin.rel_path == pytest.approx(-0.0837, abs=1e-3)
    status, note = check_verdicts.twin_status(Verdict("ok"), 30.0, -0.001, twin, 5.0)
    assert status == "ok" and "Mitsuba's path is off here" in note and "not the lab's estimator" in note
    status, note = check_verdicts.twin_status(Verdict("bias"), -0.3, -0.085, twin, 5.0)
    assert status == "FAIL: ray offsets" and "reference and estimator both disagree with the unscaled twin" in note
    status, note = check_verdicts.twin_status(Verdict("bias"), 40.0, 0.38, twin, 5.0)
    assert status == "FAIL: off the twin"
    assert check_verdicts.twin_status(Verdict("heavy tail", "unconverged: x"), -9, -0.5, twin, 5.0)[0] == \
        "WARN: heavy tail"
    assert not Twin.compare("t", 0.1566, 1e-6, 0.1565, 1e-6).path_off(5.0)


@pytest.mark.slow
def test_scaled_scenes_against_their_twin(tmp_path, monkeypatch):
    """scaled_1e-4: Mitsuba's path is 8% dark against path on the unscaled box, the lab's
    scale-robust lab_nee agrees with the box (ok), and Mitsuba's path run as a strategy (what
    the lab's estimators rendered with Mitsuba's offsets) fails as 'both disagree'.
    scaled_1e4: path agrees with the box. Check's default budget, fixed seeds."""
    monkeypatch.setattr(check, "STRATEGIES", {"lab_nee": check.STRATEGIES["lab_nee"],
                                              "mitsuba_path": ("path", {})})
    prefix = str(tmp_path / "report")
    status, text = run_check([os.path.join(STIFF, n) for n in ("scaled_1e-4.xml", "scaled_1e4.xml")]
                             + ["-o", prefix])
    assert status == 1, text
    by = {(r["scene"], r["strategy"]): r for r in read_rows(prefix)}
    ref = by[("scaled_1e-4.xml", "path (reference)")]
    assert ref["status"] == "reference: OFF" and float(ref["z"]) < -5
    assert "Mitsuba's path is off on this scene" in ref["note"] and "ray offsets at this scale" in ref["note"]
    assert float(ref["mean"]) < 0.95 * float(by[("scaled_1e-4.xml", "path (twin)")]["mean"])
    nee = by[("scaled_1e-4.xml", "lab_nee")]
    assert nee["status"] == "ok" and abs(float(nee["z_twin"])) <= 5 and "not the lab's estimator" in nee["note"]
    dark = by[("scaled_1e-4.xml", "mitsuba_path")]
    assert dark["status"] == "FAIL: ray offsets" and "both disagree with the unscaled twin" in dark["note"]
    big = by[("scaled_1e4.xml", "path (reference)")]
    assert big["status"] == "reference" and "agrees with the unscaled twin" in big["note"]
    assert by[("scaled_1e4.xml", "lab_nee")]["status"] == "ok"
    assert "REFERENCE OFF  scaled_1e-4.xml" in text and "from the cache" in by[("scaled_1e4.xml", "path (twin)")]["note"]


def test_a_missing_twin_is_one_line(tmp_path):
    scene = tmp_path / "lonely.xml"
    scene.write_text(USER_SCENE.replace('<scene version="3.0.0">',
                                        '<scene version="3.0.0">\n<default name="twin" value="nowhere.xml"/>'))
    with pytest.raises(LabError, match="its twin scene nowhere.xml is not found"):
        run_check([str(scene), *SMALL])


@pytest.mark.slow
@pytest.mark.all_strategies
def test_bidirectional_and_consistent_strategies_are_checked(tmp_path, monkeypatch):
    """lab_bdpt and lab_vcm's bpt pass the z-test (the same image: lab_vcm's bpt is lab_bdpt's
    estimator); lab_vcm's vcm and ppm and lab_photon are consistent: no "agrees" for them, their
    note says what their bias^2 showed (here, 16x16 at 16 spp, none resolved: nothing claimed).
    Their rays count, the bidirectional kinds summed in other_rays_per_pixel."""
    monkeypatch.setattr(check, "STRATEGIES", dict(check.BIDIRECTIONAL_STRATEGIES))
    prefix = str(tmp_path / "report")
    status, text = run_check([os.path.join(ROOT, "scenes", "cornell_box.xml"), *SMALL, "-o", prefix])
    assert status == 0, text
    rows = {r["strategy"]: r for r in read_rows(prefix)}
    assert rows["lab_bdpt"]["status"] == "ok" and rows["lab_vcm_bpt"]["status"] == "ok"
    assert float(rows["lab_bdpt"]["z"]) == pytest.approx(float(rows["lab_vcm_bpt"]["z"]), abs=1e-3)   # (float atomics)
    for name in ("lab_vcm", "lab_vcm_ppm", "lab_photon"):
        row = rows[name]
        assert row["status"] == "ok" and row["note"].startswith("consistent estimator: no bias resolved"), row
        assert "convergence not measured" in row["note"] and "agree" not in row["note"]
    for name in check.BIDIRECTIONAL_STRATEGIES:
        assert float(rows[name]["camera_rays_per_pixel"]) == 16 and float(rows[name]["other_rays_per_pixel"]) > 0


def test_a_consistent_estimator_converges_only_where_its_bias_shrinks():
    """judge_consistent: a resolved bias^2 that falls by more than 3 standard errors from x1 to
    x16 is "converging" with its log-log slope; one that holds fails; an unresolved one claims
    nothing."""
    falling = [BiasRung(1, 8, 4e-4, 2e-5), BiasRung(4, 32, 2e-4, 2e-5), BiasRung(16, 128, 1e-4, 2e-5)]
    verdict = judge_consistent(falling, 0.2)
    assert verdict.kind == "converging" and verdict.summary.startswith("converging: bias^2 0.0004 -> 0.0001")
    assert "slope -0.50" in verdict.summary
    steady = [BiasRung(1, 8, 4e-4, 2e-5), BiasRung(16, 128, 3.9e-4, 2e-5)]
    assert judge_consistent(steady, 0.2).kind == "bias"
    assert judge_consistent(steady, 0.2).summary.startswith("not converging")
    quiet = judge_consistent([BiasRung(1, 8, 1e-5, 2e-5)], 0.2)
    assert quiet.kind == "ok" and "convergence not measured" in quiet.summary
