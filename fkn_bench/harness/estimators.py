"""The harness's view of the estimator registry: which estimators are available, the default
one, name checks and configuration fingerprints (for resuming grids).

An estimator is *available* for a scenario when its factory builds it (``make_estimator(name,
scenario=...)`` returns without error). A registered estimator may be unavailable, e.g. a learned
one whose trained parameters are not present; ``fkn-bench run`` then refuses it when named and
skips it in ``--all`` grids, saying why, rather than scoring a filter that never ran.
"""

from __future__ import annotations

from typing import Any

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass

from fkn_bench.estimators import UnknownEstimatorError, estimator_names, make_estimator
from fkn_bench.io import to_jsonable
from fkn_bench.scenarios import Scenario

__all__ = [
    "DEFAULT_ESTIMATOR_PREFERENCE",
    "Availability",
    "probe_estimator",
    "default_estimator",
    "check_estimators",
    "estimator_fingerprint",
]

DEFAULT_ESTIMATOR_PREFERENCE: tuple[str, ...] = ("flexkalmannet", "manual-ekf")
"""``fkn-bench run`` without ``--estimator`` runs the first of these that is available: the
paper's learned filter when it is registered and its parameters exist, else its manual baseline."""


@dataclass(frozen=True)
class Availability:
    """Whether estimator ``name`` builds for ``scenario``: its configuration ``fingerprint`` (16 hex
    digits of SHA-256 over ``to_config()``) or the ``error`` that its factory raised."""

    name: str
    scenario: str
    fingerprint: str | None
    error: str | None

    @property
    def available(self) -> bool:
        return self.error is None


def probe_estimator(name: str, scenario: Scenario, options: dict[str, Any] | None = None) -> Availability:
    """Build ``name`` for ``scenario`` (with factory ``options``) and describe it (never raises
    for factory errors)."""
    try:
        config = make_estimator(name, scenario=scenario, **(options or {})).to_config()
    except Exception as exc:  # noqa: BLE001 - reported to the user as unavailability
        return Availability(name, scenario.name, None, f"{type(exc).__name__}: {exc}")
    try:
        text = json.dumps(_rounded(to_jsonable(config)), sort_keys=True)
    except (TypeError, ValueError):
        return Availability(name, scenario.name, "", None)
    return Availability(name, scenario.name, hashlib.sha256(text.encode()).hexdigest()[:16], None)


FINGERPRINT_DIGITS = 12
"""Significant digits of the floats a fingerprint hashes. Some configurations hold numbers
computed from simulated data (the oracle's noise levels), whose last bits may differ between CPUs
(SIMD paths of ``exp``/``sin``/``cos``); rounding to 12 digits makes the fingerprint the same
wherever the numbers agree to rounding (a last-bit difference crosses a 12-digit rounding boundary
with probability ~1e-4 per number), while any real change of a parameter still changes it."""


def _rounded(value: Any) -> Any:
    """``value`` (JSON-compatible) with every float rounded to :data:`FINGERPRINT_DIGITS`."""
    if isinstance(value, float):
        return float(f"{value:.{FINGERPRINT_DIGITS}g}")
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_rounded(v) for v in value]
    return value


def estimator_fingerprint(name: str, scenario: Scenario) -> str:
    """The configuration fingerprint of ``name`` for ``scenario`` ("" when it cannot be built)."""
    return probe_estimator(name, scenario).fingerprint or ""


def default_estimator(scenarios: Sequence[Scenario] = ()) -> str:
    """The first name of :data:`DEFAULT_ESTIMATOR_PREFERENCE` that is registered and available for
    every one of ``scenarios``; else the first registered preference; else the first registered."""
    names = estimator_names()
    preferred = [n for n in DEFAULT_ESTIMATOR_PREFERENCE if n in names]
    for name in preferred:
        if all(probe_estimator(name, s).available for s in scenarios):
            return name
    if preferred:
        return preferred[-1]
    if not names:
        raise UnknownEstimatorError("no estimators are registered")
    return names[0]


def check_estimators(names: Sequence[str]) -> list[str]:
    """Return ``names`` without duplicates (first occurrence kept), or raise
    :class:`~fkn_bench.estimators.UnknownEstimatorError` listing the valid names."""
    valid = estimator_names()
    unknown = [n for n in names if n not in valid]
    if unknown:
        raise UnknownEstimatorError(
            f"unknown estimator{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}; "
            f"valid estimators: {', '.join(valid)}"
        )
    return list(dict.fromkeys(names))
