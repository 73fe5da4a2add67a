"""Where lab_mis's heavy tail in fog_shafts' `shafts` region comes from (issue 44 b): 8 seeds of
lab_mis in three medium samplings at a fixed sample count, each seed's region mean and brightest
pixel; then, for one seed, the brightest pixel split into what equi-angular sampling brought and the
rest (the same render with every equi-angular contribution x 0: same random numbers), at max_depth
2, 3 and 16.

    PYTHONPATH=src .venv/bin/python benchmarks/media_shafts_tail.py
"""
import numpy as np
import mitsuba as mi

import mitsuba_lab

RES, SPP, SEEDS = 48, 64, range(100, 108)
SHAFTS = (slice(15, 19), slice(22, 27))          # fog_shafts.regions.toml's `shafts` at res 48


def render(scene, depth, seed, **params):
    from mitsuba_lab.scene import make_integrator
    integrator = make_integrator("lab_mis", {"max_depth": depth, **params})
    return np.array(mi.render(scene, integrator=integrator, spp=SPP, seed=seed)).mean(-1)


def main():
    mitsuba_lab.use_variant("llvm_ad_rgb")
    from mitsuba_lab.plugins.integrators.common import equiangular
    from mitsuba_lab.scene import load_scene

    scene = load_scene("scenes/fog_shafts.xml", res=RES)
    for sampling in ("mis", "distance", "equiangular"):
        images = [render(scene, 16, s, medium_sampling=sampling)[SHAFTS] for s in SEEDS]
        print(f"{sampling}: region mean per seed {np.round([i.mean() for i in images], 4)}, "
              f"brightest pixel per seed {np.round([i.max() for i in images], 3)}")
    original = equiangular.equiangular_scatter
    for depth in (2, 3, 16):
        equiangular.equiangular_scatter = original
        full = render(scene, depth, SEEDS[0])
        equiangular.equiangular_scatter = lambda *a, **k: 0.0 * original(*a, **k)
        rest = render(scene, depth, SEEDS[0])
        r, c = np.unravel_index(np.argmax(full[SHAFTS]), full[SHAFTS].shape)
        r, c = r + SHAFTS[0].start, c + SHAFTS[1].start
        print(f"max_depth {depth}, seed {SEEDS[0]}: brightest pixel {(int(r), int(c))} {full[r, c]:.3f}, of which "
              f"equi-angular {full[r, c] - rest[r, c]:.3f}; region mean {full[SHAFTS].mean():.4f}, of which "
              f"equi-angular {(full - rest)[SHAFTS].mean():.4f}")
    equiangular.equiangular_scatter = original


if __name__ == "__main__":
    main()
