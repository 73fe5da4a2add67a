"""The full matrix of tests/plugins/test_media_block.py: every scene (FILE_SCENES and
USER_SCENES) in the rgb, mono and spectral variants of the run's backend, every estimator of
CONFIGS that is distinct on the scene, and Mitsuba's ``volpath``, each against ``volpathmis``
(block test: 6x6-pixel block means, Welch z, Sidak alpha 0.01) at SEEDS renders a side: 64 in
rgb, 32 in mono and spectral (what a 2-core machine shared with others affords in an hour).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_media_block_matrix.py

Prints one Markdown row per case (scene, variant, renders a side, estimator and the ones it
stands for, worst |z|, the bound, blocks past it, pixel problems); recorded in
experiments/results/2026-11-28-media-block.md.
"""
import time

import pytest

import backend
import mitsuba_lab
from test_media_block import FILE_SCENES, MITSUBA, USER_SCENES, check, distinct_configs

SEEDS = {"ad_rgb": 64, "ad_mono": 32, "ad_spectral": 32}


@pytest.mark.parametrize("name", FILE_SCENES + USER_SCENES)
@pytest.mark.parametrize("kind", ["ad_rgb", "ad_mono", "ad_spectral"])
def test_every_medium_mode_passes_the_block_test(kind, name):
    mitsuba_lab.use_variant(backend.variant(kind))
    failures = []
    seeds_lab, seeds_ref = range(SEEDS[kind]), range(1000, 1000 + SEEDS[kind])
    try:
        cases = {**distinct_configs(name), **{m: [m] for m in MITSUBA}}
        for config, twins in cases.items():
            start = time.process_time()
            result, problem = check(name, config, seeds_lab, seeds_ref)
            print(f"| {name} | {kind} | {SEEDS[kind]} | {' = '.join(twins)} | {result.max_abs_z:.2f} | {result.bound:.2f} | "
                  f"{len(result.failing)} of {result.z.size} | {problem or 'none'} | "
                  f"{time.process_time() - start:.0f} |", flush=True)
            if result.failing or problem:
                failures.append(f"{config}: {result.summary()} {problem}")
    finally:
        mitsuba_lab.use_variant(backend.HOME)
    assert not failures, f"{name} {kind}: " + "; ".join(failures)
