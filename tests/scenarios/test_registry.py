"""The scenario registry: built-in scenarios, lookup errors, registration and TOML files."""

from __future__ import annotations

from pathlib import Path

import pytest

from fkn_bench.scenarios import (
    ASTROBEE_INERTIA,
    ConfigError,
    Scenario,
    UnknownScenarioError,
    get_scenario,
    list_scenarios,
    load_scenarios,
    register_scenario,
    registry,
    scenario_names,
)

BUILT_IN = (
    "ds1", "ds2", "ds1-noise5x", "ds1-gap100", "ds1-dropout", "tumble-slow", "tumble-fast", "ds1-flips",
    "tumble-flip", "tumble-inertia-error",
)


@pytest.fixture
def isolated_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """Let a test register scenarios without leaking them into other tests."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def test_built_in_names_in_order() -> None:
    assert tuple(scenario_names()[: len(BUILT_IN)]) == BUILT_IN
    assert [s.name for s in list_scenarios()] == scenario_names()


def _paper_defaults(s: Scenario) -> None:
    assert (s.dt, s.n_steps, s.split) == (0.1, 16000, (0.8, 0.1, 0.1))
    assert (s.sigma_position, s.sigma_attitude) == (0.1, 0.1)
    assert s.velocity0 == (0.0, 0.0, 0.0)
    assert s.attitude0 is None


def test_ds1_and_ds2() -> None:
    ds1, ds2 = get_scenario("ds1"), get_scenario("ds2")
    for s in (ds1, ds2):
        _paper_defaults(s)
        assert s.dynamics == "forced" and s.noise_scale == 1.0 and s.measurement_every == 10
        assert (s.dropout, s.burst_rate, s.outlier_fraction, s.sign_flip_probability) == (0, 0, 0, 0)
    assert ds1.omega0 == (0.02, 0.04, 0.06) and ds1.model_family == "ds1"
    assert ds2.omega0 == (0.10, 0.20, 0.30) and ds2.model_family == "ds2"
    assert "paper" in ds1.tags and "paper" in ds2.tags


def test_robustness_variants() -> None:
    ds1 = get_scenario("ds1")
    noise = get_scenario("ds1-noise5x")
    assert noise.noise_scale == 5.0 and noise.sigma_position_effective == pytest.approx(0.5)
    assert noise.sigma_attitude_effective == pytest.approx(0.5)
    assert noise.replace(name="ds1", noise_scale=1.0, description=ds1.description, tags=ds1.tags) == ds1
    gap = get_scenario("ds1-gap100")
    assert gap.measurement_every == 100
    assert gap.replace(measurement_every=10).config_hash() == ds1.config_hash()


def test_dropout_scenario() -> None:
    s = get_scenario("ds1-dropout")
    _paper_defaults(s)
    assert (s.dropout, s.burst_rate, s.burst_length, s.measurement_every) == (0.2, 0.002, 50, 10)
    assert s.omega0 == (0.02, 0.04, 0.06) and s.dynamics == "forced"


def test_tumble_scenarios() -> None:
    slow, fast = get_scenario("tumble-slow"), get_scenario("tumble-fast")
    for s in (slow, fast):
        _paper_defaults(s)
        assert s.dynamics == "free" and s.inertia == ASTROBEE_INERTIA and s.measurement_every == 10
    assert slow.omega0 == (0.02, 0.04, 0.06) and slow.model_family == "tumble"
    assert fast.omega0 == (0.10, 0.20, 0.30) and fast.model_family == "tumble"


def test_free_tumble_stress_scenarios() -> None:
    flip, wrong = get_scenario("tumble-flip"), get_scenario("tumble-inertia-error")
    for s in (flip, wrong):
        _paper_defaults(s)
        assert s.dynamics == "free" and s.inertia == ASTROBEE_INERTIA and s.model_family == "tumble"
    assert flip.omega0_frame == "body" and flip.omega0 == (0.6, 0.1, 0.05) and flip.inertia_error == 0.0
    assert wrong.inertia_error == 0.1 and wrong.omega0 == get_scenario("tumble-fast").omega0


def test_flips_scenario() -> None:
    s = get_scenario("ds1-flips")
    _paper_defaults(s)
    assert (s.sign_flip_probability, s.outlier_fraction, s.outlier_position_sigma) == (0.5, 0.01, 1.0)
    assert s.replace(sign_flip_probability=0.0, outlier_fraction=0.0).config_hash() == get_scenario("ds1").config_hash()


def test_get_scenario_passes_scenarios_and_applies_overrides() -> None:
    ds2 = get_scenario("ds2")
    assert get_scenario(ds2) is ds2
    s = get_scenario("ds2", noise_scale=5.0, measurement_every=10, dropout=0.2)
    assert (s.noise_scale, s.measurement_every, s.dropout, s.omega0) == (5.0, 10, 0.2, (0.1, 0.2, 0.3))
    assert get_scenario("ds2") == ds2  # the registered one is unchanged
    assert get_scenario(Scenario(name="mine"), n_steps=50).n_steps == 50


@pytest.mark.parametrize("name", ["nope", "DS1", "", None, 3])
def test_unknown_scenario_lists_valid_names(name: object) -> None:
    with pytest.raises(UnknownScenarioError) as excinfo:
        get_scenario(name)  # type: ignore[arg-type]
    assert isinstance(excinfo.value, ConfigError)
    message = str(excinfo.value)
    assert repr(name) in message
    for valid in BUILT_IN:
        assert valid in message


def test_invalid_override_names_field() -> None:
    with pytest.raises(ConfigError, match="unknown scenario field.*noise_level"):
        get_scenario("ds1", noise_level=2.0)
    with pytest.raises(ConfigError, match=r"'dropout' must be a number in \[0, 1\]"):
        get_scenario("ds1", dropout=1.2)


def test_register_scenario(isolated_registry: None) -> None:
    mine = Scenario(name="mine", noise_scale=2.0)
    assert register_scenario(mine) is mine
    assert get_scenario("mine") is mine and scenario_names()[-1] == "mine"
    with pytest.raises(ConfigError, match="already registered"):
        register_scenario(Scenario(name="mine"))
    replacement = Scenario(name="mine", noise_scale=3.0)
    register_scenario(replacement, overwrite=True)
    assert get_scenario("mine") is replacement
    with pytest.raises(TypeError, match="expected a Scenario"):
        register_scenario({"name": "dict"})  # type: ignore[arg-type]


def test_isolated_registry_did_not_leak() -> None:
    assert "mine" not in scenario_names()


# ---------------------------------------------------------------------------- TOML files
def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scenarios.toml"
    path.write_text(text)
    return path


def test_load_with_base_inheritance(tmp_path: Path, isolated_registry: None) -> None:
    path = _write(
        tmp_path,
        """
[scenario.my-fast]
base = "ds2"
noise_scale = 2.0
measurement_every = 5

[scenario.my-faster]
base = "my-fast"
dropout = 0.1

[scenario.plain]
omega0 = [0.0, 0.0, 0.1]
n_steps = 100
""",
    )
    fast, faster, plain = load_scenarios(path)
    assert fast == get_scenario("ds2").replace(name="my-fast", noise_scale=2.0, measurement_every=5, tags=(),
                                               description="ds2 with noise_scale = 2.0, measurement_every = 5")
    assert faster == fast.replace(name="my-faster", dropout=0.1, description="my-fast with dropout = 0.1")
    assert "paper" in get_scenario("ds2").tags and fast.tags == ()  # a variant is not the paper's data set
    assert plain == Scenario(name="plain", omega0=(0.0, 0.0, 0.1), n_steps=100)
    assert get_scenario("my-fast") == fast and get_scenario("my-faster") == faster
    # loading again replaces them
    load_scenarios(path)


def test_load_without_registering(tmp_path: Path) -> None:
    path = _write(tmp_path, '[scenario.unlisted]\nbase = "ds1"\nnoise_scale = 4.0\n')
    (s,) = load_scenarios(path, register=False)
    assert s.name == "unlisted" and s.noise_scale == 4.0
    assert "unlisted" not in scenario_names()


def test_load_name_field_overrides_table_name(tmp_path: Path) -> None:
    path = _write(tmp_path, '[scenario.table]\nname = "field"\nbase = "ds1"\n')
    (s,) = load_scenarios(path, register=False)
    assert s.name == "field"


def test_missing_file(tmp_path: Path) -> None:
    missing = tmp_path / "absent.toml"
    with pytest.raises(ConfigError, match="scenario file not found") as excinfo:
        load_scenarios(missing)
    assert str(missing) in str(excinfo.value)


def test_bad_toml(tmp_path: Path) -> None:
    path = _write(tmp_path, "[scenario.x\nnoise_scale = = 2\n")
    with pytest.raises(ConfigError, match="is not valid TOML") as excinfo:
        load_scenarios(path)
    assert str(path) in str(excinfo.value)


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("title = 'nothing here'\n", "no \\[scenario.NAME\\] tables"),
        ("[scenario]\n", "no \\[scenario.NAME\\] tables"),
        ("[scenario]\nx = 3\n", "\\[scenario.x\\] must be a table"),
        (
            '[scenario.bad]\nbase = "ds1"\ndropout = 2.0\n',
            "\\[scenario.bad\\]: scenario field 'dropout' must be a number in \\[0, 1\\]",
        ),
        ('[scenario.bad]\nbase = "ds1"\nnoise = 2.0\n', "\\[scenario.bad\\]: unknown scenario field\\(s\\) noise"),
        ('[scenario.bad]\nbase = "ds9"\n', "\\[scenario.bad\\]: unknown scenario 'ds9'; valid scenarios: ds1, ds2"),
        ('[scenario.bad]\nmeasurement_every = 0\n', "'measurement_every' must be an integer >= 1"),
        ("[scenario.ds1]\nnoise_scale = 5.0\n",
         "\\[scenario.ds1\\]: would redefine the built-in scenario 'ds1'; give it another name, or set override = true"),
        ('[scenario.mine]\nname = "tumble-fast"\n', "\\[scenario.mine\\]: would redefine the built-in scenario 'tumble-fast'"),
        ('[scenario.ds2]\noverride = "yes"\n', "\\[scenario.ds2\\]: 'override' must be true or false \\(got 'yes'\\)"),
    ],
)
def test_toml_errors_name_the_problem(tmp_path: Path, text: str, pattern: str, isolated_registry: None) -> None:
    path = _write(tmp_path, text)
    before = scenario_names()
    with pytest.raises(ConfigError, match=pattern):
        load_scenarios(path)
    assert scenario_names() == before


def test_failed_file_registers_nothing(tmp_path: Path, isolated_registry: None) -> None:
    path = _write(tmp_path, '[scenario.good]\nbase = "ds1"\n[scenario.bad]\nbase = "ds1"\ndt = -1\n')
    with pytest.raises(ConfigError, match="'dt'"):
        load_scenarios(path)
    assert "good" not in scenario_names()


def test_override_true_replaces_a_built_in_scenario(tmp_path: Path, isolated_registry: None) -> None:
    from fkn_bench.scenarios import BUILTIN_SCENARIOS

    assert {"ds1", "ds2", "tumble-fast"} <= BUILTIN_SCENARIOS
    path = _write(tmp_path, "[scenario.ds1]\noverride = true\nbase = \"ds1\"\nnoise_scale = 5.0\n")
    (s,) = load_scenarios(path)
    assert s.name == "ds1" and get_scenario("ds1").noise_scale == 5.0


def test_prior_families_state_their_prior_and_keep_their_family() -> None:
    from fkn_bench.scenarios import PRIOR_FAMILIES

    assert set(PRIOR_FAMILIES) == {"spin", "free-tumble"}
    for family, names in PRIOR_FAMILIES.items():
        head = get_scenario(names[0])
        assert head.name == family and "prior" in head.tags and head.split_mode == "episodes"
        assert head.has_rate_prior and head.omega0_axis == "uniform" and head.attitude0 is None
        low, high = head.omega0_magnitude
        assert high / low >= 10 and head.velocity0_std > 0 and head.position0_std > 0
        assert len(names) == 6
        for name in names[1:]:  # stress variants: the family's prior, untrained-for measurement streams
            variant = get_scenario(name)
            assert variant.model_family == family and variant.split_mode == "episodes"
            assert variant.omega0_magnitude == head.omega0_magnitude and "stress" in variant.tags
    spin, tumble = get_scenario("spin"), get_scenario("free-tumble")
    ds1_rate, ds2_rate = (sum(v * v for v in get_scenario(n).omega0) ** 0.5 for n in ("ds1", "ds2"))
    assert spin.omega0_magnitude[0] < ds1_rate < ds2_rate < spin.omega0_magnitude[1]  # covers the paper's rates
    assert spin.dynamics == "forced" and tumble.dynamics == "free" and tumble.inertia_error > 0
    assert "prior" in get_scenario("free-tumble-flips").tags
