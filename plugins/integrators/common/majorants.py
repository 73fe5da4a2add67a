"""Majorant grids: local bounds on a heterogeneous medium's extinction, traversed cell by cell.

Delta and ratio tracking propose tentative collisions at the rate of a majorant sigma_bar >=
sigma_t; Mitsuba's ``heterogeneous`` medium has one per medium, ``scale * max(grid)``, so in a
sparse grid (smoke: most cells empty, a dense core) almost every proposal is a null collision
that costs a volume lookup. A majorant grid (pbrt-v4's ``MajorantGrid`` and
``DDAMajorantIterator``) bounds each of a coarse set of cells by its own maximum: the free
flight walks the cells the ray crosses with a 3D DDA (Amanatides and Woo 1987) and samples the
exponential against a piecewise-constant majorant by accumulating optical depth: a target
tau = -ln(1 - u) is spent cell by cell (sigma_bar_k times the length in cell k) and the tentative
collision lies where it runs out; after a null collision a new tau is drawn from there. Empty
cells (bound 0) cost one DDA step and no lookup.

The bound of a cell is ``scale`` times the largest grid value that trilinear interpolation can
reach anywhere in the cell: the voxels of its footprint widened by one voxel on each side (the
texture's cell-centred lookup at u N - 1/2 reads the two voxels around it; at the grid's faces
both the clamped and the wrapped-around voxel are included, so any ``wrap_mode`` is bounded),
times 1 + 2^-16 against float rounding in the interpolation. tests/plugins/test_media.py checks
the bound at random points of every cell.

What it handles: a ``heterogeneous`` medium whose ``sigma_t`` is a one-channel ``gridvolume``
placed by scaling and translation (its box is the medium's box, as Mitsuba clips tracking to it);
``MajorantGrid.of`` refuses the rest in one line. One such medium per scene (homogeneous media
are exact without one and keep Mitsuba's sampling).
"""
from __future__ import annotations

import re

import drjit as dr
import mitsuba as mi
import numpy as np

#: Safety factor of each bound against float rounding in the trilinear interpolation.
ROUNDING = 1.0 + 2.0 ** -16


def _grid_volume_text(medium) -> str:
    text = str(medium)
    at = text.find("sigma_t = ")
    return text[at:] if at >= 0 else ""


def _to_local(medium) -> np.ndarray:
    """The 4x4 ``to_local`` matrix of the medium's sigma_t grid volume (from its description:
    Mitsuba 3.9 exposes no other way to read it)."""
    text = _grid_volume_text(medium)
    m = re.search(r"to_local = Transform\[\s*matrix=(\[\[.*?\]\])", text, re.S)
    if m is None:
        raise ValueError("cannot read the grid volume's to_local")
    rows = re.findall(r"\[([^\[\]]+)\]", m.group(1))
    return np.array([[float(v) for v in row.split(",")] for row in rows], dtype=np.float64)


def refusal(medium) -> str:
    """'' if ``MajorantGrid.of`` can build a grid for ``medium``, else why not (one line)."""
    if medium.is_homogeneous():
        return ""
    if medium.class_name() != "HeterogeneousMedium":
        return f"a {medium.class_name()} medium"
    params = mi.traverse(medium)
    if "sigma_t.data" not in params.keys() or not _grid_volume_text(medium).startswith("sigma_t = GridVolume"):
        return "a heterogeneous medium whose sigma_t is not a gridvolume"
    if params["sigma_t.data"].shape[-1] != 1:
        return f"a sigma_t grid of {params['sigma_t.data'].shape[-1]} channels (one is handled)"
    try:
        M = _to_local(medium)
    except ValueError as e:
        return str(e)
    if np.any(np.abs(M[:3, :3] - np.diag(np.diag(M[:3, :3]))) > 1e-7 * np.abs(M[:3, :3]).max()):
        return "a sigma_t grid volume that is rotated or sheared (scaling and translation are handled)"
    return ""


def cell_bounds(data: np.ndarray, resolution) -> np.ndarray:
    """Per majorant cell (indexed [z, y, x] as the data, ``resolution`` = cells along x, y, z),
    the largest value trilinear interpolation of ``data`` ([z, y, x] or [z, y, x, c], cell-centred
    voxels, any wrap mode) takes anywhere inside the cell."""
    data = np.asarray(data, dtype=np.float64)
    if data.ndim == 4:
        data = data.max(axis=3)
    out = data
    for axis, cells in zip((2, 1, 0), resolution):        # x, y, z
        n = data.shape[axis]
        maxima = []
        for k in range(cells):
            a, b = k / cells, (k + 1) / cells
            lo, hi = int(np.floor(a * n - 0.5)), int(np.floor(b * n - 0.5)) + 1
            idx = set(range(max(lo, 0), min(hi, n - 1) + 1))
            if lo < 0:
                idx |= {0, n - 1}                          # clamped, or wrapped around
            if hi > n - 1:
                idx |= {n - 1, 0}
            maxima.append(np.take(out, sorted(idx), axis=axis).max(axis=axis))
        out = np.stack(maxima, axis=axis)
    return out


class MajorantGrid:
    """The majorant grid of one heterogeneous medium: ``values`` (cells [z, y, x] flattened,
    x fastest), ``resolution`` (cells along x, y, z), ``to_local`` (world to the grid's unit
    cube), the medium and a pointer to it for the path loop's lanes."""

    def __init__(self, medium, resolution: int = 16):
        why = refusal(medium)
        if why or medium.is_homogeneous():
            raise ValueError(f"majorants = grid cannot handle {why or 'a homogeneous medium'}")
        params = mi.traverse(medium)
        data = params["sigma_t.data"].numpy()
        nz, ny, nx = data.shape[:3]
        self.resolution = tuple(min(resolution, n) for n in (nx, ny, nz))
        bounds = float(params["scale"]) * cell_bounds(data, self.resolution) * ROUNDING
        self.bounds = bounds.astype(np.float32)
        self.values = mi.Float(self.bounds.ravel())
        self.global_majorant = float(params["scale"]) * float(data.max())
        self.to_local = mi.ScalarTransform4f(_to_local(medium).tolist())
        self.medium = medium
        self.pointer = mi.MediumPtr(medium)
        self.version = _version(medium)

    @property
    def nbytes(self) -> int:
        """Memory of the bounds (float32)."""
        return int(self.bounds.nbytes)

    def describe(self) -> str:
        rx, ry, rz = self.resolution
        return (f"majorant grid {rx}x{ry}x{rz} ({self.nbytes} bytes), mean bound "
                f"{self.bounds.mean():.4g} against the global {self.global_majorant:.4g}")

    @classmethod
    def of(cls, scene: mi.Scene, resolution: int = 16) -> "MajorantGrid | None":
        """The grid of the scene's one heterogeneous medium (None if it has none); a ValueError
        whose message is one line where the scene's media cannot be handled."""
        media = {}
        for shape in scene.shapes():
            for m in (shape.interior_medium(), shape.exterior_medium()):
                if m is not None:
                    media[m.ptr] = m
        for sensor in scene.sensors():
            m = sensor.get_medium()
            if m is not None:
                media[m.ptr] = m
        hetero = [m for m in media.values() if not m.is_homogeneous()]
        for m in hetero:
            why = refusal(m)
            if why:
                raise ValueError(f"majorants = grid cannot handle {why}: use majorants = global")
        if len(hetero) > 1:
            raise ValueError(f"majorants = grid handles one heterogeneous medium per scene, this one has "
                             f"{len(hetero)}: use majorants = global")
        return cls(hetero[0], resolution) if hetero else None


def _version(medium) -> tuple:
    """What a grid was built from: the sigma_t data's Dr.Jit variable (a new one whenever the
    data is set, e.g. through ``mi.traverse``) and the scale."""
    params = mi.traverse(medium)
    return params["sigma_t.data"].array.index, float(params["scale"])


def of_integrator(integrator, scene: mi.Scene) -> "MajorantGrid | None":
    """The majorant grid of ``scene`` for a path tracer with ``majorants = grid`` (built on the
    first render of the scene and kept on the integrator for the next, until the medium's
    sigma_t data or scale change), else None; a ValueError of one line, naming the plugin, where
    the scene's media cannot have one."""
    if integrator.majorants != "grid":
        return None
    kept = getattr(integrator, "_majorant_grid", (None, None))
    if kept[0] is not scene or (kept[1] is not None and kept[1].version != _version(kept[1].medium)):
        try:
            kept = (scene, MajorantGrid.of(scene, integrator.majorant_resolution))
        except ValueError as e:
            raise ValueError(f"{integrator.ESTIMATOR.plugin_name}: {e}") from None
        integrator._majorant_grid = kept
    return kept[1]


def _local_ray(grid: MajorantGrid, ray: mi.Ray3f):
    T = mi.Transform4f(grid.to_local)
    return T @ ray.o, T @ ray.d


def _box_interval(o, d):
    """[t0, t1] of the line o + t d inside the unit cube (t0 > t1 where it misses)."""
    t0, t1 = mi.Float(-dr.inf), mi.Float(dr.inf)
    for a in range(3):
        inv = dr.rcp(d[a])
        lo, hi = (0.0 - o[a]) * inv, (1.0 - o[a]) * inv
        flat = d[a] == 0
        inside = (o[a] >= 0) & (o[a] <= 1)
        t0 = dr.select(flat, dr.select(inside, t0, dr.inf), dr.maximum(t0, dr.minimum(lo, hi)))
        t1 = dr.select(flat, dr.select(inside, t1, -dr.inf), dr.minimum(t1, dr.maximum(lo, hi)))
    return t0, t1


def _coefficients(medium, ray: mi.Ray3f, t, active):
    """(sigma_s, sigma_t) of ``medium`` at distance ``t`` along ``ray``."""
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.p, mei.t, mei.time, mei.wavelengths = ray.o + t * ray.d, t, ray.time, ray.wavelengths
    sigma_s, _, sigma_t = medium.get_scattering_coefficients(mei, active)
    return sigma_s, sigma_t


@dr.syntax
def _walk(grid: MajorantGrid, step, spacing, t, t_end, tau, cell, cross, active):
    """The DDA (Amanatides and Woo): from distance ``t`` in ``cell``, whose planes ahead the ray
    meets at ``cross`` (per axis; successive planes ``spacing`` apart), spend the optical depth
    ``tau`` against the cells' bounds. Returns (t, cell, cross, bound, collide): where it ran out
    (the tentative collision, in ``cell`` of bound ``bound``) where ``collide``, else the ray left
    the grid or reached ``t_end`` first."""
    res = mi.Vector3i(*grid.resolution)
    nx, ny = grid.resolution[0], grid.resolution[1]
    t, tau, cell, cross = mi.Float(t), mi.Float(tau), mi.Vector3i(cell), mi.Vector3f(cross)
    bound = mi.Float(0.0)
    collide = mi.Bool(False)
    walking = mi.Bool(active)
    while walking:
        bound = dr.gather(mi.Float, grid.values, cell.x + nx * (cell.y + ny * cell.z), walking)
        # where the ray leaves the cell: the nearest of the three planes ahead of it
        t_cell = dr.maximum(dr.minimum(dr.min(cross), t_end), t)
        dt = tau / bound                              # inf in an empty cell
        here = walking & (t + dt < t_cell)
        collide |= here
        t[here] = t + dt
        # past the cell: spend its optical depth, step to the neighbour
        passes = walking & ~here
        tau[passes] = tau - bound * (t_cell - t)
        t[passes] = t_cell
        moving = passes & (t_cell < t_end)
        axis_x = moving & (cross.x <= cross.y) & (cross.x <= cross.z)
        axis_y = moving & ~axis_x & (cross.y <= cross.z)
        axis_z = moving & ~axis_x & ~axis_y
        cell.x[axis_x] = cell.x + step.x
        cross.x[axis_x] = cross.x + spacing.x
        cell.y[axis_y] = cell.y + step.y
        cross.y[axis_y] = cross.y + spacing.y
        cell.z[axis_z] = cell.z + step.z
        cross.z[axis_z] = cross.z + spacing.z
        inside = ~dr.any((cell < 0) | (cell >= res))
        walking = moving & inside
    return t, cell, cross, bound, collide


@dr.syntax
def track(grid: MajorantGrid, ray: mi.Ray3f, t_max, sampler: mi.Sampler, active, kind: str):
    """Tracking along ``ray`` (unit direction, inside ``grid``'s medium) up to ``t_max`` against
    the grid's piecewise-constant majorant.

    ``kind`` ``flight`` (delta tracking for a free flight): returns (t, scattered, weight): the
    distance of the real collision where ``scattered``, and the throughput factor, per channel
    sigma_n / (sigma_bar P_null) at each null collision and sigma_s / (sigma_bar P_real) at the
    real one, P_null = mean(sigma_n) / sigma_bar (the transmittance over the exponential's
    density, 1 / sigma_bar at each tentative collision and 1 at the escape, is folded in; the
    bound is one number for every channel). ``ratio``: returns (_, _, T), T the product of
    sigma_n / sigma_bar over the tentative collisions (ratio tracking); ``delta``: T = 0 at a
    real collision, sigma_n / (sigma_bar P_null) at each null one (1 with equal channels).
    Each also returns ``nulls`` last, the null chain (``media``): the product of P_null over the
    null collisions that delta tracking chose (``flight``, ``delta``: there 1) or that ratio
    tracking passed (``ratio``: every tentative collision).
    """
    medium = grid.medium
    o, d = _local_ray(grid, ray)
    res = mi.Vector3f(*grid.resolution)
    t_in, t_out = _box_interval(o, d)
    t = dr.maximum(t_in, 0.0)
    t_end = dr.minimum(t_out, t_max)
    going = mi.Bool(active) & (t < t_end)
    start = (o + t * d) * res
    cell = mi.Vector3i(dr.clip(mi.Vector3i(dr.floor(start)), 0, mi.Vector3i(res) - 1))
    step = mi.Vector3i(dr.select(d > 0, 1, dr.select(d < 0, -1, 0)))
    ahead = (mi.Vector3f(cell) + dr.select(d > 0, 1.0, 0.0)) / res
    cross = dr.select(step != 0, (ahead - o) / d, dr.inf)       # the planes ahead, per axis
    spacing = dr.select(step != 0, dr.abs(dr.rcp(res * d)), dr.inf)
    weight = mi.UnpolarizedSpectrum(1.0)
    scattered = mi.Bool(False)
    t_hit = mi.Float(dr.inf)
    nulls = mi.Float(1.0)
    while going:
        # the next tentative collision: an optical depth tau spent cell by cell from t
        tau = -dr.log(1.0 - sampler.next_1d(going))
        t, cell, cross, bound, collide = _walk(grid, step, spacing, t, t_end, tau, cell, cross, going)
        going &= collide
        sigma_s, sigma_t = _coefficients(medium, ray, t, collide)
        sigma_n = bound - sigma_t
        p_null = dr.mean(sigma_n) / bound
        if dr.hint(kind == "ratio", mode="scalar"):
            weight[collide] *= sigma_n / bound
            nulls[collide] *= p_null
        else:
            null = collide & (sampler.next_1d(collide) < p_null)
            real = collide & ~null
            weight[null] *= sigma_n / (bound * p_null)
            if dr.hint(kind == "flight", mode="scalar"):
                nulls[null] *= p_null
                weight[real] *= sigma_s / (bound * (1.0 - p_null))
                scattered |= real
                t_hit[real] = t
            else:
                weight[real] = 0.0
            going &= ~real
        going &= dr.max(weight) > 0
    return t_hit, scattered, weight, nulls


def free_flight(grid: MajorantGrid, ray: mi.Ray3f, t_max, sampler: mi.Sampler, active):
    """``track(kind='flight')`` with its collision as a medium interaction: (mei, scattered,
    weight, nulls), as ``media.free_flight`` returns them."""
    t_hit, scattered, weight, nulls = track(grid, ray, t_max, sampler, active, "flight")
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.t = dr.select(scattered, t_hit, dr.inf)
    mei.p = ray.o + mei.t * ray.d
    mei.wi = -ray.d
    mei.sh_frame = mi.Frame3f(mei.wi)
    mei.time = ray.time
    mei.wavelengths = ray.wavelengths
    mei.medium = dr.select(scattered, grid.pointer, dr.zeros(mi.MediumPtr))
    sigma_s, _, sigma_t = grid.medium.get_scattering_coefficients(mei, scattered)
    mei.sigma_s, mei.sigma_t = sigma_s, sigma_t
    mei.combined_extinction = mi.UnpolarizedSpectrum(grid.global_majorant)
    mei.sigma_n = mei.combined_extinction - sigma_t
    return mei, scattered, weight, nulls
