"""``lab_photon``: the driver (passes, radius schedule, batches) and its settings."""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins import interrupts
from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.integrators.common import spawn
from mitsuba_lab.plugins.integrators.common.aim import AimedEmission
from mitsuba_lab.plugins.integrators.common.density_radius import first_radius
from mitsuba_lab.plugins.integrators.common.support import render_arguments, warn_if_unsupported
from mitsuba_lab.plugins.samplers.layout import bind_film_layout
from mitsuba_lab.plugins.variant import plugin_settings
from mitsuba_lab.plugins.scene_traits import SceneTraits
from mitsuba_lab.plugins.params import DIRECT_MODES, UNBOUNDED  # noqa: F401 (re-exported)

from mitsuba_lab.plugins.integrators.common import spectral
from mitsuba_lab.plugins.integrators.common.spectral import spectrum_channels
from .estimator import PhotonMapping
from .gather import CameraPass
from .grid import PhotonGrid
from .records import record_bytes
from .tracer import PhotonTracer
from mitsuba_lab.plugins.integrators.common.subpath_media import Tracking, emitter_media

#: max_depth = -1 (unbounded) is stored as this many segments (sums of depths stay in uint32).
DEPTH_CAP = 1 << 30
#: Smallest record buffer; also the smallest allowed ``max_records`` (declared in params.py).
MIN_RECORDS = params.PHOTON_MIN_RECORDS


@dataclass
class PhotonSettings:
    """The parameters of ``lab_photon``, typed; declared and checked in ``params.LAB_PHOTON``
    (build it with ``PhotonSettings.resolve(given)``, or from already checked values)."""
    photons_per_pass: int
    passes: int
    alpha: float
    radius: float
    radius_volume: float
    max_depth: int
    rr_depth: int
    direct: str
    max_records: int
    hide_emitters: bool = False
    aim: float = 0.0
    aim_at: str = "specular"

    @classmethod
    def resolve(cls, given: dict | None = None) -> "PhotonSettings":
        """Checked settings, defaults filled in (``params.resolve``; ValueError when invalid)."""
        return cls(**params.resolve("lab_photon", given or {}))

    @property
    def depth_limit(self) -> int:
        """max_depth in segments, with -1 (unbounded) mapped to DEPTH_CAP (parsed here only)."""
        return DEPTH_CAP if self.max_depth == UNBOUNDED else self.max_depth


def radius_schedule(r1: float, passes: int, alpha: float, dimension: int = 2) -> list[float]:
    """r_{i+1}^2 = r_i^2 (i + alpha) / (i + 1), i = 1..P-1 (Knaus & Zwicker 2011, eq. 20): the
    disc's area shrinks by (i + alpha) / (i + 1) from one pass to the next; ``dimension`` 3, the
    ball's volume (r^3) does, as Knaus & Zwicker's argument gives it in three dimensions."""
    rd = [r1 ** dimension]
    for i in range(1, passes):
        rd.append(rd[-1] * (i + alpha) / (i + 1))
    return [v ** (1.0 / dimension) for v in rd]


@dataclass
class PhotonStats:
    """What the last render did; times in seconds, measured after dr.eval + dr.sync_thread.

    trace_s: photon tracing (incl. storing records, reading their count, compaction);
    grid_s: grid builds; gather_s: camera passes (camera paths, NEE, density estimate);
    stored_flux: sum of the stored photons' flux per channel, over all passes.
    """
    passes: int = 0
    batches: int = 0
    splits: int = 0
    photons_traced: int = 0
    photons_stored: int = 0
    photon_segments: int = 0
    trace_s: float = 0.0
    grid_s: float = 0.0
    gather_s: float = 0.0
    radius_first: float = 0.0
    radius_last: float = 0.0
    radius_volume_first: float = 0.0
    radius_volume_last: float = 0.0
    photons_stored_in_media: int = 0
    peak_record_bytes: int = 0
    stored_flux: list = field(default_factory=lambda: [0.0, 0.0, 0.0])

    def as_dict(self) -> dict:
        d = asdict(self)
        d["photons_per_s"] = self.photons_traced / self.trace_s if self.trace_s > 0 else 0.0
        d["gather_s_per_pass"] = self.gather_s / self.passes if self.passes else 0.0
        d["grid_s_per_pass"] = self.grid_s / self.passes if self.passes else 0.0
        return d


@documented("lab_photon")
class LabPhotonIntegrator(mi.SamplingIntegrator):
    r"""Progressive photon mapping (:monosp:`lab_photon`)

    Probabilistic progressive photon mapping (Knaus & Zwicker 2011, "Progressive
    photon mapping: a probabilistic approach", ACM TOG 30(3)) on Jensen's photon
    map (Jensen 2001, "Realistic Image Synthesis Using Photon Mapping"). Each pass
    i = 1..P traces an independent photon map and renders the image once with the
    gather radius r_i, where r_{i+1}^2 = r_i^2 (i + alpha) / (i + 1); the result
    is the average of the P pass images.

    **Bias.** Every pass is a kernel density estimate, biased by the blur of radius
    r_i. The average is biased for any finite P; the bias shrinks as r_i -> 0 and
    the variance as 1 / (P r^2)-ish, so the estimator is consistent (error -> 0
    as P grows), never unbiased. Compare it with unbiased estimators by MSE =
    bias^2 + variance, not by z-scores of the mean. The bias is largest where the
    radiance changes within r: the edges of surfaces (the kernel's disk sticks out),
    sharp caustics (blurred peaks).

    **Density estimate** (``gather.py``): at every camera vertex with a smooth BSDF
    lobe, L = sum_p f(wo, wi_p) |wi_p . n_s| / |wi_p . n_p| Phi_p K(|x - x_p| / r) / r^2
    with the 2D Epanechnikov kernel K(t) = (2 / pi)(1 - t^2), t < 1 (integral over the
    plane = 1); a photon whose geometric normal is more than ~37 degrees off x's
    (n . n_p <= 0.8) is rejected, and so is one whose path plus the camera's exceeds
    ``max_depth``. Photons are found in a hashed grid of cell size r (``grid.py``:
    counting sort). Camera paths continue through delta lobes (mirror, glass, and the
    delta lobes of BSDFs that also have smooth ones: ``plastic``, ``mask``,
    ``blendbsdf``), so such a BSDF is both gathered at (its smooth lobes) and passed
    through (its delta lobes, sampled alone). Photons carry Veach's shading-normal
    (adjoint) correction (``tracer.py``).

    Pass seeds come from the render's ``seed``: different seeds give independent
    photon maps and camera samples. Each pass renders ``spp`` camera samples per pixel, so an
    image costs ``passes`` x spp of them. ``max_depth = 0`` is refused (the camera needs one
    segment to reach a photon; the path tracers accept it). ``direct = nee`` takes the direct
    light at the camera vertex by next-event estimation and BSDF sampling under the power
    heuristic, the photons only what has bounced at least once (indirect light, caustics);
    ``photons`` takes all of it from the density estimate. A record takes 52 bytes in RGB and
    56 in spectral variants, held up to three times during a batch (trace buffer, compacted
    and sorted copies): the default ``max_records`` is about 110 MB; a pass needing more is
    traced and gathered in batches with the same camera samples (the same estimate).

    Handles: any emitter with ``sample_ray`` (area, point, spot, directional,
    environment), chosen with probability proportional to its power; smooth, delta
    and mixed BSDFs; shading normals (vertex normals; with a ``normalmap`` /
    ``bumpmap`` the photons' correction uses the unperturbed shading normal, which
    is all Mitsuba's BSDF interface shows, as Mitsuba's ``ptracer`` does);
    ``hide_emitters``; RGB, mono and spectral variants. **Spectral**: each pass uses
    one set of wavelengths for all its photons and camera rays (``spectral.py``),
    so a pass image carries the colour noise of 4 wavelengths, averaged out over
    passes (not over the spp of a pass). Every emitter spectrum works (``rgb``,
    bitmap, ``blackbody``, spectrum files, ``envmap``): photons are emitted at the
    camera's wavelengths by inverting each emitter's wavelength sampling.
    Refused, in one line: polarized variants; ``render(develop=False)``; being
    wrapped by an integrator that calls its ``sample()`` (``aov``, ``moment``):
    the photon maps are built by its own ``render()``; ``hide_emitters`` in a scene
    with participating media.

    **Participating media** (homogeneous and heterogeneous): photons fly through them
    as lab_bdpt's light subpaths do (free flights, delta tracking in heterogeneous
    media) and store a *volumetric photon* at every collision; camera paths take free
    flights too, and at a collision gather the volumetric photons within r_v with the
    Epanechnikov kernel over the ball, divided by sigma_s there (``media_camera.py``,
    ``gather.volume_estimate``). ``radius_volume`` is r_v,1 (0: the surfaces' r_1),
    and r_v,{i+1}^3 = r_v,i^3 (i + alpha) / (i + 1). With ``direct = nee``, next-event
    estimation at the camera's vertex carries the transmittance to the light.

    Statistics of the last render: ``photon_stats()`` (passes, photons traced and
    stored, photon tracing / grid / gather times, photons per second) and
    ``ray_counts()`` (camera, camera-side extension, shadow and photon rays).

    .. code-block:: python

        {'type': 'lab_photon', 'photons_per_pass': 200000, 'passes': 32,
         'alpha': 0.66, 'radius': 0.0, 'radius_volume': 0.0, 'max_depth': -1, 'direct': 'nee',
         'hide_emitters': False}
    """
    #: The estimator class: what lab_photon knows about scenes and sample counts.
    ESTIMATOR = PhotonMapping
    #: Declared parameters (``params.LAB_PHOTON``), in the order of the table above.
    PARAMETERS = PhotonMapping.PARAMETERS

    def __init__(self, props: mi.Properties):
        name = self.ESTIMATOR.plugin_name
        values = plugin_settings(name, props, self.PARAMETERS, "integrator")
        if mi.is_polarized:
            variant = mi.variant()
            raise ValueError(f"{name}: variant '{variant}' is not supported: photons carry unpolarized flux "
                             f"(no Stokes vectors in the photon map); use {variant.replace('_polarized', '')}")
        super().__init__(props)
        self.settings_ = PhotonSettings(**values)
        self.stats = PhotonStats()
        self._camera = CameraPass(self.settings_)
        self._camera_rays = 0
        #: how the last render's automatic r_1 was made (``density_radius.FirstRadius``; None: ``radius`` given)
        self.radius_probe = None

    # -- Driver -------------------------------------------------------------------

    def render(self, scene: mi.Scene, sensor=0, seed=0, spp: int = 0, develop: bool = True,
               evaluate: bool = True):
        if not develop:
            raise ValueError("lab_photon: render(develop=False) is not supported: its image is the "
                             "average of developed pass images, so there is no film to leave undeveloped; "
                             "call render() with develop=True")
        traits = SceneTraits.from_scene(scene)
        if traits.media and self.settings_.hide_emitters:
            raise ValueError("lab_photon: hide_emitters is not supported in scenes with participating media yet")
        warn_if_unsupported(self, traits)         # never an image silently missing light
        sensor, seed, spp = render_arguments(scene, sensor, seed, spp)
        cfg = self.settings_
        depth = cfg.depth_limit
        min_segments = 2 if cfg.direct == "nee" else 1
        floor = spawn.offset_floor(traits)
        stats = PhotonStats(stored_flux=[0.0] * spectrum_channels())
        media = bool(traits.media)
        # heterogeneous media: delta tracking against the media's own majorants
        tracking = Tracking() if media and traits.heterogeneous_media else None
        self._camera.counters.reset()
        self._camera.hide_emitters, self._camera.offset_floor = cfg.hide_emitters, floor
        self._camera.media, self._camera.tracking = media, tracking
        size = sensor.film().crop_size()
        self._camera_rays = int(size[0]) * int(size[1]) * spp * cfg.passes
        bind_film_layout(sensor)                         # lab_zsobol learns the film's shape

        aim = AimedEmission(scene, cfg.aim, cfg.aim_at, "lab_photon")
        # Photons travel at most depth - 1 segments: the camera needs one to reach them.
        tracer = PhotonTracer(scene, max_segments=min(depth - 1, DEPTH_CAP), min_segments=min_segments,
                              rr_depth=cfg.rr_depth, offset_floor=floor,
                              aim=aim, media=media,
                              tracking=tracking,
                              emitter_media=emitter_media(scene, sensor, floor, "lab_photon") if media else None)
        self.radius_probe = None
        r1 = cfg.radius if cfg.radius > 0 else self.default_radius(scene, sensor, aim)
        radii = radius_schedule(r1, cfg.passes, cfg.alpha)
        stats.radius_first, stats.radius_last = radii[0], radii[-1]
        volume_radii = radius_schedule(cfg.radius_volume or r1, cfg.passes, cfg.alpha, dimension=3)
        if media:
            stats.radius_volume_first, stats.radius_volume_last = volume_radii[0], volume_radii[-1]
        # Spectral variants: one wavelength sample per pass, shared by photons and camera rays.
        u_passes = spectral.pass_samples(seed, cfg.passes) if mi.is_spectral else [None] * cfg.passes
        stores_per_photon = 4.0                          # first guess; learnt from each batch

        image = None
        for i, (radius, radius_volume) in enumerate(zip(radii, volume_radii)):
            pass_seed = int(mi.sample_tea_32(seed & 0xFFFFFFFF, i)[0])
            camera_seed = int(mi.sample_tea_32(i, seed & 0xFFFFFFFF)[0])
            u = u_passes[i]
            wavelengths = None if u is None else spectral.sensor_spectrum(sensor, u)[0]
            first, remaining, batch_index = 0, cfg.photons_per_pass, 0
            while remaining > 0:
                count = min(remaining, max(1, int(cfg.max_records / (1.25 * stores_per_photon))))
                for records, n_traced in self._trace_fitting(tracer, first, count, pass_seed, stats,
                                                             stores_per_photon, wavelengths):
                    stores_per_photon = max(0.25, (records.count + 1) / n_traced)
                    flux = records.total_power()
                    stats.stored_flux = [a + b for a, b in zip(stats.stored_flux, flux)]   # per channel
                    stored = records.count
                    t0 = time.perf_counter()
                    volume = None
                    if media:
                        records, in_media = records.split_media()
                        stats.photons_stored_in_media += in_media.count
                        volume = PhotonGrid(in_media, radius_volume)
                        del in_media
                    grid = PhotonGrid(records, radius)
                    dr.sync_thread()
                    stats.grid_s += time.perf_counter() - t0
                    stats.peak_record_bytes = max(stats.peak_record_bytes, 2 * stored * record_bytes())
                    del records
                    self._camera.grid, self._camera.with_direct = grid, batch_index == 0
                    self._camera.volume_grid = volume
                    t0 = time.perf_counter()
                    img = self._camera_pass(scene, sensor, camera_seed, spp, u)
                    interrupts.checkpoint(self._camera)    # Ctrl-C stops the render here, between passes
                    dr.eval(img)
                    dr.sync_thread()
                    stats.gather_s += time.perf_counter() - t0
                    image = img if image is None else image + img
                    dr.eval(image)
                    self._camera.grid = self._camera.volume_grid = None
                    batch_index += 1
                    stats.batches += 1
                first += count
                remaining -= count
            stats.passes += 1
        stats.photons_traced = cfg.photons_per_pass * cfg.passes
        self.stats = stats
        image = image * (1.0 / cfg.passes)
        dr.eval(image)
        return image

    def default_radius(self, scene: mi.Scene, sensor: mi.Sensor, aim=None) -> float:
        """The automatic r_1 (``common.density_radius``): a pixel's width, or more where a pass's
        photons (``photons_per_pass``, stored from the second segment with ``direct = nee``) are sparse."""
        cfg = self.settings_
        aim = aim or AimedEmission(scene, cfg.aim, cfg.aim_at, "lab_photon")
        self.radius_probe = first_radius(scene, sensor, cfg.photons_per_pass, min(cfg.depth_limit - 1, DEPTH_CAP),
                                         2 if cfg.direct == "nee" else 1, aim)
        return self.radius_probe.radius

    def _camera_pass(self, scene, sensor, camera_seed: int, spp: int, u):
        """One developed camera pass: Mitsuba's own ``SamplingIntegrator.render`` on the
        camera-pass object (its film, filter, sampler and spp handling, with our sample()), or
        in spectral variants the same with every ray at the pass's wavelength sample ``u``."""
        if u is None:
            return self._camera.render(scene, sensor, dr.opaque(mi.UInt32, camera_seed), spp, True, True)
        return spectral.render_pass(self._camera, scene, sensor, dr.opaque(mi.UInt32, camera_seed), spp, u)

    def _trace_fitting(self, tracer, first, count, pass_seed, stats, stores_per_photon, wavelengths=None):
        """Yield (records, photons) for photons [first, first + count), splitting the range in
        halves while its records do not fit in ``max_records`` (same photons either way)."""
        cfg = self.settings_
        capacity = int(min(cfg.max_records, max(MIN_RECORDS, math.ceil(1.5 * stores_per_photon * count))))
        while True:
            t0 = time.perf_counter()
            buffer, stores, segments = tracer.trace(first, count, pass_seed, cfg.photons_per_pass, capacity,
                                                    wavelengths)
            dr.eval(*buffer.arrays(), stores, segments)
            dr.sync_thread()
            stats.trace_s += time.perf_counter() - t0
            n_stores = int(stores[0])
            if n_stores <= capacity:
                break
            if n_stores <= cfg.max_records:              # fits: trace again with a larger buffer
                capacity = n_stores
                continue
            if count == 1:                               # one photon beyond the budget: keep what fits
                n_stores = capacity
                break
            stats.splits += 1
            half = count // 2
            yield from self._trace_fitting(tracer, first, half, pass_seed, stats, n_stores / count,
                                           wavelengths)
            yield from self._trace_fitting(tracer, first + half, count - half, pass_seed, stats,
                                           n_stores / count, wavelengths)
            return
        stats.photons_stored += n_stores
        stats.photon_segments += int(segments[0])
        yield buffer.take(n_stores).eval(), count

    # -- Camera pass ---------------------------------------------------------------

    def sample(self, scene, sampler, ray, medium=None, active=True):
        """The camera-side estimate with the current photon map (used inside ``render``).

        lab_photon builds a photon map per pass in ``render``; an integrator that calls
        ``sample`` itself (Mitsuba's ``aov`` or ``moment`` wrapping lab_photon) would get
        estimates without photons, so that is refused."""
        if self._camera.grid is None:
            raise ValueError("lab_photon: cannot be nested inside another integrator (such as aov or "
                             "moment) that calls its sample(): its photon maps are built per pass by "
                             "its own render(); render the scene with lab_photon directly")
        return self._camera.sample(scene, sampler, ray, medium, active)

    # -- Reporting --------------------------------------------------------------------

    def photon_stats(self) -> dict:
        """Statistics of the last render (see ``PhotonStats``), as plain values."""
        return self.stats.as_dict()

    def ray_counts(self, reset: bool = True) -> dict[str, int]:
        """Rays of the last render: camera, camera-side extension, shadow and photon segments."""
        counts = self._camera.counters.read(reset)    # extension and shadow rays, every batch
        return {**counts, "camera": self._camera_rays, "photon": self.stats.photon_segments}

    def settings(self) -> dict:
        return asdict(self.settings_)

    def to_string(self):
        fields = ", ".join(f"{k}={v}" for k, v in self.settings().items())
        return f"LabPhotonIntegrator[{fields}]"

    def aov_names(self):
        return []


mi.register_integrator("lab_photon", lambda props: LabPhotonIntegrator(props))
