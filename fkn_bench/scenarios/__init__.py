"""Scenario configurations and their registry (see :class:`Scenario`)."""

from fkn_bench.scenarios import registry, scenario
from fkn_bench.scenarios.registry import *  # noqa: F403  (the public API of both modules, republished)
from fkn_bench.scenarios.scenario import *  # noqa: F403

__all__ = scenario.__all__ + registry.__all__
