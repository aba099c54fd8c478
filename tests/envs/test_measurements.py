"""Measurement statistics: noise levels, schedule, dropout, bursts, outliers and sign flips.

Tolerances are about four standard errors of the estimated quantity (the seeds are fixed, so
the results are deterministic; the margins only guard against a legitimate change of streams).
"""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.envs import generate_episodes
from fkn_bench.envs.measurements import STREAMS, stream
from fkn_bench.geometry import quaternion as quat
from fkn_bench.scenarios import get_scenario

SEEDS = [0, 1, 2]
N_STEPS = 20_000


def _dense(**overrides):
    """ds1 with a measurement at every step (60000 samples over SEEDS)."""
    scenario = get_scenario("ds1", measurement_every=1, n_steps=N_STEPS, **overrides)
    return generate_episodes(scenario, SEEDS)


def _errors(episodes) -> tuple[np.ndarray, np.ndarray]:
    """Attitude error rotation vectors and position errors of the valid measurements."""
    valid = episodes.valid
    meas, truth = episodes.measurements[valid], episodes.truth[valid]
    return quat.error_rotation_vector(meas[:, :4], truth[:, :4]), meas[:, 4:] - truth[:, 4:7]


def _missing_runs(valid_row: np.ndarray) -> list[tuple[int, int]]:
    """``(start, length)`` of each maximal run of missing steps."""
    padded = np.concatenate([[False], ~valid_row, [False]]).astype(np.int8)
    edges = np.diff(padded)
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return list(zip(starts.tolist(), (stops - starts).tolist()))


@pytest.fixture(scope="module")
def clean():
    return _dense()


@pytest.mark.parametrize("noise_scale", [1.0, 5.0])
def test_noise_levels(noise_scale: float) -> None:
    episodes = _dense(noise_scale=noise_scale)
    assert episodes.valid.all()
    e, r = _errors(episodes)
    n = len(r)
    assert n == len(SEEDS) * N_STEPS
    sigma_r, sigma_q = 0.1 * noise_scale, 0.1 * noise_scale
    # per-axis standard deviation: standard error sigma / sqrt(2n) ~ 0.3%
    np.testing.assert_allclose(np.std(r, axis=0), sigma_r, rtol=0.012)
    np.testing.assert_allclose(np.std(e, axis=0), sigma_q, rtol=0.012)
    np.testing.assert_allclose(np.mean(r, axis=0), 0.0, atol=4 * sigma_r / np.sqrt(n))
    np.testing.assert_allclose(np.mean(e, axis=0), 0.0, atol=4 * sigma_q / np.sqrt(n))
    # independent axes
    for x in (r, e):
        corr = np.corrcoef(x.T)
        assert np.max(np.abs(corr - np.eye(3))) < 0.02
    # the error angle |e| of e ~ N(0, s^2 I3) is Maxwell distributed: mean 2 s sqrt(2 / pi)
    angle = np.linalg.norm(e, axis=1)
    assert np.mean(angle) == pytest.approx(2 * sigma_q * np.sqrt(2 / np.pi), rel=0.01)
    # measured quaternions are unit
    np.testing.assert_allclose(np.linalg.norm(episodes.measurements[..., :4], axis=-1), 1.0, atol=1e-15)


def test_noise_is_white_in_time(clean) -> None:
    e, r = _errors(clean)
    for x in (r[:N_STEPS], e[:N_STEPS]):  # one episode
        lag1 = np.sum(x[1:] * x[:-1], axis=0) / np.sum(x * x, axis=0)
        assert np.max(np.abs(lag1)) < 4 / np.sqrt(N_STEPS)


def test_noise_is_world_frame_error_rotation(clean) -> None:
    """``q_meas = exp(e / 2) (x) q_true`` with e the scaled standard-normal draws of the
    attitude-noise stream (one per scheduled step)."""
    e, r = _errors(clean)
    first = stream(0, "attitude_noise", 0).standard_normal((4096, 3))
    np.testing.assert_allclose(e[:4096], 0.1 * first, atol=1e-14)
    np.testing.assert_allclose(r[:4096], 0.1 * stream(0, "position_noise", 0).standard_normal((4096, 3)), atol=1e-13)


def test_noise_scale_scales_both_with_common_draws(clean) -> None:
    e1, r1 = _errors(clean)
    e5, r5 = _errors(_dense(noise_scale=5.0))
    np.testing.assert_allclose(r5, 5.0 * r1, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(e5, 5.0 * e1, rtol=1e-9, atol=1e-13)
    e0, r0 = _errors(_dense(noise_scale=0.0))
    np.testing.assert_array_equal(r0, 0.0)  # exact: noise 0 * draw = 0 is added
    np.testing.assert_allclose(e0, 0.0, atol=1e-15)


def test_sigma_fields_scale_independently(clean) -> None:
    e1, r1 = _errors(clean)
    e, r = _errors(_dense(sigma_position=0.3, sigma_attitude=0.02))
    np.testing.assert_allclose(r, 3.0 * r1, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(e, 0.2 * e1, rtol=1e-9, atol=1e-13)


@pytest.mark.parametrize("every", [1, 3, 10, 100, 4097])
def test_measurement_schedule(every: int) -> None:
    episodes = generate_episodes(get_scenario("ds1", measurement_every=every, n_steps=9000), [0, 1])
    expected = np.arange(9000) % every == 0
    np.testing.assert_array_equal(episodes.valid, np.broadcast_to(expected, (2, 9000)))
    assert np.isnan(episodes.measurements[:, ~expected]).all()
    assert np.isfinite(episodes.measurements[:, expected]).all()


@pytest.mark.parametrize("name", ["ds1", "ds1-gap100", "ds1-dropout", "ds1-flips", "tumble-fast"])
def test_missing_measurements_are_nan_rows(name: str) -> None:
    episodes = generate_episodes(get_scenario(name, n_steps=3000), [0, 1])
    valid, meas = episodes.valid, episodes.measurements
    assert valid.dtype == bool and valid.shape == (2, 3000) and meas.shape == (2, 3000, 7)
    assert np.isnan(meas[~valid]).all()
    assert np.isfinite(meas[valid]).all()
    assert valid.any() and not valid.all()


def test_dropout_fraction_and_independence(clean) -> None:
    dropped = _dense(dropout=0.2)
    n = dropped.valid.size
    assert np.mean(dropped.valid) == pytest.approx(0.8, abs=4 * np.sqrt(0.16 / n))
    # a surviving measurement has the value it would have had without dropout (exact: common random
    # numbers, the same arithmetic; masks are booleans)
    np.testing.assert_array_equal(dropped.measurements[dropped.valid], clean.measurements[dropped.valid])
    np.testing.assert_array_equal(dropped.truth, clean.truth)
    # dropout applies on top of the schedule
    sparse = generate_episodes(get_scenario("ds1", dropout=0.2, n_steps=16000), [0, 1, 2, 3])
    scheduled = np.arange(16000) % 10 == 0
    assert not sparse.valid[:, ~scheduled].any()
    assert np.mean(sparse.valid[:, scheduled]) == pytest.approx(0.8, abs=4 * np.sqrt(0.16 / 6400))


def test_burst_gaps() -> None:
    rate, length = 0.002, 50
    scenario = get_scenario("ds1", measurement_every=1, n_steps=100_000, burst_rate=rate, burst_length=length)
    episodes = generate_episodes(scenario, [0, 1, 2, 3])
    runs = [run for row in episodes.valid for run in _missing_runs(row)]
    # every gap lasts at least burst_length steps (only the episode end may cut one short)
    assert all(n >= length or start + n == 100_000 for start, n in runs)
    # a lone burst (no other start within it) is exactly burst_length long: the most common case
    complete = [n for start, n in runs if start + n < 100_000]
    assert min(complete) == length
    assert np.bincount(complete).argmax() == length
    # a gap begins where a burst starts with no start in the L steps before: rate (1 - rate)^L
    expected_runs = episodes.valid.size * rate * (1 - rate) ** length
    assert len(runs) == pytest.approx(expected_runs, abs=4 * np.sqrt(expected_runs))
    missing = 1 - np.mean(episodes.valid)
    assert missing == pytest.approx(1 - (1 - rate) ** length, rel=0.15)
    # gap lengths: L plus the overlap of further starts; mean L + ~L^2 rate / 2 for small rate
    lengths = np.array([n for _, n in runs])
    assert np.mean(lengths) == pytest.approx(missing * episodes.valid.size / len(runs))
    assert length <= np.mean(lengths) < length * 1.2


def test_ds1_dropout_measurement_fraction() -> None:
    episodes = generate_episodes("ds1-dropout", [0, 1, 2, 3])
    expected = 0.1 * 0.8 * (1 - 0.002) ** 50
    assert np.mean(episodes.valid) == pytest.approx(expected, rel=0.08)
    scheduled = np.arange(16000) % 10 == 0
    assert not episodes.valid[:, ~scheduled].any()


def test_sign_flips_change_only_the_sign(clean) -> None:
    flipped = _dense(sign_flip_probability=0.3)
    # exact: common random numbers; the flips only negate quaternions
    np.testing.assert_array_equal(flipped.valid, clean.valid)
    np.testing.assert_array_equal(flipped.truth, clean.truth)
    np.testing.assert_array_equal(flipped.measurements[..., 4:], clean.measurements[..., 4:])
    q, q_clean = flipped.measurements[..., :4], clean.measurements[..., :4]
    same = np.all(q == q_clean, axis=-1)
    negated = np.all(q == -q_clean, axis=-1)
    assert np.all(same ^ negated)
    assert np.mean(negated) == pytest.approx(0.3, abs=4 * np.sqrt(0.21 / negated.size))


def test_all_flipped() -> None:
    a = generate_episodes(get_scenario("ds1", n_steps=500), [0])
    b = generate_episodes(get_scenario("ds1", n_steps=500, sign_flip_probability=1.0), [0])
    # exact: common random numbers, the flip is a negation
    np.testing.assert_array_equal(b.measurements[..., :4], -a.measurements[..., :4])


def test_outliers(clean) -> None:
    fraction = 0.05
    noisy = _dense(outlier_fraction=fraction, outlier_position_sigma=2.0)
    np.testing.assert_array_equal(noisy.valid, clean.valid)
    changed = np.any(noisy.measurements != clean.measurements, axis=-1)
    n = changed.size
    assert np.mean(changed) == pytest.approx(fraction, abs=4 * np.sqrt(fraction * (1 - fraction) / n))
    # both parts of an outlier change: a uniformly random attitude and a position offset
    q_out, q_true = noisy.measurements[changed][:, :4], noisy.truth[changed][:, :4]
    angle = quat.angle_between(q_true, q_out)
    assert np.mean(angle) == pytest.approx(np.pi / 2 + 2 / np.pi, abs=0.06)  # uniform rotations
    offset = noisy.measurements[changed][:, 4:] - clean.measurements[changed][:, 4:]
    np.testing.assert_allclose(np.std(offset, axis=0), 2.0, rtol=0.08)
    assert np.all(np.abs(offset) > 0)
    np.testing.assert_allclose(np.linalg.norm(q_out, axis=1), 1.0, atol=1e-15)


def test_outliers_only_among_surviving_measurements() -> None:
    base = _dense(dropout=0.5)
    noisy = _dense(dropout=0.5, outlier_fraction=0.1)
    np.testing.assert_array_equal(noisy.valid, base.valid)
    changed = np.any(noisy.measurements[noisy.valid] != base.measurements[base.valid], axis=-1)
    assert np.mean(changed) == pytest.approx(0.1, abs=4 * np.sqrt(0.09 / changed.size))


def test_ds1_flips_scenario() -> None:
    flips = generate_episodes("ds1-flips", [0, 1])
    ds1 = generate_episodes("ds1", [0, 1])
    np.testing.assert_array_equal(flips.valid, ds1.valid)
    v = ds1.valid
    q, q_ds1 = flips.measurements[v][:, :4], ds1.measurements[v][:, :4]
    outlier = np.any(flips.measurements[v][:, 4:] != ds1.measurements[v][:, 4:], axis=-1)
    assert 0.0 < np.mean(outlier) < 0.025  # 1% of 3200
    negated = np.all(q == -q_ds1, axis=-1)
    assert np.mean(negated[~outlier]) == pytest.approx(0.5, abs=0.04)
    assert np.all(negated[~outlier] | np.all(q == q_ds1, axis=-1)[~outlier])


def test_streams() -> None:
    a = stream(3, "dropout", 0).random(5)
    # exact: a seeded numpy Generator gives the same bits on any CPU
    np.testing.assert_array_equal(a, stream(3, "dropout", 0).random(5))
    assert not np.array_equal(a, stream(4, "dropout", 0).random(5))
    assert not np.array_equal(a, stream(3, "burst", 0).random(5))
    assert not np.array_equal(a, stream(3, "dropout", 1).random(5))
    assert len(set(STREAMS)) == len(STREAMS)
    stream(np.int64(2), "dropout")
    for bad in (-1, True, 1.5, "0"):
        with pytest.raises(ValueError, match="non-negative integer"):
            stream(bad, "dropout")  # type: ignore[arg-type]
