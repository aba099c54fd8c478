"""Divergence flags on constructed runs."""

from __future__ import annotations

import numpy as np

from fkn_bench.metrics import DEFAULT_GROWTH_FLOORS, DivergenceFlags, error_growth, nees_high, window_rms


def _groups(values: np.ndarray) -> dict[str, np.ndarray]:
    return {g: values.copy() for g in ("attitude", "position", "omega", "velocity")}


def test_window_rms() -> None:
    x = np.array([[3.0, 4.0, 0.0, 0.0]])
    assert window_rms(x, 0, 2)[0] == np.sqrt(12.5)


def test_decaying_error_is_not_growth() -> None:
    decaying = np.linspace(5.0, 0.1, 300)[None]
    assert not error_growth(_groups(decaying), initial_steps=50, final_steps=50).any()


def test_growing_error_above_the_floor_is_growth() -> None:
    growing = np.linspace(0.1, 100.0, 300)[None]
    assert error_growth(_groups(growing), initial_steps=50, final_steps=50).all()


def test_growth_below_the_floor_is_ignored() -> None:
    magnitudes = _groups(np.zeros((1, 300)))
    magnitudes["velocity"] = np.linspace(0.0, 0.5 * DEFAULT_GROWTH_FLOORS["velocity"], 300)[None]
    assert not error_growth(magnitudes, initial_steps=50, final_steps=50).any()
    magnitudes["velocity"] = np.linspace(0.0, 3.0 * DEFAULT_GROWTH_FLOORS["velocity"], 300)[None]
    assert error_growth(magnitudes, initial_steps=50, final_steps=50).all()


def test_nan_error_is_growth() -> None:
    values = np.ones((1, 100))
    values[0, -1] = np.nan
    assert error_growth(_groups(values), initial_steps=10, final_steps=10).all()


def test_nees_high_needs_every_final_step() -> None:
    nees = np.full((3, 100), 40.0)  # above chi2(12) 99.9% = 32.9
    nees[1, -5] = 10.0  # dips once inside the final window
    nees[2, -5] = np.nan  # no value once
    assert nees_high(nees, final_steps=20).tolist() == [True, False, False]
    assert not nees_high(np.full((1, 100), 12.0), final_steps=20).any()


def test_flags_union() -> None:
    f = np.array([False, False, False, False, True])
    flags = DivergenceFlags(f.copy(), np.roll(f, 1), np.roll(f, 2), np.roll(f, 3))
    assert flags.diverged.tolist() == [True, True, True, False, True]
    assert set(flags.as_dict()) == {"non_finite", "cholesky_failed", "error_growth", "nees_high", "diverged"}
