"""One honest, timed render: image + RenderStats.

Dr.Jit records work lazily and launches it asynchronously, so the clock stops
only after ``dr.eval`` and ``dr.sync_thread``. Dr.Jit's kernel history splits
the time into compilation (code generation + LLVM/CUDA backend) and kernel
execution; the rest of the wall time is tracing Python and Mitsuba's set-up.

Before the clock starts the sensor's film is bound to its sampler
(``bind_film_layout``): a sampler whose points depend on the pixel's position
(``lab_zsobol``) then knows the film's shape under any integrator, Mitsuba's too.

Ctrl-C during a render raises KeyboardInterrupt once the running kernel (a multi-pass
integrator's pass) has finished (``interrupts``).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab import interrupts
from mitsuba_lab.plugins.samplers.layout import bind_film_layout


@dataclass
class RenderStats:
    """What one render cost; all times in seconds."""
    wall_s: float
    compile_s: float           # codegen + backend compile of kernels that missed the cache
    kernel_s: float            # execution time of all launched kernels
    kernels: int               # kernels launched
    cache_misses: int          # kernels compiled during this render (0 once warm)
    spp: int
    seed: int
    width: int
    height: int
    rays: dict[str, int] = field(default_factory=dict)  # by kind, when the integrator counts them
    integrator: dict = field(default_factory=dict)      # the integrator's own statistics (integrator_stats)

    @property
    def samples_per_second(self) -> float:
        return self.width * self.height * self.spp / self.wall_s if self.wall_s > 0 else float("inf")

    def as_dict(self) -> dict:
        return {**asdict(self), "samples_per_second": self.samples_per_second}


def _kernel_times(history: list[dict]) -> tuple[float, float, int, int]:
    compile_ms = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in history)
    exec_ms = sum(k.get("execution_time", 0.0) for k in history)
    misses = sum(1 for k in history if "cache_hit" in k and not k["cache_hit"])
    return compile_ms / 1e3, exec_ms / 1e3, len(history), misses


def timed_kernels(fn):
    """(result, wall seconds, Dr.Jit kernel history) of ``fn()``: the clock starts after
    ``dr.sync_thread()`` (nothing earlier leaks in) and stops after ``dr.eval`` of the result
    and ``dr.sync_thread()``; the history holds this call's kernels only."""
    dr.sync_thread()
    history_was_on = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()                                # drop older entries
    try:
        start = time.perf_counter()
        out = fn()
        dr.eval(out)
        dr.sync_thread()
        wall = time.perf_counter() - start
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, history_was_on)
    return out, wall, history


#: The methods by which lab integrators report statistics of their last render.
STATS_METHODS = ("bdpt_stats", "photon_stats", "mlt_stats")


def _plain(value):
    """``value`` as JSON holds it: dict keys as text, numbers, text and booleans as they are,
    anything else as its text."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    return str(value)


def integrator_stats(integrator) -> dict:
    """The statistics an integrator keeps of its last render (lab_bdpt's and lab_vcm's
    ``bdpt_stats()``, lab_photon's ``photon_stats()``: passes, times, radii, what a pilot
    chose), as plain values; {} for an integrator without them (Mitsuba's own)."""
    for name in STATS_METHODS:
        if hasattr(integrator, name):
            return _plain(getattr(integrator, name)())
    return {}


def render(scene: mi.Scene, integrator: mi.Integrator | None = None, spp: int = 0, seed: int = 0,
           sensor: int = 0) -> tuple[np.ndarray, RenderStats]:
    """Render and wait for the result. Returns (H x W x C float32 image, stats).

    ``spp`` = 0 keeps the scene sampler's own sample count. The film of sensor
    ``sensor`` is bound to its sampler first (``bind_film_layout``).
    """
    if spp < 0:
        raise ValueError(f"spp must be >= 0, got {spp}")
    integrator = integrator if integrator is not None else scene.integrator()
    bind_film_layout(scene, sensor)
    sampler = scene.sensors()[sensor].sampler()
    spp_used = spp or sampler.sample_count()
    with interrupts.rendering():          # Ctrl-C: KeyboardInterrupt, and Python's handler kept
        image, wall, history = timed_kernels(
            lambda: mi.render(scene, integrator=integrator, spp=spp, seed=seed, sensor=sensor))
    compile_s, kernel_s, kernels, misses = _kernel_times(history)
    rays = integrator.ray_counts() if hasattr(integrator, "ray_counts") else {}
    pixels = np.array(image, dtype=np.float32)
    stats = RenderStats(wall_s=wall, compile_s=compile_s, kernel_s=kernel_s, kernels=kernels,
                        cache_misses=misses, spp=spp_used, seed=seed,
                        width=pixels.shape[1], height=pixels.shape[0], rays=rays,
                        integrator=integrator_stats(integrator))
    return pixels, stats
