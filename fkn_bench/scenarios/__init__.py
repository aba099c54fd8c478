"""Scenario configurations and their registry (see :class:`Scenario`)."""

from fkn_bench.scenarios.registry import (
    UnknownScenarioError,
    get_scenario,
    list_scenarios,
    load_scenarios,
    register_scenario,
    scenario_names,
)
from fkn_bench.scenarios.scenario import ASTROBEE_INERTIA, ASTROBEE_MASS, SPLITS, ConfigError, Scenario

__all__ = [
    "ASTROBEE_INERTIA",
    "ASTROBEE_MASS",
    "SPLITS",
    "ConfigError",
    "Scenario",
    "UnknownScenarioError",
    "get_scenario",
    "list_scenarios",
    "load_scenarios",
    "register_scenario",
    "scenario_names",
]
