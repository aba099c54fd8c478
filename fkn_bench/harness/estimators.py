"""Resolving estimators: each (estimator, scenario) pair is built once, here, and everything the
harness needs afterwards (availability, configuration fingerprint, the estimator the cells run)
comes from that one build.

An estimator is *available* for a scenario when its factory builds it (``make_estimator(name,
scenario=...)`` returns without error); a learned one whose trained parameters are not present is
not. :func:`select_estimators` chooses what runs, saying why it refuses or skips a pair.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from fkn_bench.estimators import Estimator, UnknownEstimatorError, estimator_names, estimator_spec, make_estimator
from fkn_bench.io import to_jsonable
from fkn_bench.scenarios import Scenario

__all__ = [
    "DEFAULT_ESTIMATOR_PREFERENCE",
    "ResolvedEstimator",
    "Selection",
    "SelectionError",
    "resolve_estimator",
    "resolve",
    "select_estimators",
    "TRAINING_SEED_OPTION",
    "training_seed_replicas",
]

DEFAULT_ESTIMATOR_PREFERENCE: tuple[str, ...] = ("flexkalmannet", "manual-ekf")
"""Without estimator names, :func:`select_estimators` picks the first of these that is available:
the paper's learned filter when it is registered and its parameters exist, else its manual baseline."""


@dataclass(frozen=True, eq=False)
class ResolvedEstimator:
    """Estimator ``name`` (registered name) built once for scenario ``scenario`` (its name) with
    factory ``options`` (sorted ``(name, value)`` pairs). ``estimator`` is None when the factory
    raised and ``error`` (``"Type: message"``) says why. ``fingerprint``: 16 hex digits of SHA-256
    over ``to_config()`` (floats rounded to :data:`FINGERPRINT_DIGITS`) and the content of the
    weights files it names (:func:`_named_files`), so that a retuned or retrained estimator is
    recomputed on resume; "" when unknown (unavailable, or not JSON-compatible)."""

    name: str
    scenario: str
    estimator: Estimator | None = field(default=None, repr=False)
    error: str | None = None
    fingerprint: str = ""
    options: tuple[tuple[str, Any], ...] = ()
    option_error: bool = False
    """True when ``error`` comes from the ``options`` (the estimator builds without them)."""

    @property
    def available(self) -> bool:
        return self.error is None

    def problem(self) -> str:
        """Why the pair cannot run, in the command line's words: a rejected option names
        ``--estimator-option``; anything else is unavailability for the scenario."""
        if self.option_error:
            given = " ".join(f"{key}={value}" for key, value in self.options)
            return f"--estimator-option {given}: {self.error}"
        return f"estimator {self.name!r} is not available for scenario {self.scenario}: {self.error}"


class SelectionError(ValueError):
    """A selection that cannot run (a named estimator unavailable, nothing available)."""


@dataclass(frozen=True)
class Selection:
    """What :func:`select_estimators` chose: the available pairs in run order, and ``notes`` for
    the user (a preferred default that is unavailable, pairs skipped)."""

    resolved: list[ResolvedEstimator]
    notes: list[str]

    @property
    def names(self) -> list[str]:
        return list(dict.fromkeys(r.name for r in self.resolved))


FINGERPRINT_DIGITS = 12
"""Significant digits of the floats a fingerprint hashes. Some configurations hold numbers
computed from simulated data (the oracle's noise levels), whose last bits may differ between CPUs
(SIMD paths of ``exp``/``sin``/``cos``); rounding to 12 digits makes the fingerprint the same
wherever the numbers agree to rounding (a last-bit difference crosses a 12-digit rounding boundary
with probability ~1e-4 per number), while any real change of a parameter still changes it."""


def _rounded(value: Any) -> Any:
    if isinstance(value, float):
        return float(f"{value:.{FINGERPRINT_DIGITS}g}")
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_rounded(v) for v in value]
    return value


WEIGHT_FILE_SUFFIXES = (".pt", ".pth")
"""Configuration values naming a file with these endings are weights whose content the
fingerprint covers (:func:`_named_files`)."""


def _named_files(config: Any) -> dict[str, str]:
    """``{key: SHA-256}`` of the weights files that ``config``'s top-level string values name (a
    checkpoint, a committed ``.weights.pt`` by its label): a network estimator's configuration
    names its weights by path, so without their content a retrained network in the same file would
    keep its fingerprint and its stale cells would be reused."""
    from fkn_bench.training.artifacts import resolve_artifact_label

    digests = {}
    for key, value in (config.items() if isinstance(config, dict) else ()):
        if isinstance(value, str) and value.endswith(WEIGHT_FILE_SUFFIXES):
            path = resolve_artifact_label(value)
            if path.is_file():
                digests[key] = hashlib.sha256(path.read_bytes()).hexdigest()
    return digests


def resolve_estimator(name: str, scenario: Scenario, options: dict[str, Any] | None = None) -> ResolvedEstimator:
    """Build ``name`` for ``scenario`` (with factory ``options``) once and describe it (never
    raises for factory errors: they make the result unavailable)."""
    items = tuple(sorted((options or {}).items()))
    try:
        estimator = make_estimator(name, scenario=scenario, **(options or {}))
        config = estimator.to_config()
    except Exception as exc:  # noqa: BLE001 - reported to the user as unavailability
        if items:
            rejected = _option_problem(name, scenario, dict(items), exc)
            if rejected is not None:
                return ResolvedEstimator(name, scenario.name, error=rejected, options=items, option_error=True)
        return ResolvedEstimator(name, scenario.name, error=f"{type(exc).__name__}: {exc}", options=items)
    try:
        text = json.dumps(_rounded(to_jsonable(config)), sort_keys=True)
        files = _named_files(config)
        if files:  # (estimators that name no file keep the fingerprint they always had)
            text += json.dumps(files, sort_keys=True)
        fingerprint = hashlib.sha256(text.encode()).hexdigest()[:16]
    except (TypeError, ValueError):
        fingerprint = ""
    return ResolvedEstimator(name, scenario.name, estimator, fingerprint=fingerprint, options=items)


def _option_problem(name: str, scenario: Scenario, options: dict[str, Any], exc: Exception) -> str | None:
    """What is wrong with ``options`` when ``name`` builds for ``scenario`` without them (None
    when it does not: then the failure is the estimator's, not the options'). An unknown key is
    named with the options the estimator takes (its factory's keywords and, for a factory that
    passes its keywords on, those of the estimator's class)."""
    try:
        plain = make_estimator(name, scenario=scenario)
    except Exception:  # noqa: BLE001 - unavailable anyway
        return None
    factory = estimator_spec(name).factory
    valid = _option_names(factory)
    if _passes_keywords_on(factory):  # e.g. the built-in factories: **options go to the class
        valid |= _option_names(type(plain).__init__)
        if _passes_keywords_on(type(plain).__init__):  # the class's keywords are open too: its own message says
            valid = set()
    unknown = sorted(set(options) - valid) if valid else []
    if unknown:
        return (f"estimator {name!r} has no option{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}; "
                f"valid options: {', '.join(sorted(valid))}")
    message = str(exc)
    return message if isinstance(exc, ValueError) else f"{type(exc).__name__}: {message}"


def _passes_keywords_on(function: Any) -> bool:
    import inspect

    try:
        return any(p.kind is inspect.Parameter.VAR_KEYWORD for p in inspect.signature(function).parameters.values())
    except (TypeError, ValueError):
        return False


def _option_names(function: Any) -> set[str]:
    """Keyword parameters of ``function`` (not ``self``, ``scenario`` or ``**kwargs``)."""
    import inspect

    try:
        parameters = inspect.signature(function).parameters.values()
    except (TypeError, ValueError):
        return set()
    kinds = (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return {p.name for p in parameters if p.kind in kinds and p.name not in ("self", "scenario")}


def resolve(
    names: Sequence[str] | None, scenarios: Sequence[Scenario], options: dict[str, Any] | None = None
) -> list[ResolvedEstimator]:
    """Every pair of ``names`` (None: every registered estimator; duplicates dropped) x
    ``scenarios``, each built once, estimator-major; unknown names raise
    :class:`~fkn_bench.estimators.UnknownEstimatorError` listing the valid names."""
    valid = estimator_names()
    unknown = [n for n in names or () if n not in valid]
    if unknown:
        raise UnknownEstimatorError(
            f"unknown estimator{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}; "
            f"valid estimators: {', '.join(valid)}"
        )
    names = valid if names is None else list(dict.fromkeys(names))
    return [resolve_estimator(name, scenario, options) for name in names for scenario in scenarios]


def _default(scenarios: Sequence[Scenario]) -> tuple[list[ResolvedEstimator], list[str]]:
    """The first of :data:`DEFAULT_ESTIMATOR_PREFERENCE` that is registered and available on every
    scenario (else the last registered preference, else the first registered estimator), with a
    note for each preferred one passed over."""
    registered = estimator_names()
    preferred = [n for n in DEFAULT_ESTIMATOR_PREFERENCE if n in registered] or registered[:1]
    if not preferred:
        raise UnknownEstimatorError("no estimators are registered")
    passed: list[tuple[str, str]] = []
    for name in preferred:
        pairs = resolve([name], scenarios)
        if all(r.available for r in pairs) or name == preferred[-1]:
            break
        passed.append((name, next(r.error for r in pairs if not r.available) or "unavailable"))
    return pairs, [f"{better} is not available ({reason}); running {name}" for better, reason in passed]


TRAINING_SEED_OPTION = "training_seed"
"""The factory option that builds another training seed of a seed study
(:mod:`fkn_bench.training.seeds`): a cell with this option alone is a *training-seed replica* of
the estimator's committed row, which the leaderboards fold into that row's training-seed spread
instead of ranking it."""


def _seed_study_of(name: str, scenario: Scenario) -> dict[str, Any] | None:
    """The seed study of the committed artefact ``name`` runs from on ``scenario`` (None: none)."""
    from fkn_bench.training.artifacts import artifact_family, committed_artifact_path, seed_study

    try:
        path = committed_artifact_path(name, artifact_family(name, scenario))
    except (ValueError, KeyError, OSError):
        return None
    return None if path is None else seed_study(path)


def family_headline(scenario: Scenario) -> bool:
    """Whether ``scenario`` is its model family's headline: the scenario the family is named after
    (spin, free-tumble, ds1, ds2, ds1-noise-step), or any scenario of a family that none is named
    after (the tumble mixture's tumble-slow, tumble-fast, ...). Training seeds are scored there."""
    from fkn_bench.scenarios import scenario_names

    return scenario.name == scenario.model_family or scenario.model_family not in scenario_names()


def training_seed_replicas(pairs: Sequence[ResolvedEstimator], scenarios: Sequence[Scenario]) -> list[ResolvedEstimator]:
    """For every available pair of ``pairs`` on a :func:`family_headline` scenario, built without
    options from a committed artefact that a seed study chose, the same estimator built with each
    other seed of the study (``training_seed=K``): what the leaderboards' training-seed spread is
    computed from."""
    by_name = {s.name: s for s in scenarios}
    replicas = []
    for pair in pairs:
        scenario = by_name.get(pair.scenario)
        if not pair.available or pair.options or scenario is None or not family_headline(scenario):
            continue
        study = _seed_study_of(pair.name, scenario)
        if study is None:
            continue
        for run in study.get("runs", ()):
            if run.get("status") == "ok" and int(run["seed"]) != int(study["chosen_seed"]):
                replicas.append(resolve_estimator(pair.name, scenario, {TRAINING_SEED_OPTION: int(run["seed"])}))
    return replicas


def select_estimators(
    names: Sequence[str] | None,
    scenarios: Sequence[Scenario],
    *,
    every: bool = False,
    options: dict[str, Any] | None = None,
    training_seeds: bool = False,
) -> Selection:
    """The estimators to run on ``scenarios``, each pair resolved once.

    * ``names`` given: those (unknown ones raise
      :class:`~fkn_bench.estimators.UnknownEstimatorError`); a pair that is not available raises
      :class:`SelectionError`.
    * no names, ``every``: every registered estimator; unavailable pairs are skipped with a note,
      estimators with no available pair dropped.
    * no names: the default (:data:`DEFAULT_ESTIMATOR_PREFERENCE`), which must be available.

    ``training_seeds``: also every :func:`training_seed_replicas` of the chosen pairs (one whose
    seed file is missing is skipped with a note).
    """
    if names or every:
        pairs, notes = resolve(names or None, scenarios, options), []
    else:
        pairs, notes = _default(scenarios)
    chosen = []
    for pair in pairs:
        if pair.available:
            chosen.append(pair)
        elif names or not every:
            raise SelectionError(pair.problem())
        else:
            notes.append(f"skipping {pair.name} on {pair.scenario} (not available: {pair.error})")
    if not chosen:
        raise SelectionError("no available estimator to run")
    if training_seeds:
        for replica in training_seed_replicas(chosen, scenarios):
            if replica.available:
                chosen.append(replica)
            else:
                notes.append(f"skipping a training seed of {replica.name} on {replica.scenario} ({replica.error})")
    return Selection(chosen, notes)
