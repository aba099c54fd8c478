"""The adaptive baselines as estimators on the paper's pose-and-twist model: the shared recursion
against the manual EKF, online vs batch, hostile input, outputs, configuration and registry."""

from __future__ import annotations

import json

from pathlib import Path

import numpy as np
import pytest

from fkn_bench.baselines.adaptive import AdaptiveKalmanFilter, clamp_eigenvalues
from fkn_bench.baselines.akhlaghi import AkhlaghiEstimator, AkhlaghiRule
from fkn_bench.baselines.sage_husa import SageHusaEstimator
from fkn_bench.baselines.vbakf import VBAKFEstimator
from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import estimator_spec, load_estimator, make_estimator
from fkn_bench.estimators.conformance import HostileInput, check_input_rules, hostile_measurements
from fkn_bench.models import PoseTwistModel
from fkn_bench.filters.pose import error_covariance_from_state
from fkn_bench.scenarios import get_scenario

DT = 0.1
ADAPTIVE = ("sage-husa", "akhlaghi", "vbakf")


@pytest.fixture(scope="module")
def hostile_input() -> HostileInput:
    """Three 300-step ds1-flips sequences (sign flips, 1% outliers) made worse: NaN and inf
    inside the mask, a zero and non-unit quaternions, garbage outside the mask, and a row that
    initialises late (:func:`~fkn_bench.estimators.conformance.hostile_measurements`)."""
    return hostile_measurements(seeds=(0, 1, 2), steps=300, late_start=45)


@pytest.fixture(scope="module")
def hostile(hostile_input: HostileInput) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measurements, mask and times of :func:`hostile_input`."""
    return hostile_input.measurements, hostile_input.mask, hostile_input.times


def test_frozen_noise_is_the_manual_ekf(hostile) -> None:
    """alpha = 1 freezes Akhlaghi's noise: the shared numpy recursion then reproduces the torch
    EKF with the manual tuning (means, covariances, innovations, flags)."""
    z, mask, _ = hostile
    ours = AkhlaghiEstimator(alpha=1.0).estimate(z, mask, DT)
    manual = make_estimator("manual-ekf").estimate(z, mask, DT)
    for name in ("means", "covariances", "error_covariances", "innovations", "innovation_covariances"):
        np.testing.assert_allclose(getattr(ours, name), getattr(manual, name), rtol=0, atol=1e-12, err_msg=name)
    np.testing.assert_array_equal(ours.innovation_mask, manual.innovation_mask)
    np.testing.assert_array_equal(ours.initialised, manual.initialised)


@pytest.mark.parametrize("name", ADAPTIVE)
def test_online_steps_equal_batch_estimates(name: str, hostile) -> None:
    """reset()/step() runs the batch recursion on a batch of one: the same numbers to 1e-12,
    with observation dicts (times) and plain arrays (NaN when missing)."""
    z, mask, times = hostile
    estimator = make_estimator(name)
    if name == "sage-husa":
        estimator = make_estimator(name, adapt_q=True)  # the optional branch too
    batch = estimator.estimate(z, mask, DT)
    for b in range(z.shape[0]):
        estimator.reset(dt=DT)
        for t in range(z.shape[1]):
            observation = {"pose": z[b, t], "valid": mask[b, t], "time": times[t]} if b != 1 else (z[b, t] if mask[b, t] else np.full(7, np.nan))
            estimate = estimator.step(observation)
            np.testing.assert_allclose(estimate.mean, batch.means[b, t], rtol=0, atol=1e-12, err_msg=f"{name} b={b} t={t}")
            np.testing.assert_allclose(estimate.native_covariance, batch.covariances[b, t], rtol=0, atol=1e-12)
            assert estimate.initialised == batch.initialised[b, t]
            assert estimate.updated == batch.innovation_mask[b, t]


@pytest.mark.parametrize("name", ADAPTIVE)
def test_hostile_input_follows_the_documented_rules(name: str, hostile_input: HostileInput) -> None:
    """The estimator API's input rules (skip unusable measurements, renormalise, sign flips, late
    initialisation, finite outputs), and a finite adapted R."""
    estimator = make_estimator(name)
    check_input_rules(estimator, hostile_input, atol=1e-11)
    z, mask, dt = hostile_input.measurements, hostile_input.mask, hostile_input.dt
    assert np.isfinite(estimator.estimate(z, mask, dt).extras["r_diag"]).all()


@pytest.mark.parametrize("name", ADAPTIVE)
def test_estimates_are_well_formed(name: str) -> None:
    episodes = generate_episodes("ds1", [3, 4], split="test")
    result = make_estimator(name).estimate(episodes.measurements, episodes.valid, DT)
    assert result.means.shape == (2, 1600, 13) and result.innovations.shape == (2, 1600, 6)
    np.testing.assert_allclose(np.linalg.norm(result.means[..., :4], axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(result.error_covariances, error_covariance_from_state(result.means[..., :4], result.covariances), atol=1e-15)
    np.testing.assert_array_equal(result.innovation_mask, episodes.valid & (np.arange(1600) > 0))
    assert result.extras["r_diag"].shape == (2, 1600, 7) and (result.extras["r_diag"] > 0).all()
    assert ("q_diag" in result.extras) == (name == "akhlaghi")
    # at least as good as the raw position measurements over the scored window
    position_error = np.sqrt(((result.means[:, 100:, 4:7] - episodes.truth[:, 100:, 4:7]) ** 2).mean())
    assert position_error < 0.1


def test_eigenvalue_clamping() -> None:
    rng = np.random.default_rng(0)
    V = np.linalg.qr(rng.normal(size=(5, 5)))[0]
    M = np.stack([V @ np.diag([-1.0, 1e-9, 0.5, 2.0, 3.0]) @ V.T, np.diag([1.0, 2.0, 3.0, 4.0, 5.0])])
    out = clamp_eigenvalues(M, np.array([1e-3, 1e-3]))
    np.testing.assert_allclose(np.linalg.eigvalsh(out[0]), [1e-3, 1e-3, 0.5, 2.0, 3.0], atol=1e-12)
    assert out[1] is not M[1] and np.array_equal(out[1], M[1])  # untouched row


def test_subclassed_models_run_the_same_step() -> None:
    """Any StateSpaceModel runs in the adaptive recursion (the models are written once for numpy
    and torch): a subclass gives the same numbers as the model itself."""

    class Wrapped(PoseTwistModel):
        pass

    episodes = generate_episodes("ds1", [0], split="test").window(0, 200)
    results = []
    for model in (PoseTwistModel(), Wrapped()):
        adaptive = AdaptiveKalmanFilter(AkhlaghiRule(), model=model)
        assert adaptive.model is model
        results.append(adaptive.run(episodes.measurements, episodes.valid, dt=DT).means)
    np.testing.assert_allclose(results[0], results[1], rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------- configuration
def test_registry_descriptions_and_knobs(tmp_path: Path) -> None:
    """``<name>`` runs the committed tuned settings of the scenario's family (issue 21), and
    ``<name>-default`` the paper's settings."""
    from fkn_bench.training.artifacts import artifact_path, read_artifact

    scenario = get_scenario("ds1")
    for name, cls in (("sage-husa", SageHusaEstimator), ("akhlaghi", AkhlaghiEstimator), ("vbakf", VBAKFEstimator)):
        for variant in (name, f"{name}-default"):
            spec = estimator_spec(variant)
            assert spec.description and not spec.trainable
            estimator = make_estimator(variant, scenario=scenario)
            assert isinstance(estimator, cls) and estimator.name == variant
        tuned = read_artifact(artifact_path(name, "ds1"))["estimator_config"]
        config = make_estimator(name, scenario=scenario).to_config()
        assert all(config[k] == v for k, v in tuned.items() if k != "adapt") and tuned.get("q_scale")
    assert make_estimator("sage-husa-default").to_config()["forgetting"] == 0.99
    assert make_estimator("akhlaghi-default").to_config()["alpha"] == 0.3
    vb = make_estimator("vbakf-default").to_config()
    assert (vb["tau_p"], vb["tau_r"], vb["iterations"]) == (3.0, 3.0, 10) and vb["rho"] == pytest.approx(1 - np.exp(-4))
    tuned = make_estimator("vbakf", iterations=3, r_std=[0.05] * 7, name="vb3")
    again = load_estimator(tuned.save(tmp_path / "vb3.json"))
    assert isinstance(again, VBAKFEstimator) and again.to_config() == tuned.to_config() and again.name == "vb3"
    episodes = generate_episodes("ds1", [0], split="test").window(0, 200)
    np.testing.assert_array_equal(again.estimate(episodes.measurements, episodes.valid, DT).means, tuned.estimate(episodes.measurements, episodes.valid, DT).means)


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [
        ("sage-husa", {"forgetting": 1.5}, "forgetting must be in"),
        ("sage-husa", {"forgetting": 0.0}, "forgetting must be in"),
        ("sage-husa", {"floor": 0.0}, "floor must be in"),
        ("sage-husa", {"warmup": -1}, "warmup must be an integer"),
        ("akhlaghi", {"alpha": -0.1}, "alpha must be in"),
        ("vbakf", {"tau_p": 0.0}, "tau_p must be"),
        ("vbakf", {"iterations": 0}, "iterations must be an integer"),
        ("vbakf", {"rho": 1.01}, "rho must be in"),
        ("vbakf", {"r_std": [0.1] * 6}, "r_std needs 7 values"),
        ("akhlaghi", {"q_std": [-1.0] * 13}, r"q_std\[0\] = -1.0 is outside"),
        ("akhlaghi", {"gamma": 1.0}, "unknown AkhlaghiEstimator options"),
        # values of the wrong kind (issue 34, finding 5): a number is no string or bool, a flag no string
        ("sage-husa", {"forgetting": "0.986"}, r"forgetting must be a number \(got '0.986'\)"),
        ("sage-husa", {"forgetting": True}, r"forgetting must be a number \(got True\)"),
        ("sage-husa", {"warmup": "100"}, "warmup must be an integer"),
        ("akhlaghi", {"adapt_r": "false"}, r"adapt_r must be true or false \(got 'false'\)"),
        ("vbakf", {"iterations": 2.5}, "iterations must be an integer"),
        ("vbakf", {"tau_r": 10**400}, "tau_r must be in the range of a float"),
    ],
)
def test_bad_knobs_are_refused(name: str, options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_estimator(name, **options)


def test_a_parameter_file_of_the_wrong_kind_is_refused_naming_the_file(tmp_path: Path) -> None:
    """A tuned adaptive filter's ``parameters=`` file whose value is ``"0.986"`` or ``true`` is
    refused naming the file (it was read as 0.986 and 1.0; issue 34, finding 5)."""
    from fkn_bench.training.artifacts import ArtifactError, artifact_path

    document = json.loads(artifact_path("sage-husa", "ds1").read_text())
    for bad in ("0.986", True):
        document["estimator_config"]["forgetting"] = bad
        path = tmp_path / "sage-husa.json"
        path.write_text(json.dumps(document))
        with pytest.raises(ArtifactError, match=r"sage-husa\.json: invalid sage-husa settings: forgetting must be a number"):
            make_estimator("sage-husa", scenario=get_scenario("ds1"), parameters=str(path))


def test_online_api_errors() -> None:
    estimator = make_estimator("vbakf")
    with pytest.raises(RuntimeError, match=r"call reset\(dt=...\) before step\(\)"):
        estimator.step(np.full(7, np.nan))
    for dt in (0.0, np.nan, "x"):
        with pytest.raises(ValueError, match="dt must be"):
            estimator.reset(dt=dt)  # type: ignore[arg-type]
    estimator.reset(dt=DT)
    estimator.step({"pose": np.r_[1.0, 0, 0, 0, 0, 0, 0], "valid": 1, "time": 2.0})
    with pytest.raises(ValueError, match="does not increase"):
        estimator.step({"pose": np.r_[1.0, 0, 0, 0, 0, 0, 0], "valid": 1, "time": 2.0})
    # an irregular interval is predicted over its actual length and stays finite
    estimate = estimator.step({"pose": np.r_[1.0, 0, 0, 0, 0.1, 0, 0], "valid": 1, "time": 2.35})
    assert estimate.updated and np.isfinite(estimate.native_covariance).all()


class _FailsOnLargeInnovations(AkhlaghiRule):
    """Akhlaghi's rule, but its update raises LinAlgError when any innovation exceeds 100 m."""

    def update(self, ctx, noise):  # noqa: ANN001, ANN201
        if np.abs(ctx.nu).max() > 100.0:
            raise np.linalg.LinAlgError("innovation covariance is not positive definite")
        return super().update(ctx, noise)


def test_a_failed_update_is_skipped_for_its_row_only(hostile) -> None:
    """An update that fails (LinAlgError or a non-finite result) is skipped for the rows it fails
    in, as an unusable measurement is; the other rows of the batch are updated as if alone."""
    z, mask, _ = hostile
    z, mask = z[:2].copy(), mask[:2].copy()
    step = int(np.flatnonzero(mask[1])[5])
    z[1, step, 4] += 1e4
    adaptive = AdaptiveKalmanFilter(_FailsOnLargeInnovations())
    both = adaptive.run(z, mask, dt=DT)
    alone = AdaptiveKalmanFilter(_FailsOnLargeInnovations()).run(z[:1], mask[:1], dt=DT)
    np.testing.assert_allclose(both.means[0], alone.means[0], rtol=0, atol=1e-12)
    assert not both.updated[1, step] and both.updated[1, np.flatnonzero(mask[1])[6]]
    np.testing.assert_array_equal(both.means[1, step], both.prior_means[1, step])  # kept the prediction
    np.testing.assert_array_equal(both.innovations[1, step], 0.0)
    masked = mask.copy()
    masked[1, step] = False  # the same as that measurement missing
    np.testing.assert_allclose(both.means[1], AdaptiveKalmanFilter(_FailsOnLargeInnovations()).run(z, masked, dt=DT).means[1], rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ADAPTIVE)
def test_the_chi_square_gate_keeps_an_outlier_out_of_the_state_and_the_noise_estimates(name: str) -> None:
    """``gate=0.999``: a 3 m position jump is skipped before the rule sees it (the state is not
    pulled, the adapted R is the one without the jump), in ``estimate`` and ``step`` alike."""
    episodes = generate_episodes("ds1", [0], split="test").window(0, 300)
    z, valid = episodes.measurements.copy(), episodes.valid.copy()
    jump = int(np.flatnonzero(valid[0])[20])
    z[0, jump, 4:7] += 3.0
    clean = make_estimator(name, gate=0.999).estimate(episodes.measurements.copy(), valid, DT)
    gated_estimator = make_estimator(name, gate=0.999)
    gated = gated_estimator.estimate(z, valid, DT)
    plain = make_estimator(name).estimate(z, valid, DT)
    assert plain.innovation_mask[0, jump] and not gated.innovation_mask[0, jump] and clean.innovation_mask[0, jump]
    after = slice(jump, jump + 5)
    assert np.abs(gated.means[0, after, 4:7] - episodes.truth[0, after, 4:7]).max() < 0.15
    np.testing.assert_array_equal(gated.extras["r_diag"][0, jump], gated.extras["r_diag"][0, jump - 1])
    gated_estimator.reset(dt=DT)
    for t in range(z.shape[1]):
        estimate = gated_estimator.step(z[0, t] if valid[0, t] else np.full(7, np.nan))
        assert estimate.updated == gated.innovation_mask[0, t], t
        np.testing.assert_allclose(estimate.mean, gated.means[0, t], rtol=0, atol=1e-9)
    assert gated_estimator.to_config()["gate"] == 0.999
