"""The registry of named scenarios, and scenarios defined in TOML files.

Two kinds of built-in scenarios:

* **Prior families** (the benchmark's headline): ``spin`` (forced rotation) and ``free-tumble``
  (torque-free rigid body), each with five stress variants (:data:`PRIOR_FAMILIES`). Every episode
  draws its own truth from the scenario's stated prior (rate magnitude and axis, attitude,
  position, drift, principal moments; ``fkn-bench scenarios NAME`` prints it) and train, val and
  test are disjoint sets of episodes, so a learned filter is scored on truths it never saw.
* **The paper's scenarios** (Pinheiro-Torres Vogt et al., FlexKalmanNet, sections 4 and 5): ``ds1`` and
  ``ds2`` are its two data sets (one fixed rate, zero velocity; train/val/test are pieces of one
  trajectory), ``ds1-noise5x`` and ``ds1-gap100`` its robustness runs; the others stress what the
  paper does not (dropout, free tumbling with Astrobee's inertia, sign flips and outliers).

TOML format (``fkn-bench ... --scenario-file my.toml``)::

    [scenario.my-fast]
    base = "ds2"            # optional: start from a registered scenario
    noise_scale = 2.0
    measurement_every = 5

A file cannot silently redefine a built-in scenario (:data:`BUILTIN_SCENARIOS`): a table named
like one is refused unless it says ``override = true``, so that results printed as "ds1" are the
paper's ds1.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fkn_bench.io import read_toml
from fkn_bench.scenarios.scenario import ConfigError, Scenario

__all__ = [
    "UnknownScenarioError",
    "register_scenario",
    "get_scenario",
    "list_scenarios",
    "scenario_names",
    "load_scenarios",
    "BUILTIN_SCENARIOS",
    "DS1_NOISE_STEP",
    "SPIN",
    "FREE_TUMBLE",
    "PRIOR_FAMILIES",
]


class UnknownScenarioError(ConfigError):
    """A scenario name that is not registered; the message lists the valid names."""


_REGISTRY: dict[str, Scenario] = {}


def register_scenario(scenario: Scenario, *, overwrite: bool = False) -> Scenario:
    """Add ``scenario`` to the registry under ``scenario.name`` and return it."""
    if not isinstance(scenario, Scenario):
        raise TypeError(f"expected a Scenario, got {type(scenario).__name__}")
    if scenario.name in _REGISTRY and not overwrite:
        raise ConfigError(f"scenario '{scenario.name}' is already registered (pass overwrite=True)")
    _REGISTRY[scenario.name] = scenario
    return scenario


def scenario_names() -> list[str]:
    """Registered scenario names in registration order."""
    return list(_REGISTRY)


def list_scenarios() -> list[Scenario]:
    """Registered scenarios in registration order."""
    return list(_REGISTRY.values())


def get_scenario(scenario: str | Scenario, **overrides: Any) -> Scenario:
    """Look up a scenario by name (or pass one through) and apply field overrides.

    Raises :class:`UnknownScenarioError` naming the valid scenarios, or :class:`ConfigError` for an
    invalid override.
    """
    if isinstance(scenario, Scenario):
        base = scenario
    else:
        try:
            base = _REGISTRY[scenario]
        except (KeyError, TypeError):
            raise UnknownScenarioError(
                f"unknown scenario {scenario!r}; valid scenarios: {', '.join(_REGISTRY)}"
            ) from None
    return base.replace(**overrides) if overrides else base


def _from_table(name: str, table: Mapping[str, Any], earlier: Mapping[str, Scenario]) -> Scenario:
    data = dict(table)
    base_name = data.pop("base", None)
    override = data.pop("override", False)
    if not isinstance(override, bool):
        raise ConfigError(f"'override' must be true or false (got {override!r})")
    data.setdefault("name", name)
    if data["name"] in BUILTIN_SCENARIOS and not override:
        raise ConfigError(
            f"would redefine the built-in scenario '{data['name']}'; give it another name, or set "
            f"override = true to replace the built-in one"
        )
    if base_name is None:
        return Scenario.from_dict(data)
    base = earlier.get(str(base_name)) or get_scenario(str(base_name))
    # a variant is not its base: unless the table says otherwise, it is described by what it
    # changes, and does not inherit the base's tags (e.g. "paper": it is not the paper's data set)
    changed = {k: v for k, v in data.items() if k not in ("name", "description", "tags")}
    if "description" not in data:
        what = ", ".join(f"{key} = {value!r}" for key, value in changed.items())
        data["description"] = f"{base.name} with {what}" if what else f"{base.name} (same configuration)"
    data.setdefault("tags", ())
    return base.replace(**data)


def load_scenarios(path: str | Path, *, register: bool = True) -> list[Scenario]:
    """Read scenarios from a TOML file (``[scenario.NAME]`` tables, see module docstring).

    A ``base`` may name a registered scenario or one defined earlier in the same file. A table
    that names a built-in scenario (:data:`BUILTIN_SCENARIOS`) raises :class:`ConfigError` unless
    it sets ``override = true``. Returns them and, unless ``register=False``, registers them
    (replacing same-named ones).
    """
    path = Path(path)
    document = read_toml(path, "scenario file", ConfigError)
    tables = document.get("scenario")
    if not isinstance(tables, dict) or not tables:
        raise ConfigError(f"scenario file {path} has no [scenario.NAME] tables")
    scenarios: list[Scenario] = []
    loaded: dict[str, Scenario] = {}  # possible bases for the tables that follow
    for name, table in tables.items():
        if not isinstance(table, dict):
            raise ConfigError(f"{path}: [scenario.{name}] must be a table")
        try:
            scenario = _from_table(name, table, loaded)
        except ConfigError as exc:
            raise ConfigError(f"{path}: [scenario.{name}]: {exc}") from None
        scenarios.append(scenario)
        loaded[scenario.name] = scenario
    if register:
        for scenario in scenarios:
            register_scenario(scenario, overwrite=True)
    return scenarios


_DS1 = Scenario(
    name="ds1",
    description=(
        "Paper data set 1: forced rotation at [0.02, 0.04, 0.06] rad/s (world frame), v = 0, "
        "10 Hz, 16000 samples, 80/10/10 split, noise 0.1 m / 0.1 rad, a measurement every 10 steps"
    ),
    tags=("paper",),
)
_DS2 = _DS1.replace(
    name="ds2",
    description="Paper data set 2: as ds1 at [0.10, 0.20, 0.30] rad/s",
    omega0=(0.10, 0.20, 0.30),
    model_family="ds2",
)

for _scenario in (
    _DS1,
    _DS2,
    _DS1.replace(
        name="ds1-noise5x",
        description="ds1 with five times the measurement noise (0.5 m, 0.5 rad): paper's robustness run",
        noise_scale=5.0,
    ),
    _DS1.replace(
        name="ds1-gap100",
        description="ds1 with a measurement every 100 steps (10 s): paper's data-gap run",
        measurement_every=100,
    ),
    _DS1.replace(
        name="ds1-dropout",
        description=(
            "ds1 with 20% random dropout and bursts of 50 missing steps starting with probability "
            "0.002 per step"
        ),
        dropout=0.2,
        burst_rate=0.002,
        burst_length=50,
        tags=(),
    ),
    _DS1.replace(
        name="tumble-slow",
        description=(
            "Torque-free tumble with Astrobee's flight inertia from ds1's initial rate: the body "
            "rate wobbles (period ~875 s) and the world-frame rate varies by ~14%"
        ),
        dynamics="free",
        model_family="tumble",
        tags=(),
    ),
    _DS2.replace(
        name="tumble-fast",
        description="Torque-free tumble with Astrobee's flight inertia from ds2's initial rate",
        dynamics="free",
        model_family="tumble",
        tags=(),
    ),
    _DS1.replace(
        name="ds1-flips",
        description=(
            "ds1 where each measured quaternion arrives as -q with probability 0.5 and 1% of the "
            "measurements are gross outliers (random attitude, 1 m position error)"
        ),
        sign_flip_probability=0.5,
        outlier_fraction=0.01,
        tags=(),
    ),
    _DS2.replace(
        name="tumble-flip",
        description=(
            "Torque-free tumble spinning 10 deg off Astrobee's intermediate axis (body rate "
            "(0.6, 0.1, 0.05) rad/s from a random attitude): the body flips about every 150 s "
            "(Dzhanibekov effect)"
        ),
        dynamics="free",
        model_family="tumble",
        omega0=(0.6, 0.1, 0.05),
        omega0_frame="body",
        tags=(),
    ),
    _DS2.replace(
        name="tumble-inertia-error",
        description=(
            "tumble-fast where each seed's true principal moments differ from Astrobee's nominal "
            "ones by up to +-10% per axis (uniform): a filter told the nominal inertia is misinformed"
        ),
        dynamics="free",
        model_family="tumble",
        inertia_error=0.1,
        tags=(),
    ),
):
    register_scenario(_scenario)

DS1_NOISE_STEP = _DS1.replace(
    name="ds1-noise-step",
    description=(
        "ds1 with non-stationary noise: five times the measurement noise (0.5 m, 0.5 rad) in the "
        "middle third of each split, and bursts of unmodelled torque (2 s bursts starting with "
        "probability 0.002 per step, rate random walk 0.01 rad/s per step, decaying back with a "
        "5 s time constant)"
    ),
    noise_step_scale=5.0,
    kick_rate=0.002,
    kick_length=20,
    kick_sigma=0.01,
    kick_decay=5.0,
    model_family="ds1-noise-step",
    tags=(),
)
"""ds1 with non-stationary noise (five times the measurement noise in the middle third of each
split) and bursts of unmodelled torque: the scenario where estimating the noise while filtering
should pay. Its own model family, so that the learned and tuned
estimators run there with parameters trained on its training split."""
register_scenario(DS1_NOISE_STEP)

_PRIOR = dict(
    split_mode="episodes",
    n_steps=3000,
    attitude0=None,
    omega0_axis="uniform",
    position0_std=1.0,
    velocity0_std=0.01,
    test_episodes=50,
    tags=("prior",),
)
"""What the two prior families share: every split whole episodes from disjoint seed pools, 300 s
episodes (3000 samples at 10 Hz, a measurement every second), a uniformly random attitude and rate
axis, a start within about a metre of the paper's position (N(0, 1 m^2) per axis) and a drift of
N(0, (1 cm/s)^2) per axis (about 1.6 cm/s typical speed, 5 m over an episode); scored on 50 test
episodes (their stress variants on 10)."""

SPIN = _DS1.replace(
    name="spin",
    description=(
        "Prior family: forced rotation at a rate drawn per episode, magnitude log-uniform in "
        "[0.03, 0.6] rad/s (1.7 to 34 deg/s, ds1's 0.075 and ds2's 0.374 inside) about a uniformly "
        "random axis, a drift of 1 cm/s per axis and a metre of position spread; 300 s episodes, "
        "train/val/test from disjoint seed pools"
    ),
    omega0_magnitude=(0.03, 0.6),
    model_family="spin",
    **_PRIOR,
)
"""The forced-spin prior family's headline scenario (its stress variants: :data:`PRIOR_FAMILIES`)."""

FREE_TUMBLE = SPIN.replace(
    name="free-tumble",
    description=(
        "Prior family: torque-free tumble of an Astrobee-class body, principal moments Astrobee's "
        "x U(0.9, 1.1) per axis, body rate magnitude log-uniform in [0.05, 0.6] rad/s about a "
        "uniformly random body axis (spins near the intermediate axis included: about 3% of "
        "episodes start within 15 deg of it), the same translation prior as spin; 300 s episodes, "
        "train/val/test from disjoint seed pools"
    ),
    dynamics="free",
    omega0_frame="body",
    omega0_magnitude=(0.05, 0.6),
    inertia_error=0.1,
    model_family="free-tumble",
)
"""The free-tumble prior family's headline scenario."""

_STRESS = (
    ("noise5x", "five times the measurement noise (0.5 m, 0.5 rad)", dict(noise_scale=5.0)),
    ("gap100", "a measurement every 100 steps (10 s)", dict(measurement_every=100)),
    ("dropout", "20% random dropout and bursts of 50 missing steps (probability 0.002 per step)",
     dict(dropout=0.2, burst_rate=0.002, burst_length=50)),
    ("flips", "each measured quaternion negated with probability 0.5 and 1% gross outliers",
     dict(sign_flip_probability=0.5, outlier_fraction=0.01)),
    ("noise-step", "five times the measurement noise in the middle third of each episode",
     dict(noise_step_scale=5.0)),
)
"""The stress variants of each prior family: what they change and the fields that change it. They
keep their family's ``model_family``: the learned and tuned estimators meet them untrained."""

PRIOR_FAMILIES: dict[str, tuple[str, ...]] = {}
"""Each prior family's scenarios, headline first (``{"spin": ("spin", "spin-noise5x", ...)}``)."""
for _family in (SPIN, FREE_TUMBLE):
    register_scenario(_family)
    _members = [_family.name]
    for _suffix, _what, _fields in _STRESS:
        register_scenario(_family.replace(name=f"{_family.name}-{_suffix}", description=f"{_family.name} with {_what}",
                                          tags=("prior", "stress"), test_episodes=10, **_fields))
        _members.append(f"{_family.name}-{_suffix}")
    PRIOR_FAMILIES[_family.model_family] = tuple(_members)

BUILTIN_SCENARIOS: frozenset[str] = frozenset(_REGISTRY)
"""Names of the built-in scenarios, which a scenario file redefines only with ``override = true``."""
