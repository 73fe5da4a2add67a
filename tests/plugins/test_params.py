"""Declared, typed plugin parameters (plugins/params.py): messages, defaults, settings()."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import mitsuba_lab  # noqa: F401  (sets the variant, registers the plugins)
import mitsuba as mi

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.params import declared, resolve

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LAB_INTEGRATORS = ("lab_naive", "lab_nee", "lab_mis", "lab_photon", "lab_bdpt", "lab_vcm", "lab_pssmlt",
                   "lab_mmlt")
LAB_SAMPLERS = ("lab_independent", "lab_stratified", "lab_halton", "lab_sobol", "lab_zsobol")
MIS_VALID = ("beta, count_rays, emitter_samples, equiangular_samples, heuristic, hide_emitters, majorant_resolution, "
             "majorants, max_depth, medium_sampling, rr_depth, spectral_mis, transmittance")


def load_error(d: dict) -> str:
    """The last line of Mitsuba's message when instantiating ``d`` fails."""
    with pytest.raises(RuntimeError) as err:
        mi.load_dict(d)
    return str(err.value).strip().splitlines()[-1]


# ---------------------------------------------------------------------------
# Messages
# ---------------------------------------------------------------------------
MESSAGES = [
    ("lab_mis", {"max_depth": 8.5}, "lab_mis: parameter 'max_depth' expects an integer, got 8.5"),
    ("lab_mis", {"rr_depth": "five"}, "lab_mis: parameter 'rr_depth' expects an integer, got 'five'"),
    ("lab_mis", {"rr_depth": 5.5}, "lab_mis: parameter 'rr_depth' expects an integer, got 5.5"),
    ("lab_mis", {"emitter_samples": True}, "lab_mis: parameter 'emitter_samples' expects an integer, got True"),
    ("lab_mis", {"beta": "abc"}, "lab_mis: parameter 'beta' expects a number, got 'abc'"),
    ("lab_mis", {"beta": False}, "lab_mis: parameter 'beta' expects a number, got False"),
    ("lab_mis", {"hide_emitters": 1}, "lab_mis: parameter 'hide_emitters' expects a boolean, got 1"),
    ("lab_mis", {"count_rays": "yes"}, "lab_mis: parameter 'count_rays' expects a boolean, got 'yes'"),
    ("lab_mis", {"heuristic": 2}, "lab_mis: parameter 'heuristic' expects a string, got 2"),
    ("lab_mis", {"heuristic": "pow"},
     "lab_mis: parameter 'heuristic' must be one of balance, power, max, average, got 'pow'"),
    ("lab_mis", {"rr_depth": 0}, "lab_mis: parameter 'rr_depth' must be an integer >= 1, got 0"),
    ("lab_mis", {"beta": 0}, "lab_mis: parameter 'beta' must be a finite number > 0, got 0.0"),
    ("lab_mis", {"beta": float("inf")}, "lab_mis: parameter 'beta' must be a finite number > 0, got inf"),
    ("lab_mis", {"emitter_samples": 0}, "lab_mis: parameter 'emitter_samples' must be an integer >= 1, got 0"),
    ("lab_nee", {"max_depth": -2},
     "lab_nee: parameter 'max_depth' must be -1 (unbounded) or an integer >= 0, got -2"),
    ("lab_naive", {"rr_depth": 0}, "lab_naive: parameter 'rr_depth' must be an integer >= 1, got 0"),
    ("lab_photon", {"max_depth": 0},
     "lab_photon: parameter 'max_depth' must be -1 (unbounded) or an integer >= 1, got 0"),
    ("lab_photon", {"direct": "both"}, "lab_photon: parameter 'direct' must be one of photons, nee, got 'both'"),
    ("lab_photon", {"alpha": 1}, "lab_photon: parameter 'alpha' must be a number in (0, 1), got 1.0"),
    ("lab_photon", {"passes": 2.5}, "lab_photon: parameter 'passes' expects an integer, got 2.5"),
    ("lab_photon", {"max_records": 10}, "lab_photon: parameter 'max_records' must be an integer >= 1024, got 10"),
    ("lab_sobol", {"sample_count": 0}, "lab_sobol: parameter 'sample_count' must be an integer >= 1, got 0"),
    ("lab_sobol", {"sample_count": 8.5}, "lab_sobol: parameter 'sample_count' expects an integer, got 8.5"),
    ("lab_independent", {"seed": -1}, "lab_independent: parameter 'seed' must be an integer in [0, 2^32), got -1"),
    ("lab_independent", {"seed": "x"}, "lab_independent: parameter 'seed' expects an integer, got 'x'"),
    ("lab_stratified", {"jitter": 1}, "lab_stratified: parameter 'jitter' expects a boolean, got 1"),
    ("lab_halton", {"randomization": "cranley"},
     "lab_halton: parameter 'randomization' must be one of permute_digits, owen, got 'cranley'"),
    ("lab_halton", {"sample_count": 3_000_000},
     "lab_halton: parameter 'sample_count' must be an integer in [1, 2097152], got 3000000"),
    ("lab_zsobol", {"width": -4}, "lab_zsobol: parameter 'width' must be an integer >= 0, got -4"),
]


@pytest.mark.parametrize("plugin, given, message", MESSAGES)
def test_resolve_messages(plugin, given, message):
    with pytest.raises(ValueError) as err:
        resolve(plugin, given)
    assert str(err.value) == message


@pytest.mark.parametrize("plugin, given, message", MESSAGES)
def test_plugin_messages_through_load_dict(plugin, given, message):
    assert load_error({"type": plugin, **given}) == f"ParameterError: {message}"


def test_the_error_is_a_value_error():
    assert issubclass(params.ParameterError, ValueError)


@pytest.mark.parametrize("element, message", [
    ('<string name="rr_depth" value="five"/>', "lab_mis: parameter 'rr_depth' expects an integer, got 'five'"),
    ('<float name="max_depth" value="8.5"/>', "lab_mis: parameter 'max_depth' expects an integer, got 8.5"),
    ('<integer name="hide_emitters" value="1"/>', "lab_mis: parameter 'hide_emitters' expects a boolean, got 1"),
    ('<string name="heuristic" value="pow"/>',
     "lab_mis: parameter 'heuristic' must be one of balance, power, max, average, got 'pow'"),
    ('<string name="heuristc" value="power"/>',
     f"lab_mis: unknown parameter 'heuristc'; valid parameters: {MIS_VALID}; did you mean 'heuristic'?"),
])
def test_messages_through_an_xml_scene(element, message):
    with pytest.raises(RuntimeError) as err:
        mi.load_string(f'<scene version="3.0.0"><integrator type="lab_mis">{element}</integrator></scene>')
    assert str(err.value).strip().splitlines()[-1] == f"ParameterError: {message}"


def test_integral_values_are_accepted_and_normalised():
    assert resolve("lab_mis", {"max_depth": 8.0, "beta": 3})["max_depth"] == 8
    assert type(resolve("lab_mis", {"max_depth": 8.0})["max_depth"]) is int
    assert type(resolve("lab_mis", {"beta": 3})["beta"]) is float
    assert mi.load_dict({"type": "lab_mis", "max_depth": 8.0}).settings()["max_depth"] == 8
    xml = '<scene version="3.0.0"><integrator type="lab_mis"><float name="max_depth" value="8"/></integrator></scene>'
    assert mi.load_string(xml).integrator().settings()["max_depth"] == 8
    sampler = mi.load_dict({"type": "lab_sobol", "sample_count": 8.0, "seed": 3.0})
    assert sampler.sample_count() == 8 and sampler.settings() == {"sample_count": 8, "seed": 3}


# ---------------------------------------------------------------------------
# Unknown names
# ---------------------------------------------------------------------------
def test_unknown_name_lists_the_valid_ones_with_a_suggestion():
    message = f"lab_mis: unknown parameter 'heuristc'; valid parameters: {MIS_VALID}; did you mean 'heuristic'?"
    assert load_error({"type": "lab_mis", "heuristc": "power"}) == f"ParameterError: {message}"
    with pytest.raises(ValueError) as err:
        resolve("lab_mis", {"heuristc": "power"})
    assert str(err.value) == message


def test_unknown_name_without_a_close_match():
    with pytest.raises(ValueError) as err:
        resolve("lab_nee", {"heuristic": "power"})
    assert str(err.value) == ("lab_nee: unknown parameter 'heuristic'; valid parameters: count_rays, "
                              "equiangular_samples, hide_emitters, majorant_resolution, majorants, max_depth, medium_sampling, rr_depth, "
                              "spectral_mis, transmittance")
    with pytest.raises(ValueError) as err:
        resolve("lab_zsobol", {"widht": 4, "zzz": 1})
    assert str(err.value) == ("lab_zsobol: unknown parameters 'widht', 'zzz'; valid parameters: sample_count, "
                              "seed, width; did you mean 'width' for 'widht'?")


def test_photon_takes_hide_emitters_as_the_path_tracers_do():
    assert resolve("lab_photon", {"hide_emitters": True})["hide_emitters"] is True
    assert load_error({"type": "lab_photon", "hide_emitters": 3}).endswith(
        "lab_photon: parameter 'hide_emitters' expects a boolean, got 3")


def test_mitsuba_base_parameters_and_nested_objects_are_left_to_mitsuba():
    # timeout is read by Mitsuba's SamplingIntegrator: accepted, passed through by resolve
    mi.load_dict({"type": "lab_mis", "timeout": 10.0})
    assert resolve("lab_mis", {"timeout": 10.0})["timeout"] == 10.0
    # a nested object is not ours to flag: Mitsuba reports it as unreferenced, as before
    text = load_error({"type": "lab_mis", "nested": {"type": "diffuse"}})
    assert "ParameterError" not in text
    with pytest.raises(RuntimeError, match='unreferenced property.*\n.*object "nested"'):
        mi.load_dict({"type": "lab_mis", "nested": {"type": "diffuse"}})


# ---------------------------------------------------------------------------
# resolve, declared, settings()
# ---------------------------------------------------------------------------
PATH_DEFAULTS = {"max_depth": -1, "rr_depth": 5, "hide_emitters": False, "count_rays": True}
MEDIA_DEFAULTS = {"majorants": "global", "majorant_resolution": 16, "spectral_mis": True}
DEFAULTS = {
    "lab_naive": PATH_DEFAULTS,
    "lab_nee": {**PATH_DEFAULTS, "medium_sampling": "distance", "equiangular_samples": 1, "transmittance": "ratio",
                **MEDIA_DEFAULTS},
    "lab_mis": {**PATH_DEFAULTS, "heuristic": "power", "beta": 2.0, "emitter_samples": 1, "medium_sampling": "mis",
                "equiangular_samples": 1, "transmittance": "ratio", **MEDIA_DEFAULTS},
    "lab_photon": {"photons_per_pass": 100_000, "passes": 16, "alpha": 2.0 / 3.0, "radius": 0.0, "radius_volume": 0.0,
                   "max_depth": -1, "rr_depth": 5, "direct": "nee", "max_records": 1 << 21,
                   "hide_emitters": False, "aim": 0.5, "aim_at": "specular"},
    "lab_pssmlt": {**PATH_DEFAULTS, "heuristic": "power", "beta": 2.0, "emitter_samples": 1, "medium_sampling": "mis",
                   "equiangular_samples": 1, "transmittance": "ratio", **MEDIA_DEFAULTS, "chains": 8192, "bootstrap": 100_000,
                   "bootstrap_share": 0.25, "large_step": 0.3, "small_step": "normal", "sigma": 0.01},
    "lab_mmlt": {"max_depth": 8, "heuristic": "power", "beta": 2.0, "chains": 8192, "bootstrap": 100_000,
                 "bootstrap_share": 0.25, "large_step": 0.3, "small_step": "normal", "sigma": 0.01},
    "lab_independent": {"sample_count": 4, "seed": 0},
    "lab_stratified": {"sample_count": 4, "seed": 0, "jitter": True},
    "lab_halton": {"sample_count": 4, "seed": 0, "randomization": "owen"},
    "lab_sobol": {"sample_count": 4, "seed": 0},
    "lab_zsobol": {"sample_count": 4, "seed": 0, "width": 0},
}


@pytest.mark.parametrize("plugin", sorted(DEFAULTS))
def test_resolve_fills_every_default(plugin):
    assert resolve(plugin, {}) == DEFAULTS[plugin]
    assert list(resolve(plugin, {})) == [p.name for p in declared(plugin)]


def test_declared_and_resolve_for_other_plugins():
    assert declared("path") is None and declared("independent") is None
    given = {"max_depth": 8.5, "anything": "goes"}
    out = resolve("path", given)
    assert out == given and out is not given
    assert set(params.lab_plugins()) == set(LAB_INTEGRATORS + LAB_SAMPLERS)


@pytest.mark.parametrize("plugin", LAB_INTEGRATORS + LAB_SAMPLERS)
def test_plugin_classes_reference_their_declarations(plugin):
    obj = mi.load_dict({"type": plugin})
    assert type(obj).PARAMETERS is declared(plugin)
    assert obj.settings() == resolve(plugin, {})


SETTINGS_CASES = [
    ("lab_naive", {"max_depth": 3, "rr_depth": 2}),
    ("lab_nee", {"max_depth": 0, "hide_emitters": True, "count_rays": False}),
    ("lab_mis", {"heuristic": "balance", "emitter_samples": 2, "max_depth": 8.0}),
    ("lab_mis", {"heuristic": "power", "beta": 1, "rr_depth": 3}),
    ("lab_photon", {"photons_per_pass": 20000, "passes": 2, "direct": "photons", "radius": 0.01, "max_depth": 4}),
    ("lab_independent", {"sample_count": 16, "seed": 7}),
    ("lab_stratified", {"sample_count": 9, "jitter": False}),
    ("lab_halton", {"sample_count": 8, "randomization": "permute_digits"}),
    ("lab_sobol", {"sample_count": 32, "seed": 2 ** 32 - 1}),
    ("lab_zsobol", {"sample_count": 16, "width": 128}),
]


@pytest.mark.parametrize("plugin, given", SETTINGS_CASES)
def test_settings_equal_resolve(plugin, given):
    obj = mi.load_dict({"type": plugin, **given})
    settings = obj.settings()
    assert settings == resolve(plugin, given)
    assert {k: type(v) for k, v in settings.items()} == {k: type(v) for k, v in resolve(plugin, given).items()}


def test_equivalent_strategies_normalise_parameters():
    from mitsuba_lab.scene import SceneTraits, equivalent_strategies, load_scene

    traits = SceneTraits.from_scene(load_scene("scenes/cornell_box.xml", res=8))
    same = equivalent_strategies(traits, {"a": ("lab_mis", {"max_depth": 8}),
                                          "b": ("lab_mis", {"max_depth": 8.0, "beta": 2, "heuristic": "power"}),
                                          "c": ("lab_mis", {"max_depth": 8, "count_rays": False})})
    assert set(same.values()) == {"a"}
    with pytest.raises(ValueError, match="unknown parameter 'heuristc'"):
        equivalent_strategies(traits, {"a": ("lab_mis", {"heuristc": "power"})})


# ---------------------------------------------------------------------------
# Samplers nested in a scene, cloned
# ---------------------------------------------------------------------------
SAMPLER_XML = """<scene version="3.0.0">
    <integrator type="lab_mis"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <sampler type="{kind}">
            <integer name="sample_count" value="8"/>
            <integer name="seed" value="5"/>
            {extra}
        </sampler>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="sphere"><point name="center" x="0" y="0" z="4"/><emitter type="area"/></shape>
</scene>"""


@pytest.mark.parametrize("kind, extra, own", [
    ("lab_independent", "", {}),
    ("lab_stratified", '<boolean name="jitter" value="false"/>', {"jitter": False}),
    ("lab_halton", '<string name="randomization" value="permute_digits"/>', {"randomization": "permute_digits"}),
    ("lab_sobol", "", {}),
    ("lab_zsobol", '<integer name="width" value="8"/>', {"width": 8}),
])
def test_sampler_in_an_xml_scene_and_its_clone_keep_their_parameters(kind, extra, own):
    scene = mi.load_string(SAMPLER_XML.format(kind=kind, extra=extra))
    sampler = scene.sensors()[0].sampler()
    expected = resolve(kind, {"sample_count": 8, "seed": 5, **own})
    assert sampler.settings() == expected
    for twin in (sampler.clone(), sampler.fork()):
        assert type(twin) is type(sampler) and twin.settings() == expected
    image = np.array(mi.render(scene, spp=8, seed=1))
    assert np.isfinite(image).all() and image.mean() > 0
    # the same samples again; a pixel's samples add with float atomics across threads, whose order
    # varies from run to run (~1e-7 relative seen under load)
    np.testing.assert_allclose(image, np.array(mi.render(scene, spp=8, seed=1)), rtol=1e-5, atol=0)


def test_sampler_xml_errors_name_the_parameter():
    with pytest.raises(RuntimeError) as err:
        mi.load_string(SAMPLER_XML.format(kind="lab_stratified", extra='<string name="jitter" value="no"/>'))
    assert str(err.value).strip().splitlines()[-1] == \
        "ParameterError: lab_stratified: parameter 'jitter' expects a boolean, got 'no'"


# ---------------------------------------------------------------------------
# No Mitsuba needed
# ---------------------------------------------------------------------------
def test_params_module_needs_no_mitsuba():
    """The declarations (and the text made from them) load without Mitsuba or Dr.Jit: tools read
    them before any variant is chosen (``mitsuba-lab plugins``, the runner's checks)."""
    code = ("import sys\n"
            "import mitsuba_lab.plugins.params as m, mitsuba_lab.plugins.param_docs as d\n"
            "assert m.resolve('lab_mis', {'max_depth': 8.0})['max_depth'] == 8\n"
            "assert d.rst_table(m.declared('lab_vcm'))\n"
            "assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True, env={**os.environ, "MITSUBA_LAB_ACTIVATE": "0"})


# ---------------------------------------------------------------------------
# Each plugin's docstring ends with its declared parameters, and its source holds no table
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("plugin", params.lab_plugins())
def test_help_shows_every_declared_parameter_with_its_default(plugin):
    import re

    from mitsuba_lab.plugins.param_docs import default_text, type_name

    doc = type(mi.load_dict({"type": plugin})).__doc__
    table = doc.split("Parameters (declared in ``plugins/params.py``):", 1)[1]
    for p in params.declared(plugin):
        row = re.search(rf"^{p.name} +(\w+) +(.*)$", table, re.MULTILINE)
        assert row and row[1] == type_name(p), (plugin, p.name)
        flat = " ".join(table[row.start():].split())
        default = re.search(r"default: ``(.*?)``\)", flat)
        assert default and default[1] == (default_text(p) or "empty"), (plugin, p.name)


def test_no_plugin_source_writes_a_parameter_table_of_its_own():
    """The declarations are the one source: a hand-written table would drift from them."""
    import re

    from mitsuba_lab.commands.plugin_text import docstrings

    rule = re.compile(r"^\s*=+( +=+)+\s*$", re.MULTILINE)
    assert not [name for name, doc in docstrings().items() if rule.search(doc)]
