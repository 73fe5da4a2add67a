"""Tests of mitsuba_lab.experiment.report.spectrum: error spectra and MSE-vs-spp slopes.

Synthetic images with known spectra, fixed seeds; tolerances stated per test.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from mitsuba_lab.experiment.report.spectrum import (
    bright_mask, low_frequency_fraction, mse_slope, plot_error_spectra, radial_power_spectrum,
    rows_below_bright, slope_table, spectrum_rows)

N = 256


def white(seed=0, n=N, channels=None):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, n) if channels is None else (n, n, channels))


def box_blur(e):
    """3x3 periodic box filter: low-pass (red) noise."""
    return sum(np.roll(np.roll(e, dy, 0), dx, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 9


def laplacian(e):
    """Periodic discrete Laplacian: high-pass (blue) noise, no power at DC."""
    return 4 * e - np.roll(e, 1, 0) - np.roll(e, -1, 0) - np.roll(e, 1, 1) - np.roll(e, -1, 1)


def test_white_noise_spectrum_is_flat_at_the_variance():
    """Parseval: each bin ~ s^2 = 4. Mean of 8 seeds; bins from 16 on hold >= 100
    frequencies (~5% noise per bin): 25% per bin, 3% over all bins."""
    spectra = [radial_power_spectrum(2.0 * white(s)) for s in range(8)]
    freq, power = spectra[0][0], np.mean([p for _, p in spectra], axis=0)
    assert freq.shape == power.shape == (N // 2,)
    assert 0 < freq[0] < freq[-1] <= 0.5
    assert np.all(np.abs(power[16:] / 4.0 - 1) < 0.25)
    assert abs(np.mean(power) / 4.0 - 1) < 0.03


def test_channels_are_averaged_first():
    e = white(2, channels=3)
    np.testing.assert_allclose(radial_power_spectrum(e)[1], radial_power_spectrum(e.mean(-1))[1])


def test_a_single_frequency_lands_in_its_bin():
    y, x = np.indices((N, N))
    wave = np.cos(2 * np.pi * 32 * x / N)           # 32 / 256 = 0.125 cycles per pixel
    freq, power = radial_power_spectrum(wave)
    assert abs(freq[np.nanargmax(power)] - 0.125) <= 0.5 / len(freq)
    assert low_frequency_fraction(wave, cutoff=0.26) == pytest.approx(1.0)
    assert low_frequency_fraction(wave, cutoff=0.24) == pytest.approx(0.0, abs=1e-12)


def test_low_frequency_fraction_white_red_blue():
    """White: about cutoff^2 = 1/16 (area share; ~3000 frequencies, 15%); a Laplacian
    (blue) has far less, a box blur (red) far more; 8 seeds."""
    fw = [low_frequency_fraction(white(s)) for s in range(8)]
    assert abs(np.mean(fw) / (1 / 16) - 1) < 0.15
    assert all(low_frequency_fraction(laplacian(white(s))) < 0.2 / 16 for s in range(8))
    assert all(low_frequency_fraction(box_blur(white(s))) > 2.5 / 16 for s in range(8))
    assert np.isnan(low_frequency_fraction(np.ones((8, 8))))
    with pytest.raises(ValueError, match="cutoff"):
        low_frequency_fraction(white(0), cutoff=0)
    with pytest.raises(ValueError, match="shape"):
        low_frequency_fraction(np.zeros(5))


def test_mse_slope():
    spp = np.array([4, 16, 64, 256])
    assert mse_slope(spp, 3.0 * spp ** -1.5) == pytest.approx(-1.5, abs=1e-12)
    assert mse_slope(spp, 0.2 / spp) == pytest.approx(-1.0, abs=1e-12)
    for bad_spp, bad_mse in (([4, 4], [1.0, 0.5]), ([4, 16], [1.0, 0.0]), ([4, 16], [1.0])):
        with pytest.raises(ValueError):
            mse_slope(bad_spp, bad_mse)


def _point(spp, mse, images=(), budget=None):
    return SimpleNamespace(spp=spp, mse_corrected=mse, images=list(images), budget_s=budget)


def test_slope_table_and_spectrum_plot(tmp_path):
    ref = np.zeros((32, 32, 3))
    noise = {"a.exr": white(3, n=32, channels=3), "b.exr": laplacian(white(4, n=32))[..., None] * np.ones(3)}
    groups = {
        ("mis", "independent"): [_point(4, 1.0, ["a.exr"]), _point(16, 0.25), _point(64, 1 / 16)],
        ("mis", "lab_zsobol"): [_point(4, 0.5, ["b.exr"]), _point(16, 0.5 / 8),
                                _point(32, 0.01, budget=0.5)],          # a time-budget point: ignored
        ("mis", "one_point"): [_point(4, 1.0)],                        # too few points: no row
    }
    label = lambda key: f"{key[0]} / {key[1]}"                         # noqa: E731
    lines = slope_table(groups, label)
    table = "\n".join(lines)
    assert "| mis / independent | -1.00 | 4-64 | 3 |" in table
    assert "| mis / lab_zsobol | -1.50 | 4-16 | 2 |" in table
    assert "one_point" not in table
    path = plot_error_spectra(groups, label, ref, str(tmp_path), str(tmp_path / "spectra.png"),
                              read_image=lambda p: noise[p.rsplit("/", 1)[-1]])
    assert path and (tmp_path / "spectra.png").stat().st_size > 1000
    assert slope_table({}, label) == []
    assert plot_error_spectra({}, label, ref, str(tmp_path), str(tmp_path / "none.png")) is None


def test_bright_mask_and_rows_below_bright():
    """A 2x2 'emitter' at rows 3-4: the mask grows it by one pixel each way, and the
    emitter-free rectangle starts `margin` rows below its last row."""
    ref = np.full((16, 12, 3), 0.5)
    ref[3:5, 6:8] = 17.0
    mask = bright_mask(ref, threshold=5.0)
    assert mask.sum() == 16 and mask[2:6, 5:9].all()
    assert bright_mask(ref, threshold=5.0, grow=0).sum() == 4
    assert rows_below_bright(ref, threshold=5.0, margin=2) == 7
    assert rows_below_bright(ref, threshold=50.0) == 0
    assert rows_below_bright(np.full((4, 4), 9.0), threshold=5.0) == 4


def test_spectrum_rows_skip_a_visible_emitter_only_when_half_the_image_remains():
    ref = np.full((16, 16, 3), 0.5)
    assert spectrum_rows(ref) == 0                       # nothing bright: whole image
    ref[1:3, 6:10] = 17.0                                # an emitter near the top
    assert spectrum_rows(ref) == 5                       # last bright row 2, + 1 + margin 2
    ref[12, 3] = 40.0                                    # a bright pixel low down: too few rows left
    assert spectrum_rows(ref) == 0
