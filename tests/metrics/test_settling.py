"""Settling time on constructed signals with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.metrics import DEFAULT_TOLERANCES, moving_rms, settling_band, settling_time


def test_exponential_decay_settles_at_the_analytic_time() -> None:
    dt = 0.1
    t = np.arange(1000) * dt
    error = 2.0 * np.exp(-t / 5.0)  # enters 0.1 at t = 5 ln 20 = 14.98 s
    result = settling_time(error[None], dt, tolerance=0.1)
    assert result.settled[0]
    assert result.band[0] == pytest.approx(0.1)
    assert result.time[0] == pytest.approx(5 * np.log(20), abs=dt)


def test_band_widens_to_two_percent_of_the_peak() -> None:
    error = np.concatenate([np.full(10, 100.0), np.full(90, 1.5)])[None]
    result = settling_time(error, 1.0, tolerance=1.0, peak_fraction=0.02)
    assert result.band[0] == pytest.approx(2.0)
    assert result.time[0] == 10.0


def test_inside_the_band_from_the_start_is_zero() -> None:
    result = settling_time(np.full((2, 50), 0.5), 0.1, tolerance=1.0)
    assert np.all(result.time == 0.0) and np.all(result.settled)


def test_never_settling_run_is_flagged_with_the_run_length() -> None:
    error = np.linspace(0.0, 5.0, 200)[None]  # grows out of the band
    result = settling_time(error, 0.1, tolerance=1.0)
    assert not result.settled[0]
    assert result.time[0] == pytest.approx(200 * 0.1)


def test_late_excursion_resets_settling() -> None:
    error = np.full(100, 0.1)
    error[70] = 5.0  # a single spike late in the run
    result = settling_time(error[None], 1.0, tolerance=1.0, peak_fraction=0.0)
    assert result.time[0] == 71.0


def test_smoothing_ignores_single_noisy_samples() -> None:
    rng = np.random.default_rng(0)
    error = np.abs(rng.normal(0.0, 0.3, size=(1, 2000)))
    error[0, 1500] = 2.0  # one outlier; the 100-step RMS stays well inside 1.0
    result = settling_time(error, 0.1, tolerance=1.0, window=100, peak_fraction=0.0)
    assert result.time[0] == 0.0


def test_nan_counts_as_outside() -> None:
    error = np.zeros((1, 10))
    error[0, 9] = np.nan
    result = settling_time(error, 1.0, tolerance=1.0)
    assert not result.settled[0] and result.time[0] == 10.0


def test_moving_rms_known_values() -> None:
    x = np.array([[3.0, 4.0, 0.0, 0.0]])
    assert np.allclose(moving_rms(x, 1), [3.0, 4.0, 0.0, 0.0])
    # window 3: centred, shrinking at the ends
    expected = [np.sqrt(25 / 2), np.sqrt(25 / 3), np.sqrt(16 / 3), 0.0]
    assert np.allclose(moving_rms(x, 3), expected)
    with pytest.raises(ValueError):
        moving_rms(x, 0)


def test_band_ignores_nan_peak() -> None:
    band = settling_band(np.array([[np.nan, np.nan], [1.0, 200.0]]), 1.0)
    assert band.tolist() == [1.0, 4.0]


def test_default_tolerances_cover_every_group() -> None:
    assert set(DEFAULT_TOLERANCES) == {"attitude", "position", "omega", "velocity"}
    assert all(v > 0 for v in DEFAULT_TOLERANCES.values())
