"""The Scenario dataclass: validation messages, derived values, dict round trip, config hash."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys

import pytest

from fkn_bench.scenarios import ASTROBEE_INERTIA, ASTROBEE_MASS, SPLITS, ConfigError, Scenario, list_scenarios


def test_config_error_is_a_value_error() -> None:
    assert issubclass(ConfigError, ValueError)


def test_defaults_are_the_papers_data_set_1() -> None:
    s = Scenario(name="x")
    assert s.dynamics == "forced"
    assert s.omega0 == (0.02, 0.04, 0.06)
    assert s.inertia == ASTROBEE_INERTIA == (0.153428, 0.142714, 0.162303)
    assert ASTROBEE_MASS == 9.5838
    assert (s.dt, s.n_steps, s.split) == (0.1, 16000, (0.8, 0.1, 0.1))
    assert (s.sigma_position, s.sigma_attitude, s.noise_scale, s.measurement_every) == (0.1, 0.1, 1.0, 10)
    assert (s.dropout, s.burst_rate, s.outlier_fraction, s.sign_flip_probability) == (0.0, 0.0, 0.0, 0.0)
    assert s.velocity0 == (0.0, 0.0, 0.0)
    assert s.attitude0 is None


def test_split_bounds() -> None:
    s = Scenario(name="x")
    assert s.split_bounds() == {"train": (0, 12800), "val": (12800, 14400), "test": (14400, 16000), "full": (0, 16000)}
    assert set(SPLITS) == {"train", "val", "test", "full"}
    odd = Scenario(name="y", n_steps=1001, split=(0.5, 0.25, 0.25))
    bounds = odd.split_bounds()
    assert bounds["train"][0] == 0 and bounds["test"][1] == 1001
    assert bounds["train"][1] == bounds["val"][0] and bounds["val"][1] == bounds["test"][0]


def test_effective_sigmas() -> None:
    s = Scenario(name="x", sigma_position=0.2, sigma_attitude=0.05, noise_scale=3.0)
    assert s.sigma_position_effective == pytest.approx(0.6)
    assert s.sigma_attitude_effective == pytest.approx(0.15)


def test_normalisation_and_conversion_of_values() -> None:
    s = Scenario(name="x", attitude0=[0.0, 3.0, 0.0, 4.0], omega0=[1, 2, 3], dropout=0, tags=["a", 1])
    assert s.attitude0 == (0.0, 0.6, 0.0, 0.8)
    assert s.omega0 == (1.0, 2.0, 3.0) and all(isinstance(v, float) for v in s.omega0)
    assert isinstance(s.dropout, float)
    assert s.tags == ("a", "1")


def test_frozen() -> None:
    s = Scenario(name="x")
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.noise_scale = 2.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("changes", "field", "allowed"),
    [
        ({"sigma_position": -0.1}, "sigma_position", "in [0, 1e+06]"),
        ({"sigma_attitude": -1e-9}, "sigma_attitude", "in [0, 1e+06]"),
        ({"noise_scale": -1.0}, "noise_scale", "in [0, 1e+06]"),
        ({"noise_scale": 1e300}, "noise_scale", "in [0, 1e+06]"),
        ({"noise_scale": 1e5, "sigma_attitude": 100.0}, "noise_scale", "noise_scale x sigma_attitude <= 1e+06"),
        ({"noise_scale": float("nan")}, "noise_scale", "finite"),
        ({"position0_std": float("inf")}, "position0_std", "finite"),
        ({"measurement_every": 0}, "measurement_every", "integer >= 1"),
        ({"measurement_every": 2.0}, "measurement_every", "integer >= 1"),
        ({"measurement_every": True}, "measurement_every", "integer >= 1"),
        ({"n_steps": 1}, "n_steps", "integer >= 2"),
        ({"burst_length": -1}, "burst_length", "integer >= 0"),
        ({"free_substeps": 0}, "free_substeps", "integer >= 1"),
        ({"dataset_seed": -1}, "dataset_seed", "integer >= 0"),
        ({"dropout": 1.5}, "dropout", "[0, 1]"),
        ({"dropout": -0.1}, "dropout", "[0, 1]"),
        ({"dropout": 1.0}, "dropout", "[0, 1)"),
        ({"burst_rate": 2.0}, "burst_rate", "[0, 1]"),
        ({"outlier_fraction": -0.5}, "outlier_fraction", "[0, 1]"),
        ({"sign_flip_probability": 1.01}, "sign_flip_probability", "[0, 1]"),
        ({"dt": 0.0}, "dt", "> 0"),
        ({"dynamics": "thrusting"}, "dynamics", "'forced' or 'free'"),
        ({"omega0_frame": "inertial"}, "omega0_frame", "'world' or 'body'"),
        ({"inertia_error": 0.05}, "inertia_error", "only with free dynamics"),
        ({"dynamics": "free", "inertia_error": -0.1}, "inertia_error", "[0, 0.5)"),
        ({"dynamics": "free", "inertia": (1.0, 1.0, 1.9), "inertia_error": 0.1}, "inertia_error", "physical"),
        ({"inertia": (1.0, 1.0, 3.0)}, "inertia", "physical"),
        ({"inertia": (0.15, -0.14, 0.16)}, "inertia", "positive"),
        ({"inertia": (0.15, 0.14)}, "inertia", "3 finite numbers"),
        ({"omega0": (0.1, 0.2)}, "omega0", "3 finite numbers"),
        ({"omega0": "fast"}, "omega0", "3 finite numbers"),
        ({"omega0": (0.1, float("nan"), 0.0)}, "omega0", "finite"),
        ({"attitude0": (0.0, 0.0, 0.0, 0.0)}, "attitude0", "non-zero quaternion"),
        ({"split": (0.5, 0.5, 0.5)}, "split", "summing to 1"),
        ({"split": (1.0, 0.0, 0.0)}, "split", "three positive fractions"),
        ({"split": (0.9998, 0.0001, 0.0001)}, "split", "at least 2 samples"),
        ({"name": ""}, "name", "non-empty"),
        ({"omega0_axis": "random"}, "omega0_axis", "'fixed' or 'uniform'"),
        ({"omega0_magnitude": (0.0, 0.5)}, "omega0_magnitude", "log-uniform: low > 0"),
        ({"omega0_magnitude": (0.5, 0.1)}, "omega0_magnitude", "low <= high"),
        ({"omega0_magnitude": (0.1, 1e3)}, "omega0_magnitude", "<= 100 rad/s"),
        ({"omega0_magnitude": (0.1,)}, "omega0_magnitude", "2 finite numbers"),
        ({"omega0_magnitude_distribution": "normal"}, "omega0_magnitude_distribution", "'log-uniform' or 'uniform'"),
        ({"omega0": (0.0, 0.0, 0.0), "omega0_magnitude": (0.1, 0.2)}, "omega0", "non-zero when its magnitude is drawn"),
        ({"omega0": (1e3, 0.0, 0.0)}, "omega0", "at most 100 rad/s"),
        ({"velocity0_std": -0.01}, "velocity0_std", "in [0, 1e+06]"),
    ],
)
def test_invalid_values_name_field_and_range(changes: dict, field: str, allowed: str) -> None:
    with pytest.raises(ConfigError) as excinfo:
        Scenario(**{"name": "x", **changes})
    message = str(excinfo.value)
    assert f"'{field}'" in message
    assert allowed in message
    # and the same through replace()
    if field != "name":
        with pytest.raises(ConfigError, match=field):
            Scenario(name="x").replace(**changes)


def test_later_fields_at_their_defaults_leave_the_hash_unchanged() -> None:
    # ds1's hash before omega0_frame and inertia_error existed (committed artefacts carry it)
    from fkn_bench.scenarios import get_scenario

    assert get_scenario("ds1").config_hash() == "54c803d2a4670c32"


def test_physical_inertia_limits() -> None:
    Scenario(name="x", inertia=(1.0, 1.0, 2.0))  # a thin disc: allowed (triangle equality)
    Scenario(name="x", inertia=(1.0, 1.0, 1.0))


def test_replace_unknown_field() -> None:
    with pytest.raises(ConfigError) as excinfo:
        Scenario(name="x").replace(noise=2.0, colour="red")
    message = str(excinfo.value)
    assert "colour, noise" in message and "valid fields" in message and "noise_scale" in message


def test_replace_returns_validated_copy() -> None:
    base = Scenario(name="x")
    changed = base.replace(noise_scale=5.0)
    assert changed.noise_scale == 5.0 and base.noise_scale == 1.0
    assert changed.replace(noise_scale=1.0) == base


@pytest.mark.parametrize("scenario", list_scenarios(), ids=lambda s: s.name)
def test_dict_round_trip(scenario: Scenario) -> None:
    data = scenario.to_dict()
    assert json.loads(json.dumps(data)) == data  # JSON-compatible
    assert isinstance(data["omega0"], list)
    assert Scenario.from_dict(data) == scenario
    assert Scenario.from_dict(json.loads(json.dumps(data))) == scenario


def test_from_dict_errors() -> None:
    with pytest.raises(ConfigError, match="'name' is required"):
        Scenario.from_dict({"noise_scale": 2.0})
    with pytest.raises(ConfigError, match="unknown scenario field.*bogus"):
        Scenario.from_dict({"name": "x", "bogus": 1})
    with pytest.raises(ConfigError, match="'dropout'"):
        Scenario.from_dict({"name": "x", "dropout": 3})
    partial = Scenario.from_dict({"name": "x", "noise_scale": 2})
    assert partial == Scenario(name="x", noise_scale=2.0)


def test_config_hash_stable_and_ignores_labels() -> None:
    s = Scenario(name="x")
    h = s.config_hash()
    assert len(h) == 16 and int(h, 16) >= 0
    assert Scenario(name="x").config_hash() == h
    assert s.replace(name="other", description="words", tags=("a", "b")).config_hash() == h
    assert Scenario.from_dict(s.to_dict()).config_hash() == h
    # the same in a fresh interpreter with another hash seed
    code = "from fkn_bench.scenarios import Scenario; print(Scenario(name='x').config_hash())"
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.strip() == h


_CHANGES = {
    "dynamics": "free",
    "omega0": (0.02, 0.04, 0.061),
    "omega0_frame": "body",
    "inertia_error": 0.05,
    "inertia": (0.15, 0.14, 0.16),
    "attitude0": (1.0, 0.0, 0.0, 0.0),
    "position0": (10.9, -6.7, 5.0),
    "position0_std": 0.1,
    "velocity0": (0.0, 0.0, 0.01),
    "velocity0_std": 0.01,
    "omega0_axis": "uniform",
    "omega0_magnitude": (0.02, 0.5),
    "omega0_magnitude_distribution": "uniform",
    "dt": 0.05,
    "n_steps": 16001,
    "split": (0.7, 0.2, 0.1),
    "split_mode": "episodes",
    "sigma_position": 0.2,
    "sigma_attitude": 0.2,
    "noise_scale": 5.0,
    "measurement_every": 1,
    "dropout": 0.2,
    "burst_rate": 0.01,
    "burst_length": 5,
    "outlier_fraction": 0.01,
    "outlier_position_sigma": 2.0,
    "sign_flip_probability": 0.5,
    "noise_step_scale": 5.0,
    "kick_rate": 0.01,
    "kick_length": 5,
    "kick_sigma": 0.01,
    "kick_decay": 2.0,
    "free_substeps": 2,
    "dataset_seed": 1,
    "model_family": "ds2",
    "measurement_covariance": True,
}


def test_change_table_covers_every_generating_field() -> None:
    fields = {f.name for f in dataclasses.fields(Scenario)}
    assert set(_CHANGES) == fields - {"name", "description", "tags", "test_episodes"}  # (test_episodes: generates nothing)
    assert Scenario(name="x", test_episodes=50).config_hash() == Scenario(name="x").config_hash()


@pytest.mark.parametrize("field", sorted(_CHANGES))
def test_config_hash_sensitive_to_generating_fields(field: str) -> None:
    base = Scenario(name="x", dynamics="free") if field == "inertia_error" else Scenario(name="x")
    assert base.replace(**{field: _CHANGES[field]}).config_hash() != base.config_hash()


def test_the_prior_is_described_quantity_by_quantity() -> None:
    """``describe_prior`` (what ``fkn-bench scenarios NAME`` prints): fixed values say so; drawn
    ones state their distribution and range."""
    from fkn_bench.scenarios import get_scenario

    assert get_scenario("ds1").describe_prior() == {
        "rate": "fixed (0.02, 0.04, 0.06) rad/s (world frame)", "attitude": "uniform on SO(3)",
        "position": "(10.9, -6.7, 4.9) m (fixed)", "velocity": "(0, 0, 0) m/s (fixed)",
        "splits": "pieces of each episode: train the first 80%, val the next 10%, test the last 10%",
    }
    assert get_scenario("spin").describe_prior()["splits"].startswith("whole episodes from disjoint seed pools")
    spin = Scenario(name="spin", omega0_axis="uniform", omega0_magnitude=(0.02, 0.5), velocity0_std=0.01,
                    position0_std=1.0, dynamics="free", inertia_error=0.1)
    prior = spin.describe_prior()
    assert prior["rate"] == "magnitude log-uniform in [0.02, 0.5] rad/s, axis uniform on the sphere (world frame)"
    assert prior["velocity"] == "(0, 0, 0) m/s + N(0, 0.01^2) per axis"
    assert prior["inertia"].endswith("x (1 + U(-0.1, 0.1)) per axis") and spin.has_rate_prior
