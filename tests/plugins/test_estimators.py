"""The estimators' own knowledge (plugins/integrators/estimator.py and the classes it finds):
which scenes each lab integrator can render, what its sample count means, and the plugin
registration that finds them. lab_photon's limits are new here: scenes it cannot render are
left out of a sweep with the reason."""
import os
import subprocess
import sys

import mitsuba as mi
import pytest

import mitsuba_lab
from backend import variant
from mitsuba_lab.experiment.pipeline.config import PASS_PARAMETER, PluginSpec, parse_config, sample_count_plugin
from mitsuba_lab.experiment.pipeline.plan import build_plan
from mitsuba_lab.plugins.integrators.estimator import lookup
from mitsuba_lab.scene import ALL_LAB_INTEGRATORS, SceneTraits, strategy_applicability

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

PLASTIC_XML = """<scene version="3.0.0">
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="sphere" id="ball"><bsdf type="plastic"/></shape>
    <shape type="rectangle" id="floor">
        <transform name="to_world"><scale value="4"/><translate z="-1"/></transform>
        <bsdf type="diffuse"/>
    </shape>
    <emitter type="constant"/>
</scene>"""


def traits_of(scene_dict):
    return SceneTraits.from_scene(mi.load_dict(scene_dict))


def plastic_scene(bsdf):
    return {"type": "scene", "ball": {"type": "sphere", "bsdf": bsdf},
            "floor": {"type": "rectangle", "bsdf": {"type": "diffuse"}}, "light": {"type": "constant"}}


@pytest.mark.parametrize("bsdf", [
    {"type": "plastic"},
    {"type": "mask", "opacity": 0.5, "inner": {"type": "diffuse"}},
    {"type": "blendbsdf", "weight": 0.5, "a": {"type": "conductor"}, "b": {"type": "diffuse"}},
    {"type": "twosided", "inner": {"type": "plastic"}},
])
@pytest.mark.parametrize("direct", ["photons", "nee"])
def test_photon_applies_where_a_bsdf_mixes_delta_and_smooth_lobes(bsdf, direct):
    """Its camera paths continue through the delta lobes (tests/plugins/test_photon_scenes.py
    shows the light is there)."""
    t = traits_of(plastic_scene(bsdf))
    assert len(t.mixed_bsdfs) == 1
    for kind, params in (("lab_photon", {"direct": direct}), ("lab_naive", {}), ("lab_nee", {}),
                         ("lab_mis", {}), ("path", {})):
        assert strategy_applicability(t, kind, params) == (True, "")


def test_photon_applies_to_smooth_and_purely_delta_bsdfs():
    for bsdf in ({"type": "diffuse"}, {"type": "roughplastic"}, {"type": "dielectric"}, {"type": "conductor"},
                 {"type": "null"}):
        t = traits_of(plastic_scene(bsdf))
        assert t.mixed_bsdfs == () and strategy_applicability(t, "lab_photon", {}) == (True, ""), bsdf


def test_photon_renders_media_and_is_left_out_without_emitters():
    medium = {"type": "scene", "ball": {"type": "sphere", "bsdf": {"type": "null"},
                                        "interior": {"type": "homogeneous", "albedo": 0.5, "sigma_t": 1.0}},
              "light": {"type": "constant"}}
    assert strategy_applicability(traits_of(medium), "lab_photon", {}) == (True, "")
    applies, reason = strategy_applicability(traits_of(medium), "lab_photon", {"hide_emitters": True})
    assert not applies and reason == "lab_photon does not support hide_emitters in scenes with participating media yet"
    applies, reason = strategy_applicability(traits_of({"type": "scene", "ball": {"type": "sphere"}}),
                                             "lab_photon", {})
    assert not applies and "needs an emitter" in reason


def test_a_sweep_keeps_lab_photon_in_a_plastic_scene(tmp_path):
    from mitsuba_lab.experiment.sweep import assess_scene

    (tmp_path / "plastic.xml").write_text(PLASTIC_XML)
    config = parse_config({"experiment": {"spp": [4]},
                           "scenes": {"plastic": {"path": "plastic.xml"},
                                      "cornell": {"path": os.path.join(ROOT, "scenes", "cornell_box.xml"),
                                                  "resolution": 8}},
                           "strategies": {"mis": {"type": "lab_mis"}, "ppm": {"type": "lab_photon"}}},
                          str(tmp_path / "x.toml"))
    plan = build_plan(config, assess_scene)
    assert plan.left_out == []
    assert sorted(p.strategy for p in plan.points) == ["mis", "mis", "ppm", "ppm"]


def test_photon_strategies_are_the_same_estimator_after_defaults():
    from mitsuba_lab.scene import equivalence_reason, equivalent_strategies

    t = traits_of(plastic_scene({"type": "diffuse"}))
    same = equivalent_strategies(t, {"a": ("lab_photon", {}), "b": ("lab_photon", {"alpha": 2.0 / 3.0}),
                                     "c": ("lab_photon", {"direct": "photons"})})
    assert same == {"a": "a", "b": "a", "c": "c"}
    assert equivalence_reason(t, "lab_photon", {}) == "same parameters (lab_photon)"


# -- What the sample count means --------------------------------------------------------------

def test_sample_count_parameter_is_the_plugins():
    assert dict(PASS_PARAMETER) == {"lab_photon": "passes"}
    assert PASS_PARAMETER.get("lab_mis") is None and PASS_PARAMETER.get("path") is None
    assert "lab_photon" in PASS_PARAMETER and len(PASS_PARAMETER) == 1
    photon = type(mi.load_dict({"type": "lab_photon"}))
    assert photon.ESTIMATOR.SAMPLE_COUNT_PARAMETER == "passes" == PASS_PARAMETER["lab_photon"]
    spec = PluginSpec("ppm", "lab_photon", {"alpha": 0.5})
    assert sample_count_plugin(spec, 12) == (PluginSpec("ppm", "lab_photon", {"alpha": 0.5, "passes": 12}), 1)


def test_estimators_need_no_variant():
    """The report and the `plugins` command run without a Mitsuba variant: the estimators'
    knowledge (here the sample-count parameter) is there without importing Mitsuba."""
    code = ("import os, sys\n"
            "os.environ['MITSUBA_LAB_ACTIVATE'] = '0'\n"   # as the mitsuba-lab command imports it
            "from mitsuba_lab.experiment.pipeline.config import PASS_PARAMETER\n"
            "from mitsuba_lab.plugins.integrators.estimator import lookup\n"
            "print(dict(PASS_PARAMETER), lookup('lab_naive').SIMPLICITY, 'mitsuba' in sys.modules)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "{'lab_photon': 'passes'} 0 False"


def test_every_lab_integrator_has_an_estimator_its_plugin_class_uses():
    for name in ALL_LAB_INTEGRATORS:
        estimator = lookup(name)
        assert estimator is not None and estimator.plugin_name == name
        plugin = type(mi.load_dict({"type": name}))
        assert plugin.ESTIMATOR is estimator and plugin.PARAMETERS is estimator.PARAMETERS
    assert lookup("path") is None


# -- Registration (the module list itself: tests/test_layout.py) ----------------------------

@pytest.mark.slow
def test_photon_follows_a_variant_switch():
    import numpy as np

    original = mi.variant()
    if variant("ad_mono") not in mi.variants():
        pytest.skip(f"this Mitsuba build has no {variant('ad_mono')}")
    try:
        mitsuba_lab.use_variant(variant("ad_mono"))
        integrator = mi.load_dict({"type": "lab_photon", "photons_per_pass": 2000, "passes": 1, "max_depth": 4})
        image = np.array(mi.render(mi.load_dict(mi.cornell_box()), integrator=integrator, spp=1))
        assert image.shape[-1] == 1 and np.isfinite(image).all() and image.mean() > 0
    finally:
        mitsuba_lab.use_variant(original)
    assert type(mi.load_dict({"type": "lab_photon"})).__name__ == "LabPhotonIntegrator"
