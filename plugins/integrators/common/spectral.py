"""Spectral variants: one set of wavelengths per pass, shared by photons and camera rays.

A density estimate adds up photons that hit near a camera vertex, so a photon's flux and the
camera path's BSDF values must be spectra at the same wavelengths. In a spectral variant every
pass therefore draws one wavelength sample u_i for all of its lanes:

* camera rays come from ``Sensor.sample_ray_differential(time, u_i, ...)``: the sensor's own
  wavelength sampling (its response function and pdf, the ray weight), the same wavelengths
  lambda_i in every lane (``render_pass``, Mitsuba's camera pass with u_i in place of a
  per-lane sample);
* photons are emitted at lambda_i (``EmitterSpectra``, ``emit``). An emitter samples its
  k-th wavelength as F(frac(u + k/4)) with weight L_e(lambda) / p(lambda), F its own
  monotone inverse CDF: uniform over [MI_CIE_MIN, MI_CIE_MAX] for ``rgb``, ``uniform`` and
  bitmap spectra, importance sampled for ``blackbody``, spectrum files and the D65 of an
  ``envmap``. F does not depend on where the emitter is sampled, so it is tabulated once per
  render; for each pass and emitter the table gives u_k with F(frac(u_k + k/4)) = lambda_k
  and the density p(lambda_k) = dF^-1/dlambda (a central difference over 8 table steps,
  exact for the uniform map). One ``sample_ray`` call per wavelength with the same spatial
  samples (so the same ray), wavelength k of call k, times p(lambda_k), is the flux
  L_e(lambda_k) x (spatial weight) at exactly the camera's wavelengths. An emitter whose F
  is not monotone is refused in one line.

The sensor's weight carries the spectral pdf, the photon flux does not, so a pass estimates
the pixel's spectral integral at lambda_i; u_i follows a golden-ratio sequence with a random
start (``pass_samples``), so any number of passes covers the spectrum evenly and every u_i
is uniform: the average over passes converges to the full spectral integral. Consequence:
each pass has the colour noise of only 4 wavelengths, and that noise averages out over
passes, not over the camera samples of one pass (a few passes show colour noise that more
spp per pass would not remove).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

def spectrum_channels() -> int:
    """Channels of the variant's unpolarized spectrum: 3 (RGB), 1 (mono), 4 (spectral)."""
    return dr.size_v(mi.UnpolarizedSpectrum)


#: 1 / golden ratio: u_i = frac(u_0 + i / phi) fills [0, 1) evenly for any number of passes.
INV_PHI = (math.sqrt(5.0) - 1.0) / 2.0


def pass_samples(seed: int, passes: int) -> list[float]:
    """u_i for passes i = 0..P-1: golden-ratio sequence from a start drawn from ``seed``."""
    start = float(mi.sample_tea_float32(seed & 0xFFFFFFFF, 0x5EC7)) if passes else 0.0
    return [(start + i * INV_PHI) % 1.0 for i in range(passes)]


def sensor_spectrum(sensor: mi.Sensor, u: float):
    """(wavelengths (nm), spectral weight) the sensor gives every camera ray of a pass with
    sample ``u``: the weight (response over density, an ``mi.Spectrum``) that a camera ray's
    weight carries, and that a light path splatted into the film at those wavelengths needs."""
    wavelengths, weight = sensor.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f, 1), mi.Float(u))
    n = dr.size_v(mi.UnpolarizedSpectrum)
    # opaque: a pass's values must not be compiled into the kernels
    return ([float(wavelengths[k][0]) for k in range(n)],
            mi.Spectrum(*[dr.opaque(mi.Float, float(weight[k][0])) for k in range(n)]))


def emitter_name(emitter, index: int) -> str:
    shape = emitter.get_shape()                          # an area light is known by its shape
    return (shape.id() if shape is not None else emitter.id()) or f"#{index}"


class EmitterSpectra:
    """Each emitter's wavelength map F (``TABLE`` + 1 points of u -> lambda), and per pass the
    samples and densities that emit photons at given wavelengths (``tables``)."""

    TABLE = 4096
    #: Half-width, in table steps, of the central difference that gives dF^-1/dlambda.
    HALF_WINDOW = 4

    def __init__(self, scene: mi.Scene, plugin: str = "lab_photon"):
        self.plugin = plugin
        self._lane_tables = None            # (``lane_samples``: made on first use)
        emitters = scene.emitters()
        n = self.TABLE + 1
        self.grid = np.linspace(0.0, 1.0, n)
        u = mi.Float(np.minimum(self.grid, 1.0 - 2.0 ** -24))
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = mi.Vector3f(0, 0, 1)
        # One direct call per emitter (some spectra, e.g. blackbody, cannot be sampled inside a
        # symbolic call over all emitters). Wavelength 0 has no shift: it is F itself.
        # Mitsuba's blackbody samples its wavelengths with a host-side Newton loop, which runs
        # only on values known when the kernel is traced: its samples must stay literals
        self.literal_samples = any(key.endswith("temperature") for e in emitters for key in mi.traverse(e).keys())
        if self.literal_samples and len(emitters) > 1:
            # (with several emitters a lane's sample is gathered from a table: not a literal)
            raise ValueError(f"{plugin}: a blackbody emitter among {len(emitters)} emitters cannot be emitted at "
                             f"the camera's wavelengths in spectral variants (Mitsuba samples a blackbody's "
                             f"wavelengths only from values fixed when its kernel is traced); give it an "
                             f"RGB or tabulated spectrum, make it the only emitter, or use an RGB variant")
        self.maps = np.array([np.array(e.sample_wavelengths(si, u)[0][0], dtype=np.float64) for e in emitters])
        for e, lam in enumerate(self.maps):
            if np.any(np.diff(lam) < 0) or not np.all(np.isfinite(lam)):
                raise ValueError(f"{plugin}: emitter '{emitter_name(emitters[e], e)}' "
                                 f"({emitters[e].class_name()}) samples its wavelengths by a map that "
                                 f"is not monotone, so its photons cannot be emitted at the camera's "
                                 f"wavelengths in spectral variants; use an RGB variant")

    def invert(self, e: int, wavelengths) -> tuple[np.ndarray, np.ndarray]:
        """(t, density) of emitter ``e``'s map at each of ``wavelengths`` (numpy): t with F(t) =
        lambda, linear in the table, and dF^-1/dlambda there (a central difference over 2
        ``HALF_WINDOW`` table steps); both 0 where the emitter never samples lambda."""
        table, h = self.maps[e], self.HALF_WINDOW
        lam = np.asarray(wavelengths, dtype=np.float64)
        inside = (table[0] <= lam) & (lam <= table[-1])
        i = np.clip(np.searchsorted(table, lam), h, len(table) - 1 - h)
        span = table[i + h] - table[i - h]
        density = (self.grid[i + h] - self.grid[i - h]) / np.where(span > 0, span, 1.0)
        return (np.where(inside, np.interp(lam, table, self.grid), 0.0),
                np.where(inside & (span > 0), density, 0.0))

    def tables(self, wavelengths: list[float]):
        """(u_k, p_k) for k = 0..n-1, each a Float array over the emitters: the sample for
        which an emitter's wavelength k is ``wavelengths[k]``, and that wavelength's density
        (0 where the emitter never samples it: it emits nothing there)."""
        n = len(wavelengths)
        us, ps = [], []
        for k, lam in enumerate(wavelengths):
            t, p = zip(*(self.invert(e, lam) for e in range(len(self.maps))))
            us.append(mi.Float([(float(t_e) - k / n) % 1.0 for t_e in t]))
            ps.append(mi.Float([float(p_e) for p_e in p]))
        if not self.literal_samples:
            # with one emitter a table is a single value, which would be compiled into the
            # kernels, and every pass would compile them again: keep it in memory
            dr.make_opaque(*us, *ps)
        return us, ps

    def emit(self, emitter, emitter_index, time, wavelengths, sample2, sample3):
        """(ray, flux weight) of each lane's ``emitter`` (``emitter_index``: its index in the
        scene's emitters) at the pass's ``wavelengths`` (``emit`` with this pass's tables), or,
        where ``wavelengths`` is a Dr.Jit array, at each lane's own (``lane_samples``)."""
        if not isinstance(wavelengths, (list, tuple)):
            samples, densities = self.lane_samples(emitter_index, wavelengths)
            return emit(emitter, time, [wavelengths[k] for k in range(len(samples))], samples, densities,
                        sample2, sample3, True)
        u_tables, p_tables = self.tables(wavelengths)
        return emit(emitter, time, [dr.opaque(mi.Float, v) for v in wavelengths],
                    [dr.gather(mi.Float, t, emitter_index) for t in u_tables],
                    [dr.gather(mi.Float, t, emitter_index) for t in p_tables], sample2, sample3, True)

    #: Steps of the per-lane inverse maps over [MI_CIE_MIN, MI_CIE_MAX] (``lane_samples``).
    LANE_TABLE = 4096

    def check_lane_samples(self) -> None:
        """Refuse, in one line, emitters that ``lane_samples`` cannot emit."""
        if self.literal_samples:
            raise ValueError(f"{self.plugin}: a blackbody emitter cannot be emitted at each lane's own wavelengths "
                             f"in spectral variants (Mitsuba samples a blackbody's wavelengths only from values "
                             f"fixed when its kernel is traced); give it an RGB or tabulated spectrum, or use an "
                             f"RGB variant")

    def lane_samples(self, emitter_index, wavelengths):
        """(u_k, p_k) per lane (``tables``' values) for wavelengths that differ from lane to lane
        (lab_mmlt: each chain holds its own wavelength sample): each emitter's t and density
        tabulated once over a uniform grid of ``LANE_TABLE`` steps over the visible range and
        interpolated linearly (exact for the uniform map of ``rgb`` and ``uniform`` spectra).
        Mitsuba samples a blackbody's wavelengths only from literals (see ``__init__``), so a
        blackbody is refused here in one line."""
        self.check_lane_samples()
        if self._lane_tables is None:
            lo, hi, m = mi.MI_CIE_MIN, mi.MI_CIE_MAX, self.LANE_TABLE
            grid = np.linspace(lo, hi, m + 1)
            t, p = zip(*(self.invert(e, grid) for e in range(len(self.maps))))
            self._lane_tables = (mi.Float(np.concatenate(t)), mi.Float(np.concatenate(p)))
        t_table, p_table = self._lane_tables
        lo, hi, m = mi.MI_CIE_MIN, mi.MI_CIE_MAX, self.LANE_TABLE
        n = dr.size_v(mi.UnpolarizedSpectrum)
        base = mi.UInt32(emitter_index) * (m + 1)
        samples, densities = [], []
        for k in range(n):
            x = dr.clip((mi.Float(wavelengths[k]) - lo) * (m / (hi - lo)), 0.0, float(m))
            i = dr.minimum(mi.UInt32(x), m - 1)
            f = x - mi.Float(i)
            t = dr.lerp(dr.gather(mi.Float, t_table, base + i), dr.gather(mi.Float, t_table, base + i + 1), f)
            u = t - k / n
            samples.append(dr.select(u < 0.0, u + 1.0, u))
            densities.append(dr.lerp(dr.gather(mi.Float, p_table, base + i),
                                     dr.gather(mi.Float, p_table, base + i + 1), f))
        return samples, densities


def emit(emitter, time, wavelengths, samples, densities, sample2, sample3, active):
    """(ray, flux weight) of ``Emitter.sample_ray`` at the pass's ``wavelengths``.

    ``samples`` and ``densities``: per wavelength, the u_k and p(lambda_k) of this lane's
    emitter (``EmitterSpectra.tables``). One call per wavelength with the same spatial samples
    gives the same ray each time; wavelength k of call k is L_e(lambda_k) / p(lambda_k) x
    (spatial weight), and p(lambda_k) is multiplied back: the camera's weight holds the pdf.
    """
    ray = None
    values = []
    for k, u in enumerate(samples):
        ray_k, weight_k = emitter.sample_ray(time, u, sample2, sample3, active)
        ray = ray_k if ray is None else ray
        values.append(mi.unpolarized_spectrum(weight_k)[k] * densities[k])
    # The camera's wavelengths exactly (the inverted map returns them up to rounding).
    ray.wavelengths = type(ray.wavelengths)(*wavelengths)
    return ray, mi.Spectrum(*values)


def render_pass(integrator, scene: mi.Scene, sensor: mi.Sensor, seed, spp: int, u: float):
    """One camera pass of ``integrator`` (a ``SamplingIntegrator``), developed, with every
    camera ray's wavelength sample equal to ``u``: Mitsuba's ``SamplingIntegrator.render``
    (the Python version of its AD integrators) with that one change."""
    film = sensor.film()
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(spp)
    sampler.set_samples_per_wavefront(spp)
    size = film.crop_size()
    border = film.rfilter().border_size() if film.sample_border() else 0
    width, height = int(size[0]) + 2 * border, int(size[1]) + 2 * border
    sampler.seed(seed, width * height * spp)
    film.prepare([])

    idx = dr.arange(mi.UInt32, width * height * spp) // dr.opaque(mi.UInt32, spp)
    pos = mi.Vector2i()
    pos.y = mi.Int32(idx // width)
    pos.x = mi.Int32(idx % width)
    pos += mi.Vector2i(film.crop_offset()) - border
    pos_f = mi.Vector2f(pos) + sampler.next_2d()
    scale = dr.rcp(mi.ScalarVector2f(film.crop_size()))
    offset = -mi.ScalarVector2f(film.crop_offset()) * scale
    aperture = sampler.next_2d() if sensor.needs_aperture_sample() else mi.Point2f(0.5)
    time = mi.Float(sensor.shutter_open())
    if sensor.shutter_open_time() > 0:
        time += sampler.next_1d() * sensor.shutter_open_time()
    ray, ray_weight = sensor.sample_ray_differential(time, dr.opaque(mi.Float, u), dr.fma(pos_f, scale, offset),
                                                     aperture)
    L, valid, _ = integrator.sample(scene, sampler, ray, sensor.get_medium(), True)   # (rays start in its medium)

    block = film.create_block()
    block.set_coalesce(block.coalesce() and spp >= 4)
    splat = mi.Vector2f(pos) if film.rfilter().is_box_filter() else pos_f
    alpha = dr.select(valid, mi.Float(1), mi.Float(0))
    value = mi.unpolarized_spectrum(L * ray_weight)
    if mi.has_flag(film.flags(), mi.FilmFlags.Special):
        block.put(splat, film.prepare_sample(value, ray.wavelengths, block.channel_count(), weight=1.0,
                                             alpha=alpha))
    else:
        rgb = mi.spectrum_to_srgb(value, ray.wavelengths)
        values = [rgb.x, rgb.y, rgb.z] + ([alpha] if mi.has_flag(film.flags(), mi.FilmFlags.Alpha) else [])
        block.put(splat, values + [mi.Float(1)])
    film.put_block(block)
    return film.develop()
