"""KalmanEstimator: batch vs online, adversarial inputs, accuracy on ds1, configuration and
persistence."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import fkn_bench  # noqa: F401  (registers AstrobeeTumble-v0)
from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import Estimate, EstimatorFileError, KalmanEstimator, load_estimator, make_estimator
from fkn_bench.estimators.conformance import HostileInput, check_input_rules, hostile_measurements
from fkn_bench.filters.pose import error_covariance_from_state, state_covariance_from_error
from fkn_bench.geometry.quaternion import align_sign, angle_between
from fkn_bench.scenarios import get_scenario
from fkn_bench.types import STATE_NAMES

DT = 0.1
ONLINE = ("manual-ekf", "manual-ukf", "manual-mekf", "oracle-ekf")


@pytest.fixture(scope="module")
def hostile_input() -> HostileInput:
    """Two 250-step ds1-flips sequences (sign flips, 1% outliers) from the test split, made
    worse: NaN and inf inside the mask, a zero and non-unit quaternions, garbage outside the
    mask (:func:`~fkn_bench.estimators.conformance.hostile_measurements`)."""
    return hostile_measurements(seeds=(0, 1), steps=250, late_start=None)


@pytest.fixture(scope="module")
def hostile(hostile_input: HostileInput) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measurements, mask and times of :func:`hostile_input`."""
    return hostile_input.measurements, hostile_input.mask, hostile_input.times


def _as_observation(kind: str, z: np.ndarray, valid: bool, time: float):  # noqa: ANN202
    if kind == "dict":
        return {"pose": z.copy(), "valid": np.int64(valid), "time": np.array(time)}
    if kind == "dict-no-time":
        return {"pose": z.copy(), "valid": int(valid)}
    return z.copy() if valid else np.full(7, np.nan)  # (7,) array, NaN when missing


# ---------------------------------------------------------------------------- online vs batch
@pytest.mark.parametrize("name", ONLINE)
def test_online_steps_equal_batch_estimates(name: str, hostile) -> None:
    """reset()/step() and estimate() give the same means to 1e-12 for every built-in filter
    (the UKF too: online it runs the same torch code one row at a time, and the only difference
    is summation order in batched products, measured at ~1e-14)."""
    z, mask, times = hostile
    estimator = make_estimator(name, scenario=get_scenario("ds1-flips"))
    batch = estimator.estimate(z, mask, DT)
    assert np.isfinite(batch.means).all()
    cheap = name in ("manual-ekf", "oracle-ekf")  # the numpy online EKF: both forms for both rows
    for b in range(z.shape[0]):
        for kind in ("dict", "array") if cheap else (("dict", "array")[b],):
            estimator.reset(dt=DT)
            for t in range(z.shape[1]):
                estimate = estimator.step(_as_observation(kind, z[b, t], mask[b, t], times[t]))
                np.testing.assert_allclose(estimate.mean, batch.means[b, t], rtol=0, atol=1e-12, err_msg=f"{name} {kind} b={b} t={t}")
                assert estimate.initialised == batch.initialised[b, t]
                assert estimate.updated == batch.innovation_mask[b, t]
                native = batch.error_covariances if estimator.filter.covariance_dim == 12 else batch.covariances
                np.testing.assert_allclose(estimate.native_covariance, native[b, t], rtol=0, atol=1e-12)
                if kind == "dict":
                    assert estimate.time == pytest.approx(times[t])


def test_online_without_times_counts_steps(hostile) -> None:
    z, mask, _ = hostile
    estimator = make_estimator("manual-ekf")
    batch = estimator.estimate(z[:1], mask[:1], DT)
    estimator.reset(dt=DT)
    for t in range(z.shape[1]):
        estimate = estimator.step(_as_observation("dict-no-time", z[0, t], mask[0, t], 0.0))
        assert estimate.time == pytest.approx(t * DT)
        np.testing.assert_allclose(estimate.mean, batch.means[0, t], rtol=0, atol=1e-12)


def test_online_in_the_gymnasium_loop() -> None:
    """The documented loop: env.step(estimate.mean) with the environment's own observations
    gives the batch estimates of the same episode."""
    scenario = get_scenario("ds1-flips", n_steps=300)
    env = gym.make("AstrobeeTumble-v0", scenario=scenario)
    estimator = make_estimator("manual-ekf")
    episodes = generate_episodes(scenario, [11])
    batch = estimator.estimate(episodes.measurements, episodes.valid, scenario.dt)
    observation, _ = env.reset(seed=11)
    estimator.reset(dt=scenario.dt)
    for t in range(scenario.n_steps):
        estimate = estimator.step(observation)
        np.testing.assert_allclose(estimate.mean, batch.means[0, t], rtol=0, atol=1e-12)
        if t == scenario.n_steps - 1:
            break
        observation, reward, terminated, truncated, _ = env.step(estimate.mean)
        assert np.isfinite(reward)
    env.close()


def test_estimate_values_and_conversions(hostile) -> None:
    z, mask, times = hostile
    for name in ("manual-ekf", "manual-mekf"):
        estimator = make_estimator(name)
        batch = estimator.estimate(z, mask, DT)
        B, T = mask.shape
        assert batch.means.shape == (B, T, 13) and batch.covariances.shape == (B, T, 13, 13)
        assert batch.error_covariances.shape == (B, T, 12, 12)
        assert batch.innovations.shape == (B, T, 6) and batch.innovation_covariances.shape == (B, T, 6, 6)
        q = batch.means[..., :4]
        # exact: estimate() converted with this very function on the same arrays (same computation twice)
        if name == "manual-ekf":
            np.testing.assert_allclose(batch.error_covariances, error_covariance_from_state(q, batch.covariances), rtol=0, atol=0)
        else:
            np.testing.assert_allclose(batch.covariances, state_covariance_from_error(q, batch.error_covariances), rtol=0, atol=0)
        estimator.reset(dt=DT)
        for t in range(40):
            estimate = estimator.step(_as_observation("dict", z[0, t], mask[0, t], times[t]))
        assert isinstance(estimate, Estimate)
        np.testing.assert_allclose(estimate.covariance, batch.covariances[0, 39], rtol=0, atol=1e-12)
        np.testing.assert_allclose(estimate.error_covariance, batch.error_covariances[0, 39], rtol=0, atol=1e-12)
        for array in (estimate.mean, estimate.native_covariance):
            with pytest.raises(ValueError, match="read-only"):
                array[...] = 0.0
        # the estimator keeps its own copy: the next step is not affected by the returned arrays
        following = estimator.step(_as_observation("dict", z[0, 40], mask[0, 40], times[40]))
        np.testing.assert_allclose(following.mean, batch.means[0, 40], rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------- adversarial input
@pytest.mark.parametrize("name", ["manual-ekf", "manual-ukf", "manual-mekf"])
def test_adversarial_batch_input(name: str, hostile_input: HostileInput) -> None:
    """NaN/inf/zero-norm quaternions inside the mask are skipped (documented rule), quaternions are
    renormalised, sign flips at every step change only the estimate's sign, outputs are finite."""
    check_input_rules(make_estimator(name), hostile_input, atol=1e-12)


@pytest.mark.parametrize("name", ["manual-ekf", "manual-ukf", "manual-mekf"])
def test_gross_outliers_give_finite_output(name: str, hostile) -> None:
    """1e6 outliers (position, quaternion, both signs) go in and the output stays finite. (The
    UKF then carries ~1e5 m in its state: its sigma-point sums round at ~1e-11 and the results
    are no longer reproducible to 1e-12 under bit-level changes such as sign flips.)"""
    z, mask, _ = hostile
    z = z.copy()
    steps = np.flatnonzero(mask[1])
    z[1, steps[5], 4:7] = 1e6
    z[1, steps[7], :4] = [1e6, -1e6, 1.0, 0.0]
    z[1, steps[9]] = -1e6
    estimator = make_estimator(name)
    result = estimator.estimate(z, mask, DT)
    for array in (result.means, result.covariances, result.error_covariances, result.innovations, result.innovation_covariances):
        assert np.isfinite(array).all()
    assert result.innovation_mask[1, steps[[5, 7, 9]]].all()
    assert np.abs(result.means[1, steps[5], 4:7]).max() > 1e4
    clean = estimator.estimate(hostile[0], mask, DT)
    np.testing.assert_allclose(result.means[0], clean.means[0], rtol=0, atol=1e-12)  # the other row is untouched


def test_adversarial_inputs_are_refused_with_clear_messages() -> None:
    estimator = make_estimator("manual-ekf")
    z = np.zeros((1, 5, 7))
    z[..., 0] = 1.0
    mask = np.ones((1, 5), bool)
    with pytest.raises(ValueError, match="no sequences or no time steps"):
        estimator.estimate(z[:, :0], mask[:, :0], DT)
    with pytest.raises(ValueError, match="use measurements\\[None\\] for a single sequence"):
        estimator.estimate(z[0], mask[0], DT)
    with pytest.raises(ValueError, match=r"mask must have shape \(1, 5\)"):
        estimator.estimate(z, mask[:, :3], DT)
    for dt in (0.0, -DT, np.nan, np.inf, "0.1 s", None):
        with pytest.raises(ValueError, match="dt must be"):
            estimator.estimate(z, mask, dt)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="dt must be"):
            estimator.reset(dt=dt)  # type: ignore[arg-type]
    fresh = make_estimator("manual-ukf")
    with pytest.raises(RuntimeError, match=r"call reset\(dt=...\) before step\(\)"):
        fresh.step(np.full(7, np.nan))
    estimator.reset(dt=DT)
    estimator.step({"pose": z[0, 0], "valid": 1, "time": 5.0})
    with pytest.raises(ValueError, match="observation time 5.0 does not increase"):
        estimator.step({"pose": z[0, 1], "valid": 1, "time": 5.0})
    with pytest.raises(ValueError, match=r"shape \(7,\)"):
        estimator.step(np.zeros(6))


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize("name", ["manual-ekf", "manual-ukf", "manual-mekf"])
def test_online_adversarial_observations_stay_finite(name: str) -> None:
    episodes = generate_episodes("ds1", [4], split="test").window(0, 120)
    estimator = make_estimator(name)
    estimator.reset(dt=DT)
    rng = np.random.default_rng(0)
    hostile = [np.full(7, np.nan), np.array([np.nan] + [0.0] * 6), np.array([0.0] * 4 + [1.0] * 3), np.full(7, 1e6), np.full(7, -1e6), np.array([1e160] * 4 + [0.0] * 3)]
    for t in range(episodes.n_steps):
        if episodes.valid[0, t]:
            z = episodes.measurements[0, t] * (-1.0 if t % 20 else 1.0)
        else:
            z = hostile[rng.integers(len(hostile))]
        estimate = estimator.step({"pose": z, "valid": 1, "time": episodes.times[t]})
        assert np.isfinite(estimate.mean).all() and np.isfinite(estimate.native_covariance).all()
    assert np.linalg.norm(estimate.mean[:4]) == pytest.approx(1.0, abs=0.05)


# ---------------------------------------------------------------------------- accuracy on ds1
def test_manual_ekf_beats_the_measurements_on_ds1() -> None:
    """ds1 test split, 20 episodes, a measurement every 10 steps, scored from step 100 on."""
    episodes = generate_episodes("ds1", 20, split="test")
    estimates = make_estimator("manual-ekf").estimate(episodes.measurements, episodes.valid, DT)
    scored = slice(100, None)
    truth, means = episodes.truth[:, scored], estimates.means[:, scored]
    valid = episodes.valid[:, scored]
    measured = episodes.measurements[:, scored][valid]
    attitude = np.sqrt(np.mean(angle_between(truth[..., :4], means[..., :4]) ** 2))
    attitude_measured = np.sqrt(np.mean(angle_between(truth[valid][:, :4], measured[:, :4] / np.linalg.norm(measured[:, :4], axis=1, keepdims=True)) ** 2))
    position = np.sqrt(np.mean(np.sum((truth[..., 4:7] - means[..., 4:7]) ** 2, axis=-1)))
    position_measured = np.sqrt(np.mean(np.sum((truth[valid][:, 4:7] - measured[:, 4:7]) ** 2, axis=-1)))
    # the record: per-component RMSE, quaternion sign-aligned to the truth
    aligned = means.copy()
    aligned[..., :4] = align_sign(means[..., :4], truth[..., :4])
    rmse = np.sqrt(np.mean((aligned - truth) ** 2, axis=(0, 1)))
    print("\nmanual-ekf on ds1 (test split, 20 episodes, from step 100): per-component RMSE")
    print("  ".join(f"{n}={v:.4f}" for n, v in zip(STATE_NAMES, rmse)))
    print(f"attitude {attitude:.4f} rad (measurements {attitude_measured:.4f}); position {position:.4f} m (measurements {position_measured:.4f})")
    assert attitude_measured == pytest.approx(0.1 * np.sqrt(3), rel=0.05)  # the data are what we think
    assert position_measured == pytest.approx(0.1 * np.sqrt(3), rel=0.05)
    assert attitude < 0.6 * attitude_measured
    assert position < 0.6 * position_measured
    assert rmse[7:10].max() < 0.02 and rmse[10:].max() < 0.01  # rad/s, m/s (true |w| = 0.075 rad/s)


# ---------------------------------------------------------------------------- config and persistence
def test_configuration_is_checked() -> None:
    with pytest.raises(ValueError, match="unknown filter variant 'pf'; valid variants: ekf, ukf, mekf"):
        KalmanEstimator(variant="pf")
    with pytest.raises(ValueError, match=r"q_std needs 13 values \(got shape \(12,\)\)"):
        KalmanEstimator(q_std=[0.1] * 12)
    with pytest.raises(ValueError, match=r"r_std\[6\] = 0.0 is outside"):
        KalmanEstimator(r_std=[0.1] * 6 + [0.0])
    with pytest.raises(ValueError, match=r"p0_std\[11\] = nan is outside"):
        KalmanEstimator(variant="mekf", p0_std=[0.1] * 11 + [np.nan])
    with pytest.raises(ValueError, match=r"r_std needs 6 values"):
        KalmanEstimator(variant="mekf", r_std=[0.1] * 7)
    with pytest.raises(ValueError, match=r"unknown KalmanEstimator config keys \['gain'\]"):
        KalmanEstimator.from_config({"variant": "ekf", "gain": 2.0})


@pytest.mark.parametrize("variant", ["ekf", "ukf", "mekf"])
def test_save_load_round_trip(variant: str, tmp_path: Path, hostile) -> None:
    z, mask, _ = hostile
    rng = np.random.default_rng(0)
    original = KalmanEstimator(
        variant=variant,
        q_std=(np.array(make_estimator(f"manual-{variant}").to_config()["q_std"]) * rng.uniform(0.5, 2.0, 13 if variant != "mekf" else 12)).tolist(),
        name=f"tuned-{variant}",
        description="tuned by hand",
    )
    path = original.save(tmp_path / f"{variant}.json")
    assert [p.name for p in tmp_path.iterdir()] == [f"{variant}.json"]
    loaded = load_estimator(path)
    assert isinstance(loaded, KalmanEstimator) and loaded.variant_name == variant
    assert loaded.to_config() == original.to_config()
    assert (loaded.name, loaded.description) == (f"tuned-{variant}", "tuned by hand")
    # exact: the JSON round trip of the config is lossless (float repr), then the same computation twice
    np.testing.assert_array_equal(loaded.estimate(z[:, :80], mask[:, :80], DT).means, original.estimate(z[:, :80], mask[:, :80], DT).means)
    assert KalmanEstimator.load(path).to_config() == original.to_config()
    # a hand-edited file with a bad config is refused with the file's name
    document = json.loads(path.read_text())
    document["config"]["r_std"] = [0.1] * 3
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps(document))
    with pytest.raises(EstimatorFileError, match=r"broken\.json: invalid KalmanEstimator config: r_std needs"):
        load_estimator(broken)


def test_failed_save_keeps_the_previous_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = make_estimator("manual-ekf").save(tmp_path / "estimator.json")
    before = path.read_bytes()

    def fail(self: KalmanEstimator) -> dict:
        raise RuntimeError("disk full")

    monkeypatch.setattr(KalmanEstimator, "to_config", fail)
    with pytest.raises(RuntimeError, match="disk full"):
        make_estimator("manual-mekf").save(path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["estimator.json"]
    monkeypatch.undo()
    assert load_estimator(path).to_config()["variant"] == "ekf"


def test_full_covariance_configuration(tmp_path: Path, hostile) -> None:
    z, mask, _ = hostile
    r_std = np.array([0.05] * 4 + [0.1] * 3)
    diagonal = KalmanEstimator(r_std=r_std)
    full = KalmanEstimator(r_cov=np.diag(r_std**2).tolist())
    # exact: both build R = diag(r_std**2) bit for bit (x*x correctly rounded; symmetrising a diagonal
    # matrix returns it), then run the same filter
    np.testing.assert_array_equal(full.estimate(z, mask, DT).means, diagonal.estimate(z, mask, DT).means)
    correlated = np.diag(r_std**2)
    correlated[4, 5] = correlated[5, 4] = 0.5 * 0.1 * 0.1
    estimator = KalmanEstimator(r_cov=correlated.tolist(), name="correlated")
    assert not np.allclose(estimator.estimate(z, mask, DT).means, diagonal.estimate(z, mask, DT).means)
    loaded = load_estimator(estimator.save(tmp_path / "correlated.json"))
    assert loaded.to_config() == estimator.to_config() and "r_cov" in loaded.to_config()
    np.testing.assert_array_equal(loaded.estimate(z, mask, DT).means, estimator.estimate(z, mask, DT).means)
    with pytest.raises(ValueError, match="give either r_std or r_cov, not both"):
        KalmanEstimator(r_std=r_std, r_cov=correlated.tolist())
    with pytest.raises(ValueError, match="r_cov must be positive definite"):
        KalmanEstimator(r_cov=(-correlated).tolist())
    with pytest.raises(ValueError, match=r"q_cov must be a 13x13 matrix"):
        KalmanEstimator(q_cov=np.eye(12).tolist())


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"r_std": [0.1] * 6 + [1e160]}, r"r_std\[6\] = 1e\+160 is outside \[1e-100, 1e\+06\]"),
        ({"q_std": [0.0] + [0.005] * 12}, r"q_std\[0\] = 0\.0 is outside"),
        ({"p0_std": [float("nan")] * 13}, r"p0_std\[0\] = nan is outside"),
        ({"r_std": ["a"] * 7}, r"r_std must be 7 numbers"),
        ({"r_cov": (1e13 * np.eye(7)).tolist()}, r"r_cov's eigenvalues must lie in"),
    ],
)
def test_noise_that_would_overflow_the_filter_is_refused_by_name(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        KalmanEstimator(**options)


def test_the_chi_square_gate_skips_gross_outliers_alike_in_estimate_and_step() -> None:
    """``gate=0.999`` (issue 21, item 3): a 3 m position jump at one measurement is skipped (no
    update, no pull on the state), the good measurements are used, ``step`` skips the same one;
    without a gate the jump goes in. A gate outside (0, 1) is refused, naming it."""
    episodes = generate_episodes("ds1", [0], split="test").window(0, 300)
    z, valid = episodes.measurements.copy(), episodes.valid.copy()
    jump = int(np.flatnonzero(valid[0])[20])
    z[0, jump, 4:7] += 3.0
    gated = make_estimator("manual-ekf", gate=0.999)
    plain = make_estimator("manual-ekf").estimate(z, valid, 0.1)
    batch = gated.estimate(z, valid, 0.1)
    assert plain.innovation_mask[0, jump] and not batch.innovation_mask[0, jump]
    assert batch.innovation_mask[0].sum() >= valid[0].sum() - 2  # (the first initialises; at most one good one gated)
    after = slice(jump, jump + 10)
    assert np.abs(batch.means[0, after, 4:7] - episodes.truth[0, after, 4:7]).max() < 0.15
    assert np.abs(plain.means[0, after, 4:7] - episodes.truth[0, after, 4:7]).max() > 0.25  # pulled by the jump
    gated.reset(dt=0.1)
    for t in range(z.shape[1]):
        estimate = gated.step(z[0, t] if valid[0, t] else np.full(7, np.nan))
        assert estimate.updated == batch.innovation_mask[0, t], t
        np.testing.assert_allclose(estimate.mean, batch.means[0, t], rtol=0, atol=1e-10)
    assert gated.to_config()["gate"] == 0.999 and KalmanEstimator.from_config(gated.to_config()).filter.gate == 0.999
    for bad in (0.0, 1.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="gate must be a probability in"):
            make_estimator("manual-ekf", gate=bad)
