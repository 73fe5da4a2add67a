"""Power proof that left tests/plugins/test_aim.py (38 CPU s; the suite keeps the 10%-off
density against the mean check, which renders nothing): same code, prints its z (recorded in
experiments/results/2026-11-28-power-proofs.md).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/power/test_aim_power.py
"""
import math
import tomllib

import mitsuba as mi
import numpy as np

from agreement import Z_BOUND, scene_path
from mitsuba_lab.scene import load_scene, make_integrator
from test_aim import MAX_DEPTH, aim_class


def caustic_floor_means(scene, params, seeds, spp=64):
    """Region ``caustic_floor``'s mean (caustic.regions.toml, res 64) of lab_bdpt, per seed."""
    box = tomllib.load(open(scene_path("caustic.regions.toml"), "rb"))["regions"]["caustic_floor"]
    xs, ys = slice(round(box[0] * 64), round(box[2] * 64)), slice(round(box[1] * 64), round(box[3] * 64))
    integrator = make_integrator("lab_bdpt", {"max_depth": MAX_DEPTH, **params})
    return np.array([np.array(mi.render(scene, integrator=integrator, spp=spp, seed=s))[ys, xs].mean()
                     for s in seeds])


def test_a_wrong_aimed_density_is_caught(monkeypatch):
    """On the caustic's floor, lit by light subpaths through the glass: aimed and not, the same
    mean (|z| <= 5; 4 seeds of 256 spp without, 8 of 128 with: few renders of many samples,
    as each render's fixed cost dominates); the aimed part of the density 10% too large, in the
    weights and the MIS, darkens it by ~9%: |z| > 10 (power). The side without aim adds little
    of the variance: at 1024 spp (two thirds of the test's time) z was +1.89 and -20.26, at 256
    +2.44 and -19.5."""
    scene = load_scene(scene_path("caustic.xml"), res=64)
    plain = caustic_floor_means(scene, {}, range(1000, 1004), spp=256)

    def z(values):
        return (values.mean() - plain.mean()) / math.sqrt(values.var(ddof=1) / len(values) + plain.var(ddof=1) / len(plain))

    right = z(caustic_floor_means(scene, {"aim": 0.5}, range(8), spp=128))
    correct = aim_class()._aimed_pdf
    monkeypatch.setattr(aim_class(), "_aimed_pdf", lambda self, y, d: 1.1 * correct(self, y, d))
    wrong = z(caustic_floor_means(scene, {"aim": 0.5}, range(8), spp=128))
    print(f"caustic floor, aimed against not: z {right:+.2f}; aimed density x 1.1: z {wrong:+.1f}")
    assert abs(right) <= Z_BOUND and abs(wrong) > 2 * Z_BOUND
