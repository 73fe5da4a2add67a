"""Declared, typed parameters of every lab plugin, and the one place they are read.

Each lab plugin's parameters are declared once, here, as a tuple of ``Param``
(name, kind, default, constraint, one-line doc); the plugin classes reference
their tuple (``PARAMETERS``) and read their ``mi.Properties`` through
``read_properties``. The same declarations serve code that has no Mitsuba
object at all (the experiment runner's eager checks, a run's identity):

* ``declared(plugin_type)``: the tuple of ``Param`` of a lab plugin, or None;
* ``resolve(plugin_type, params)``: names, types and constraints checked, every
  declared parameter returned with its default filled in, values normalised
  (8.0 -> 8); any other plugin's parameters come back unchanged.

Errors are ``ParameterError`` (a ``ValueError``) whose text is one line naming
the plugin and the parameter, e.g. ``lab_mis: parameter 'rr_depth' must be an
integer >= 1, got 0``; Mitsuba wraps it, with its traceback, and the last line
of its message is still that line.

No Mitsuba import: nothing here depends on the variant, so the module is not
re-run on a variant switch (``plugins/__init__.py``).
"""
from __future__ import annotations

import difflib
import math
from dataclasses import replace

from .param_types import AUTOMATIC_LENGTH, Param, ParameterError, _int_at_least, _override, _show  # noqa: F401 (re-exported)


# ---------------------------------------------------------------------------
# Declarations
# ---------------------------------------------------------------------------
#: Mitsuba's convention: max_depth = -1 means unbounded.
UNBOUNDED = -1
#: lab_mis heuristics (``mis_weight.mis_weight``).
HEURISTICS = ("balance", "power", "max", "average")
#: lab_photon's ``direct`` modes.
DIRECT_MODES = ("photons", "nee")
#: lab_photon: the smallest record buffer, also the smallest allowed ``max_records``.
PHOTON_MIN_RECORDS = 1024
#: lab_halton's randomisations, and its largest sample count (float32 digit extraction
#: is exact below 2^21, see halton.py).
RANDOMIZATIONS = ("permute_digits", "owen")
HALTON_MAX_SPP = 1 << 21

#: Shared by lab_naive, lab_nee and lab_mis (``LabPathIntegrator``).
PATH_TRACER = (
    Param("max_depth", int, UNBOUNDED,
          "longest path in segments: -1 unbounded, 0 black, 1 emitters seen directly, 2 direct lighting",
          check=lambda v: v == UNBOUNDED or v >= 0, expected="-1 (unbounded) or an integer >= 0"),
    Param("rr_depth", int, 5, "depth at which Russian roulette starts", **_int_at_least(1)),
    Param("hide_emitters", bool, False,
          "camera rays pass through area emitters; the bare environment is invalid (alpha 0)"),
    Param("count_rays", bool, True, "count camera, extension and shadow rays (ray_counts())"),
)

#: How the NEE path tracers sample where light scatters in a medium and how their shadow
#: rays estimate transmittance (``integrators/common/media.py``); no effect on a scene without media.
MEDIUM_SAMPLINGS = ("distance", "equiangular", "mis")
TRANSMITTANCES = ("ratio", "delta")
MAJORANTS = ("global", "grid")


def _media(sampling_default: str) -> tuple[Param, ...]:
    return (
        Param("medium_sampling", str, sampling_default,
              "where in-scattered direct light is sampled along a ray in a medium: distance (free flights, "
              "NEE at the collision), equiangular (Kulla-Fajardo, towards a light point sampled from the "
              "ray's origin; in heterogeneous media inside the medium's box, its transmittance tracked as "
              "the shadow rays') or mis (both, weighted by the estimator's MIS; in heterogeneous media over "
              "the null collisions, Miller et al. 2019)", choices=MEDIUM_SAMPLINGS),
        Param("equiangular_samples", int, 1, "with medium_sampling equiangular or mis: equi-angular samples on each "
              "segment of a camera ray in a medium, their mean (splitting the single scattering the pixel sees "
              "directly); every later segment takes one", **_int_at_least(1)),
        Param("transmittance", str, "ratio", "shadow rays' transmittance in heterogeneous media: ratio (ratio "
              "tracking) or delta (delta tracking, 0 or 1); exact (Beer-Lambert) in homogeneous media either way",
              choices=TRANSMITTANCES),
        Param("majorants", str, "global",
              "the bounds that delta and ratio tracking propose collisions against in a heterogeneous "
              "medium: global (one per medium, Mitsuba's: scale x the grid's maximum) or grid (a coarse "
              "grid of local bounds, built once per scene from the sigma_t gridvolume and walked cell by "
              "cell; 4 bytes a cell; one heterogeneous medium per scene, its one-channel sigma_t grid "
              "scaled and translated, not rotated); homogeneous media need none", choices=MAJORANTS),
        Param("majorant_resolution", int, 16, "majorant grid cells along each axis (at most the sigma_t grid's own "
              "resolution there)", **_int_at_least(1)),
        Param("spectral_mis", bool, True, "with chromatic extinction, weight the distances sampled with the path's "
              "channel by one-sample MIS over all channels' densities (volpathmis); false: divide by the "
              "sampling channel's density alone (volpath). No effect in grey media"),
    )

#: lab_nee: the path tracer's and the medium sampling (distance by default: plain NEE).
LAB_NEE = PATH_TRACER + _media("distance")
#: lab_mis: the path tracer's and its own.
LAB_MIS = PATH_TRACER + (
    Param("heuristic", str, "power", "MIS heuristic", choices=HEURISTICS),
    Param("beta", float, 2.0, "power-heuristic exponent (1 = balance)",
          check=lambda v: v > 0 and math.isfinite(v), expected="a finite number > 0"),
    Param("emitter_samples", int, 1, "shadow rays per vertex, n_L", **_int_at_least(1)),
) + _media("mis")

#: Aimed emission (``integrators/common/aim.py``): lab_photon, lab_bdpt and lab_vcm. Aiming changes nothing in
#: a scene without aim_at shapes (the light emits as Mitsuba samples it, with the same random numbers),
#: so every one aims by default. lab_vcm's default depends on its mode (``VCM_AIM_DEFAULTS``, unless ``aim``
#: is given): 0.9 in vcm (vcm.toml's vcm_auto), lab_bdpt's 0.5 in bpt and lt (so bpt renders lab_bdpt's
#: image), none in ppm and bpm: there merging carries the direct light too, brought only by the unaimed
#: light subpaths with 1 / (1 - aim) the weight: noisier away from the targets, not biased.
AIM_DEFAULT = 0.5
VCM_AIM_DEFAULTS = {"vcm": 0.9, "bpt": AIM_DEFAULT, "lt": AIM_DEFAULT, "bpm": 0.0, "ppm": 0.0, "pt": 0.0}
VCM_AIM_DEFAULT = VCM_AIM_DEFAULTS["vcm"]      # (mode vcm's, the default mode: the declared default)


def _aim(default: float) -> tuple[Param, ...]:
    return (
        Param("aim", float, default, "share of an area light's emitted directions aimed at the bounding spheres of "
              "the aim_at shapes, where a scene has them (Jensen's projection map, simplest form); 0 = "
              "cosine-weighted only, as Mitsuba emits",
              check=lambda v: 0.0 <= v < 1.0, expected="a number in [0, 1)"),
    Param("aim_at", str, "specular", "shapes aimed at: specular (every shape whose BSDF has only delta lobes) "
          "or shape ids joined by ','", check=lambda v: bool(v.strip()) and all(t.strip() for t in v.split(",")),
          expected="'specular' or shape ids joined by ','"),
    )


AIM = _aim(AIM_DEFAULT)

#: lab_photon (progressive photon mapping). Its max_depth is -1 or >= 1: a camera
#: path needs one segment to reach a photon.
LAB_PHOTON = (
    Param("photons_per_pass", int, 100_000, "photons emitted per pass", **_int_at_least(1)),
    Param("passes", int, 16, "passes (photon maps) averaged", **_int_at_least(1)),
    Param("alpha", float, 2.0 / 3.0, "radius reduction r_{i+1}^2 = r_i^2 (i + alpha) / (i + 1)",
          check=lambda v: 0.0 < v < 1.0, expected="a number in (0, 1)"),
    Param("radius", float, 0.0, "first-pass radius in scene units; 0 = automatic: a pixel's width where the camera "
          "looks, or wider where photons are sparse there (1/64 per pass in it: common/density_radius.py)",
          **AUTOMATIC_LENGTH),
    Param("radius_volume", float, 0.0, "first-pass radius r_v,1 of the ball volumetric photons are gathered in "
          "(scenes with participating media), in scene units; 0 = automatic (the surfaces' first radius); "
          "r_v,{i+1}^3 = r_v,i^3 (i + alpha) / (i + 1)",
          **AUTOMATIC_LENGTH),
    Param("max_depth", int, UNBOUNDED, "longest path in segments (camera + light subpath), -1 unbounded",
          check=lambda v: v == UNBOUNDED or v >= 1, expected="-1 (unbounded) or an integer >= 1"),
    replace(PATH_TRACER[1], doc="depth at which Russian roulette starts, on both subpaths"),
    Param("direct", str, "nee", "direct light by photons, or by NEE + MIS (photons for the rest)",
          choices=DIRECT_MODES),
    Param("max_records", int, 1 << 21, "most photon records held at once (a pass is split to fit)",
          **_int_at_least(PHOTON_MIN_RECORDS)),
    PATH_TRACER[2],                                   # hide_emitters, Mitsuba's meaning
) + AIM


def _techniques():
    """``integrators.bdpt.techniques`` (parses ``strategies``, ``only_strategy``; imported when first needed)."""
    from mitsuba_lab.plugins.integrators.bdpt import techniques

    return techniques

#: lab_bdpt (bidirectional path tracing).
LAB_BDPT = (
    Param("max_depth", int, UNBOUNDED, "longest path in segments (light + camera subpath), -1 unbounded",
          check=lambda v: v == UNBOUNDED or v >= 1, expected="-1 (unbounded) or an integer >= 1"),
    replace(PATH_TRACER[1], doc="depth at which Russian roulette starts, on both subpaths"),
    PATH_TRACER[2],                                   # hide_emitters, Mitsuba's meaning
    Param("heuristic", str, "power", "MIS heuristic over all strategies of a path",
          choices=("balance", "power")),
    Param("beta", float, 2.0, "power-heuristic exponent (1 = balance)",
          check=lambda v: v > 0 and math.isfinite(v), expected="a finite number > 0"),
    Param("strategies", str, "all", "strategies used: all, camera (s <= 1), light (t = 1), or kinds "
          "joined by '+' from hit, nee, light, connect",
          check=lambda v: _techniques().parse_techniques(v) is not None,
          expected="all, camera, light or kinds from hit, nee, light, connect joined by '+'"),
    Param("light_paths", float, 1.0, "light subpaths traced per camera subpath (light tracing's "
          "share: above 1 the extra ones only splat t = 1 connections; below 1 camera subpaths share them)",
          check=lambda v: 1.0 / 64 <= v <= 64, expected="a number in [1/64, 64]"),
    Param("max_vertices", int, 1 << 21, "most light-subpath vertices held at once (a render is split "
          "into passes to fit)", **_int_at_least(1024)),
    Param("only_strategy", str, "", "render only strategy (s, t), written 's,t', with its MIS weight "
          "(Veach's per-strategy images); empty = every strategy",
          check=lambda v: v == "" or _techniques().Strategy.parse(v) is not None,
          expected="empty or 's,t' with s >= 0, t >= 1 and s + t >= 2"),
    Param("equiangular", float, 0.0, "share of camera flights in homogeneous media drawn equi-angularly towards a light "
          "(the rest free flights; their density in every MIS weight). Both kinds: scenes of at most 8 emitters",
          check=lambda v: 0.0 <= v <= 1.0, expected="a number in [0, 1]"),
    Param("equiangular_nee", str, "all", "camera segments in homogeneous media adding an equi-angular NEE sample, a 2nd "
          "s = 1 technique (lab_mis's; not with merging): off, first (the sensor's), all", choices=("off", "first", "all")),
) + tuple(p for p in _media("distance") if p.name in ("majorants", "majorant_resolution")) + AIM + (
    Param("count_rays", bool, True, "count camera, extension, shadow (NEE), connection, light-subpath and sensor "
          "(light tracing's) rays (ray_counts())"),
)

#: lab_vcm's modes (the techniques each enables: ``vcm.estimator.MODES``).
VCM_MODES = ("vcm", "bpt", "bpm", "ppm", "lt", "pt")

#: Density-estimation kernels (``integrators/common/kernels.py``), lab_vcm's ``kernel``.
KERNELS = ("epanechnikov", "constant")

#: How lab_vcm's pilot prices an iteration (``pilot_costs``).
PILOT_COSTS = ("counted", "measured")


def _cost(name: str, default: float, what: str) -> Param:
    return Param(name, float, default, f"with pilot_costs = counted: nanoseconds per {what}",
                 check=lambda v: v >= 0.0 and math.isfinite(v), expected="a finite number >= 0")


#: lab_vcm's pilot with ``pilot_costs = counted``: the cost of each kind of counted work, in
#: nanoseconds (``selection.PilotCosts.from_counts``). The defaults were fitted once by
#: ``benchmarks/bench_pilot_costs.py`` (48x48, 1 and 8 iterations, max_depth 8, medians of 3 rounds
#: on the Cornell box, the caustic and light_in_glass; 2 shared cores, llvm_ad_rgb, Dr.Jit 1.5):
#: only their ratios matter to the choice, and only roughly.
PILOT_WORK_COSTS = (
    _cost("cost_camera_ray", 980.0, "camera ray of every technique's camera subpaths (with its first vertex)"),
    _cost("cost_extension_ray", 660.0, "extension ray of every technique's camera subpaths (with its vertex)"),
    _cost("cost_shadow_ray", 0.0, "next-event estimation's shadow ray at a camera vertex"),
    _cost("cost_connection", 1250.0, "connection of a camera vertex to a light vertex (with its shadow ray)"),
    _cost("cost_merge", 410.0, "light vertex a merge lookup reads"),
    _cost("cost_light_ray", 180.0, "light-subpath ray (with its vertex)"),
    _cost("cost_sensor_ray", 220.0, "light tracing's join of a light vertex to the sensor (with its splat)"),
    _cost("cost_light_vertex", 760.0, "stored light vertex (storing and bucketing it)"),
    _cost("cost_pass", 71e6, "pass of every technique (its fixed cost: Python, kernel launches)"),
    _cost("cost_path_ray", 180.0, "camera or extension ray of path tracing alone (lab_mis)"),
    _cost("cost_path_shadow_ray", 550.0, "shadow ray of path tracing alone (lab_mis)"),
)

#: lab_vcm's pilot: the most light subpaths per camera subpath it may choose unless told.
VCM_LIGHT_PATHS_MAX = 16.0

def _vcm_aim() -> tuple[Param, ...]:
    """lab_vcm's aim and aim_at: aim's default depends on the mode (``VCM_AIM_DEFAULTS``)."""
    aim, aim_at = _aim(VCM_AIM_DEFAULT)
    return (replace(aim, doc=aim.doc + "; unless given: 0.9 in mode vcm, 0.5 in bpt and lt (lab_bdpt's), 0 in bpm "
                    "and ppm (merging carries the direct light there, and only the unaimed light subpaths bring it)"),
            aim_at)

#: lab_vcm (vertex connection and merging).
LAB_VCM = (
    Param("mode", str, "vcm", "which techniques: vcm (all), bpt (connections: lab_bdpt), bpm (merging), "
          "ppm (merging at the first smooth camera vertex), lt (light tracing), pt (path tracing: lab_mis)",
          choices=VCM_MODES),
    Param("radius", float, 0.0, "first iteration's merging radius r_1 in scene units; 0 = automatic: a pixel's "
          "width where the camera looks, or wider where light vertices are sparse there (common/density_radius.py)",
          **AUTOMATIC_LENGTH),
    Param("radius_volume", float, 0.0, "first iteration's radius r_v,1 of the ball medium vertices merge in "
          "(scenes with participating media), in scene units; 0 = automatic (the surfaces' r_1); "
          "r_v,i = r_v,1 i^((alpha - 1) / 3)",
          **AUTOMATIC_LENGTH),
    Param("alpha", float, 0.75, "radius schedule r_i = r_1 i^((alpha - 1) / 2), iteration i = sample i",
          check=lambda v: 0.0 < v < 1.0, expected="a number in (0, 1)"),
    Param("light_paths", float, 1.0, "light subpaths traced per camera subpath in each iteration: all of "
          "them merge and splat; camera subpath i connects to light subpath i (below 1: i mod N, shared)",
          check=lambda v: 1.0 / 64 <= v <= 64, expected="a number in [1/64, 64]"),
    Param("kernel", str, "epanechnikov", "merging's density kernel over the disc of radius r_i: epanechnikov "
          "(2 / pi) (1 - d^2 / r^2) / r^2, as lab_photon (2/3 the blur's bias, 4/3 the variance), or constant "
          "1 / (pi r^2), as SmallVCM", choices=KERNELS),
    Param("merge_first", bool, False, "merge at the camera's first vertex too (modes vcm and bpm; Georgiev's "
          "VCM); false leaves the light arriving there to light tracing, NEE and connections, and that merge "
          "out of every MIS sum (ppm always merges there)"),
    Param("pilot", bool, True, "efficiency-aware choice for the whole image (modes vcm and bpt; on by default in "
          "mode vcm only): a pilot (at most pilot_share of the counted work) estimates relative variance x cost per "
          "iteration (pilot_costs) with every technique and with path tracing alone, and the render uses the lower "
          "(path tracing alone: mode pt, lab_mis's estimator)"),
    Param("pilot_share", float, 0.125, "with pilot: the most the pilot's counted work (cost_* x its counts) may be of "
          "the whole render's; where its fewest iterations would cost more, no pilot: every technique at light_paths if "
          "the scene has a specular shape (only delta lobes), else path tracing alone; "
          "1 = no bound (pilot renders of max(4, spp / 128) iterations)",
          check=lambda v: 0.0 < v <= 1.0, expected="a number in (0, 1]"),
    Param("light_paths_max", float, VCM_LIGHT_PATHS_MAX, "with pilot: the most light subpaths per camera subpath the "
          "pilot may choose, powers of two times light_paths up to it, by their relative variance x cost; 0 = "
          "light_paths only", check=lambda v: v == 0.0 or 1.0 / 64 <= v <= 64,
          expected="0 or a number in [1/64, 64]"),
    Param("pilot_costs", str, "counted", "with pilot: how the pilot prices an iteration: counted, its pilot renders' "
          "work by kind (rays, connections, merge lookups, stored light vertices, passes) times the cost_* parameters, "
          "so the choice depends only on the scene, settings, seed and variant; or measured, their wall-clock times "
          "(the choice then depends on the machine's load)", choices=PILOT_COSTS),
) + PILOT_WORK_COSTS + (
    Param("merge_vertices", str, "all", "which light vertices merge (mode vcm): all, or caustic, only those "
          "reached through a delta lobe (Jensen's caustic photons); merging is then a technique only there, and "
          "every other path's light comes from the other techniques", choices=("all", "caustic")),
    Param("connections", str, "all", "connections at a camera vertex (modes vcm and bpt): all, to every vertex of "
          "its light subpath (lab_bdpt), or one, to one of them picked uniformly and counted n times, the MIS "
          "weights counting a connection as 1 / (mean vertices per light subpath)", choices=("all", "one")),
) + tuple(p for p in LAB_BDPT if p.name in ("max_depth", "rr_depth", "hide_emitters", "heuristic", "beta",
                                            "max_vertices", "equiangular", "equiangular_nee")) + _vcm_aim() + (
    replace(LAB_BDPT[-1], doc="count rays as lab_bdpt does, and under 'merge' the light vertices merging's grid "
                              "lookups read (ray_counts())"),
)

#: lab_pssmlt (Kelemen's primary-sample-space MLT over lab_mis's path loop, ``integrators/mlt/``): lab_mis's
#: parameters and the chains'; its small steps, and its most bootstrap paths (traced in one wavefront).
MLT_SMALL_STEPS, MLT_MAX_BOOTSTRAP = ("normal", "exponential"), 1 << 22
#: The most paths ``bootstrap_share`` grows a bootstrap to (4x as many ran out of 23 GB: benchmarks/mlt_door.py).
MLT_GROWN_BOOTSTRAP = 1 << 20
LAB_PSSMLT = LAB_MIS + (
    Param("chains", int, 8192, "Markov chains advancing in lock-step, one per lane (at most the render's "
          "mutations: width x height x spp)", **_int_at_least(1)),
    Param("bootstrap", int, 100_000, "independent paths that estimate the normaliser b (the image's mean "
          "luminance) and from which the chains start, drawn in proportion to their luminance",
          check=lambda v: 1 <= v <= MLT_MAX_BOOTSTRAP, expected=f"an integer in [1, {MLT_MAX_BOOTSTRAP}]"),
    Param("bootstrap_share", float, 0.25, "bootstrap paths per mutation: a render that starts chains uses "
          f"max(bootstrap, bootstrap_share x width x height x spp) paths, the second at most {MLT_GROWN_BOOTSTRAP}, "
          "so the bootstrap grows with the budget; 0: exactly bootstrap (a progressive run's chains start in its "
          "first pass, whose spp is small)", check=lambda v: 0.0 <= v <= 64.0, expected="a number in [0, 64]"),
    Param("large_step", float, 0.3, "probability that a step draws every primary sample afresh (a large step)",
          check=lambda v: 0.0 <= v <= 1.0, expected="a number in [0, 1]"),
    Param("small_step", str, "normal", "the small step's perturbation of each primary sample (wrapped to "
          "[0, 1)): normal (standard deviation sigma, pbrt-v4's) or exponential (Kelemen et al. 2002, offsets "
          "from 1/1024 to 1/64)", choices=MLT_SMALL_STEPS),
    Param("sigma", float, 0.01, "standard deviation of the normal small step, in primary sample space",
          check=lambda v: 0.0 < v <= 1.0, expected="a number in (0, 1]"),
)

#: lab_mmlt (multiplexed MLT over lab_bdpt's subpaths and MIS weights, ``integrators/mlt/mmlt.py``): its
#: depth and strategy are part of the chains' state, so the depth must be bounded; no Russian roulette
#: (pbrt-v4's MLTIntegrator has none: a path's length is what the state picks).
LAB_MMLT = _override((
    Param("max_depth", int, 8, "longest path in segments (light + camera subpath); each chain keeps one "
          "length from 1 to max_depth, the lengths' chains in proportion to their b", **_int_at_least(1)),
) + tuple(p for p in LAB_BDPT if p.name in ("heuristic", "beta")) + tuple(
    p for p in LAB_PSSMLT if p.name in ("chains", "bootstrap", "bootstrap_share", "large_step", "small_step",
                                        "sigma")), Param(
    "bootstrap", int, 100_000, "independent paths, split evenly over the lengths (bootstrap // max_depth "
    "each), that estimate each length's normaliser b_k and from which the chains start, drawn in proportion "
    "to their luminance", check=lambda v: 1 <= v <= MLT_MAX_BOOTSTRAP,
    expected=f"an integer in [1, {MLT_MAX_BOOTSTRAP}]"))

#: Shared by every lab sampler (``LabSampler``).
SAMPLER = (
    Param("sample_count", int, 4, "samples per pixel", **_int_at_least(1)),
    Param("seed", int, 0, "base seed, added to the render seed",
          check=lambda v: 0 <= v < 2 ** 32, expected="an integer in [0, 2^32)"),
)

LAB_STRATIFIED = SAMPLER + (
    Param("jitter", bool, True, "uniform offset inside each cell (false: cell centres, biased)"),
)

LAB_HALTON = _override(SAMPLER, Param(
    "sample_count", int, 4, "samples per pixel",
    check=lambda v: 1 <= v <= HALTON_MAX_SPP, expected=f"an integer in [1, {HALTON_MAX_SPP}]")) + (
    Param("randomization", str, "owen", "digit randomisation", choices=RANDOMIZATIONS),
)

LAB_ZSOBOL = SAMPLER + (
    Param("width", int, 0, "width of the rendered pixel block (film or crop window); 0 = take it from "
          "the film, which the lab binds before each render (else: one warning, a guess)",
          **_int_at_least(0)),
)

_DECLARED: dict[str, tuple[Param, ...]] = {
    "lab_naive": PATH_TRACER,
    "lab_nee": LAB_NEE,
    "lab_mis": LAB_MIS,
    "lab_photon": LAB_PHOTON,
    "lab_bdpt": LAB_BDPT,
    "lab_vcm": LAB_VCM,
    "lab_pssmlt": LAB_PSSMLT,
    "lab_mmlt": LAB_MMLT,
    "lab_independent": SAMPLER,
    "lab_stratified": LAB_STRATIFIED,
    "lab_halton": LAB_HALTON,
    "lab_sobol": SAMPLER,
    "lab_zsobol": LAB_ZSOBOL,
}

#: Parameters that Mitsuba's own C++ base classes read (``mi.SamplingIntegrator``:
#: timeout, samples_per_pass, block_size): accepted, not listed, left to Mitsuba.
#: (hide_emitters, which the base also reads, is declared by the lab's integrators.)
MITSUBA_BASE_PARAMETERS = {
    "integrator": ("timeout", "samples_per_pass", "block_size"),
    "sampler": (),
}

_PER_PASS = "light subpaths are traced per pass, and passes are sized by 'max_vertices'"
#: Mitsuba base parameters that a lab plugin refuses, with the reason (a one-line error).
REFUSED_BASE_PARAMETERS = {
    "lab_bdpt": {"samples_per_pass": _PER_PASS},
    "lab_vcm": {"samples_per_pass": _PER_PASS},
}


def base_parameters(plugin: str, kind: str | None = None) -> tuple[str, ...]:
    """The Mitsuba base parameters ``plugin`` accepts and leaves to Mitsuba (its kind's, less
    those it refuses); ``kind`` defaults to ``plugin_kind(plugin)``."""
    refused = REFUSED_BASE_PARAMETERS.get(plugin, {})
    return tuple(p for p in MITSUBA_BASE_PARAMETERS[kind or plugin_kind(plugin) or "integrator"]
                 if p not in refused)


def plugin_kind(plugin_type: str) -> str | None:
    """'integrator' or 'sampler' for a lab plugin, None for any other name."""
    if plugin_type not in _DECLARED:
        return None
    return "sampler" if _DECLARED[plugin_type][0].name == SAMPLER[0].name else "integrator"


# ---------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------

def declared(plugin_type: str) -> tuple[Param, ...] | None:
    """The declared parameters of a lab plugin (``lab_mis``, ``lab_sobol``, ...), else None."""
    return _DECLARED.get(plugin_type)


def lab_plugins() -> tuple[str, ...]:
    """Names of every lab plugin with declared parameters."""
    return tuple(_DECLARED)


def _unknown_message(plugin: str, unknown: list[str], parameters: tuple[Param, ...]) -> str:
    valid = sorted(p.name for p in parameters)
    names = ", ".join(f"'{n}'" for n in unknown)
    text = (f"{plugin}: unknown parameter {names}" if len(unknown) == 1 else
            f"{plugin}: unknown parameters {names}")
    text += f"; valid parameters: {', '.join(valid)}"
    hints = [(n, difflib.get_close_matches(n, valid, n=1)) for n in unknown]
    hints = [f"'{close[0]}'" + (f" for '{n}'" if len(unknown) > 1 else "") for n, close in hints if close]
    if hints:
        text += f"; did you mean {', '.join(hints)}?"
    return text


def _check(plugin: str, given: dict, parameters: tuple[Param, ...], passthrough: tuple[str, ...]
           ) -> tuple[dict, dict]:
    """(declared values with defaults, given Mitsuba base parameters); raises ParameterError."""
    names = {p.name for p in parameters}
    for name, reason in REFUSED_BASE_PARAMETERS.get(plugin, {}).items():
        if name in given:
            raise ParameterError(f"{plugin}: parameter '{name}' is not supported: {reason}")
    unknown = [k for k in given if k not in names and k not in passthrough]
    if unknown:
        raise ParameterError(_unknown_message(plugin, unknown, parameters))
    values = {p.name: p.convert(plugin, given[p.name]) if p.name in given else p.default
              for p in parameters}
    if plugin in DEPENDENT_DEFAULTS:
        DEPENDENT_DEFAULTS[plugin](values, given)
    extra = {k: v for k, v in given.items() if k in passthrough}
    return values, extra


def _vcm_dependent_defaults(values: dict, given) -> None:
    """lab_vcm's defaults that follow its mode, unless given: the pilot in mode vcm only (mode bpt is
    lab_bdpt's estimator, the other modes have no choice to make), choosing up to
    VCM_LIGHT_PATHS_MAX light subpaths; the mode's aim (``VCM_AIM_DEFAULTS``)."""
    if "pilot" not in given:
        values["pilot"] = values["mode"] == "vcm"
    if "aim" not in given:
        values["aim"] = VCM_AIM_DEFAULTS[values["mode"]]
    if "light_paths_max" not in given:
        values["light_paths_max"] = max(VCM_LIGHT_PATHS_MAX, values["light_paths"]) if values["pilot"] else 0.0


#: Defaults that depend on other parameters' values, filled in wherever parameters are read (the
#: plugin's properties and the runner's ``resolve`` alike, so a run records what renders).
DEPENDENT_DEFAULTS = {"lab_vcm": _vcm_dependent_defaults}


def resolve(plugin_type: str, params: dict) -> dict:
    """Every declared parameter of ``plugin_type``, checked, normalised, defaults filled in.

    Raises ParameterError (a ValueError) with a one-line message on an unknown name, a
    value of the wrong type or one that breaks its constraint. Parameters that Mitsuba's
    own base class reads (e.g. ``timeout``) are passed through unchanged after the
    declared ones. For a plugin that is not the lab's, returns ``dict(params)``.
    """
    parameters = declared(plugin_type)
    if parameters is None:
        return dict(params)
    values, extra = _check(plugin_type, dict(params), parameters, base_parameters(plugin_type))
    return {**values, **extra}


def read_properties(plugin: str, props, parameters: tuple[Param, ...] | None = None,
                    kind: str | None = None) -> dict:
    """The declared parameters of ``plugin`` read from a ``mi.Properties``: checked like
    ``resolve``, every declared name with its value (defaults filled in).

    ``parameters`` defaults to ``declared(plugin)``, ``kind`` ('integrator' or 'sampler',
    which decides the Mitsuba base parameters left alone) to ``plugin_kind(plugin)``.
    Properties holding objects (nested plugins) or references are left to Mitsuba, which
    reports those it finds unreferenced; every other property is read (so marked as
    queried), and an undeclared one is an error. Call it before the Mitsuba base
    class's constructor, so that its own type errors never come first.
    """
    if parameters is None:
        parameters = declared(plugin)
        if parameters is None:
            raise KeyError(f"{plugin}: no declared parameters")
    passthrough = base_parameters(plugin, kind)
    types = type(props).Type
    skip = (types.Object, types.Reference, types.ResolvedReference)
    given = {}
    for name in props.keys():
        if name in passthrough or props.type(name) in skip:
            continue
        given[name] = props[name]
    values, _ = _check(plugin, given, parameters, passthrough)
    return values

