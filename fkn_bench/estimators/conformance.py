"""Conformance checks of the estimator API's input rules, for the project's estimators and yours.

Every estimator of fkn-bench follows the same documented rules for bad measurements
(:mod:`fkn_bench.estimators.base`): a measurement inside the mask that is non-finite or has a
(near) zero-norm quaternion is skipped (predict only); measured quaternions are renormalised, so
their scale changes nothing; q and -q are the same attitude, so sign flips change nothing but the
sign of the estimated quaternion; a sequence reports the prior until its first usable
measurement; nothing outside the mask is read; and no output is ever NaN or infinite.

:func:`hostile_measurements` builds a small batch that breaks every one of those at once, and
:func:`check_input_rules` runs an estimator on it and raises ``AssertionError`` naming the rule it
breaks. Use it in your own tests::

    from fkn_bench.estimators.conformance import check_input_rules

    def test_my_filter_follows_the_input_rules():
        check_input_rules(MyEstimator())

:func:`garbage_measurements` is a fuzz: a fraction of a batch's measurements (30% by default)
replaced by garbage of every kind at once (values up to 1e300, position jumps of 1 m to 1e15 m,
1e4 m outliers, random quaternions of any scale, NaN and inf, zero and tiny quaternions, sign
flips), half of it inside the mask where there was no measurement. :func:`check_survives_garbage`
runs an estimator on it and asserts that it raises nothing and emits nothing non-finite (the
estimators' restart rule, :func:`~fkn_bench.estimators.base.restart_diverged`, is allowed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fkn_bench.types import ArrayB, ArrayF

__all__ = ["HostileInput", "hostile_measurements", "check_input_rules", "garbage_measurements", "check_survives_garbage",
           "build_for_checks"]


@dataclass(frozen=True)
class HostileInput:
    """Measurements ``(B, T, 7)``, mask ``(B, T)``, times ``(T,)`` in s, the time step ``dt`` (s),
    and the ``(sequence, step)`` indices of the unusable measurements placed inside the mask."""

    measurements: ArrayF
    mask: ArrayB
    times: ArrayF
    dt: float
    unusable: tuple[tuple[int, int], ...]
    late_sequence: int | None


def hostile_measurements(seeds: tuple[int, ...] = (0, 1, 2), steps: int = 300, late_start: int | None = 45) -> HostileInput:
    """ds1-flips test-split sequences (random sign flips, 1% gross outliers) made worse: in
    sequence 0 a NaN, an inf and a zero quaternion inside the mask (its 3rd, 5th and 7th
    measurements) and a quaternion scaled by 3 (9th); in sequence 1 every quaternion scaled by
    0.25 and the value 7.0 everywhere outside the mask; and, with ``late_start``, sequence 2
    masked until that step (it initialises late). Needs at least two seeds, three with
    ``late_start`` (ValueError otherwise)."""
    from fkn_bench.envs import generate_episodes

    if len(seeds) < 2:
        raise ValueError(f"hostile_measurements needs at least two seeds (got {len(seeds)}): sequence 1 carries "
                         f"the rescaled quaternions")
    if late_start is not None and len(seeds) < 3:
        raise ValueError(f"late_start needs at least three seeds (got {len(seeds)})")
    episodes = generate_episodes("ds1-flips", list(seeds), split="test").window(0, steps)
    z, mask = episodes.measurements.copy(), episodes.valid.copy()
    measured = np.flatnonzero(mask[0])
    z[0, measured[2], 3] = np.nan
    z[0, measured[4], 5] = np.inf
    z[0, measured[6], :4] = 0.0
    z[0, measured[8], :4] *= 3.0
    z[1, mask[1], :4] *= 0.25
    z[~mask] = np.nan
    z[1, ~mask[1]] = 7.0  # garbage outside the mask
    if late_start is not None:
        mask[2, :late_start] = False
    unusable = tuple((0, int(measured[i])) for i in (2, 4, 6))
    return HostileInput(z, mask, np.asarray(episodes.times), float(episodes.scenario.dt), unusable,
                        2 if late_start is not None else None)


def _close(actual: ArrayF, expected: ArrayF, atol: float, rule: str) -> None:
    np.testing.assert_allclose(actual, expected, rtol=0, atol=atol, err_msg=f"input rule broken: {rule}")


def check_input_rules(estimator: object, hostile: HostileInput | None = None, *, atol: float = 1e-11) -> None:
    """Run ``estimator.estimate`` on ``hostile`` (default :func:`hostile_measurements`) and check
    the rules of the module docstring; raises ``AssertionError`` naming the first rule broken.
    ``atol`` bounds the differences that rounding may leave between equivalent inputs."""
    data = hostile if hostile is not None else hostile_measurements()
    z, mask, dt = data.measurements, data.mask, data.dt
    result = estimator.estimate(z, mask, dt)  # type: ignore[attr-defined]
    for name in ("means", "covariances", "error_covariances", "innovations", "innovation_covariances"):
        array = getattr(result, name, None)
        if array is not None:
            assert np.isfinite(array).all(), f"input rule broken: {name} must be finite"
    innovation_mask = getattr(result, "innovation_mask", None)
    if innovation_mask is not None:
        for b, t in data.unusable:
            assert not innovation_mask[b, t], f"input rule broken: the unusable measurement at ({b}, {t}) was used"
    skipped = mask.copy()
    for b, t in data.unusable:
        skipped[b, t] = False
    reference = estimator.estimate(np.nan_to_num(z, nan=0.0, posinf=0.0), skipped, dt)  # type: ignore[attr-defined]
    _close(result.means, reference.means, atol, "unusable measurements are skipped (same as masked)")
    rescaled = z.copy()
    rescaled[..., :4] *= 10.0
    _close(estimator.estimate(rescaled, mask, dt).means, result.means, atol,  # type: ignore[attr-defined]
           "measured quaternions are renormalised (their scale changes nothing)")
    flipped = z.copy()
    flipped[..., :4] *= np.where(np.arange(z.shape[1]) % 2 == 0, -1.0, 1.0)[None, :, None]
    other = estimator.estimate(flipped, mask, dt).means  # type: ignore[attr-defined]
    _close(other[..., 4:], result.means[..., 4:], atol, "sign flips change no position, rate or velocity")
    _close(np.abs(other[..., :4]), np.abs(result.means[..., :4]), atol, "sign flips change only the quaternion's sign")
    initialised = getattr(result, "initialised", None)
    if data.late_sequence is not None and initialised is not None:
        first = int(np.flatnonzero(mask[data.late_sequence])[0])
        row = initialised[data.late_sequence]
        assert not row[:first].any() and row[first:].all(), (
            "input rule broken: a sequence reports the prior until its first usable measurement"
        )


GARBAGE_KINDS = (
    "values up to 1e300 in every component",
    "a position jump of 1 m to 1e15 m",
    "a random quaternion scaled by 1e-200 to 1e200",
    "one component NaN, inf or -inf",
    "a zero quaternion",
    "the quaternion's sign flipped",
    "the quaternion scaled by 1e-12",
    "a 1e4 m position outlier",
)
"""What :func:`garbage_measurements` puts in place of a measurement, drawn uniformly."""


def garbage_measurements(
    measurements: ArrayF, mask: ArrayB, rng: np.random.Generator, fraction: float = 0.3
) -> tuple[ArrayF, ArrayB]:
    """``(measurements, mask)`` ``(B, T, 7)``, ``(B, T)`` with a ``fraction`` of the steps
    (measured or not) replaced by garbage of a kind of :data:`GARBAGE_KINDS` drawn uniformly;
    half of the garbage at steps without a measurement is put inside the mask. Copies; the
    inputs are not modified."""
    z, valid = np.array(measurements, dtype=np.float64), np.array(mask, dtype=bool)
    batch, steps, _ = z.shape
    hit = rng.random((batch, steps)) < fraction
    kind = rng.integers(0, len(GARBAGE_KINDS), size=(batch, steps))
    sign = rng.choice([-1.0, 1.0], size=(batch, steps, 7))
    g = z.copy()
    huge = sign * 10.0 ** rng.uniform(-3.0, 300.0, size=(batch, steps, 7))
    g = np.where((kind == 0)[..., None], huge, g)
    jump = sign[..., 4:] * 10.0 ** rng.uniform(0.0, 15.0, size=(batch, steps, 3))
    g[..., 4:] = np.where((kind == 1)[..., None], z[..., 4:] + jump, g[..., 4:])
    scaled = rng.normal(size=(batch, steps, 4)) * 10.0 ** rng.uniform(-200.0, 200.0, size=(batch, steps, 1))
    g[..., :4] = np.where((kind == 2)[..., None], scaled, g[..., :4])
    rows, cols = np.nonzero(kind == 3)
    g[rows, cols, rng.integers(0, 7, size=rows.size)] = rng.choice([np.nan, np.inf, -np.inf], size=rows.size)
    g[..., :4] = np.where((kind == 4)[..., None], 0.0, g[..., :4])
    g[..., :4] = np.where((kind == 5)[..., None], -z[..., :4], g[..., :4])
    g[..., :4] = np.where((kind == 6)[..., None], 1e-12 * z[..., :4], g[..., :4])
    g[..., 4:] = np.where((kind == 7)[..., None], z[..., 4:] + 1e4 * sign[..., 4:], g[..., 4:])
    z = np.where(hit[..., None], g, z)
    valid |= hit & (rng.random((batch, steps)) < 0.5)
    return z, valid


def check_survives_garbage(estimator: object, measurements: ArrayF, mask: ArrayB, dt: float) -> object:
    """Run ``estimator.estimate`` on (garbage) inputs and assert that every output array is
    finite; returns the estimates. Exceptions propagate (the fuzz allows none)."""
    result = estimator.estimate(measurements, mask, dt)  # type: ignore[attr-defined]
    for name in ("means", "covariances", "error_covariances", "innovations", "innovation_covariances"):
        array = getattr(result, name, None)
        if array is not None:
            bad = ~np.isfinite(array)
            assert not bad.any(), f"{name} has {int(bad.sum())} non-finite entries"
    return result


def build_for_checks(name: str, scenario: object = None) -> object:
    """Registered estimator ``name`` built for ``scenario`` (a
    :class:`~fkn_bench.scenarios.Scenario`, default ds1) or, where it does not build there, for
    the first named scenario it builds for (an estimator whose only trained parameters are another
    family's, e.g. ``flexkalmannet-tv``'s of ds1-noise-step): the checks above hold for any input,
    so the estimator's parameters may come from anywhere. Raises the first scenario's error when
    it builds for none."""
    from fkn_bench.estimators import make_estimator
    from fkn_bench.scenarios import get_scenario, scenario_names

    try:
        return make_estimator(name, scenario=scenario if scenario is not None else get_scenario("ds1"))
    except Exception as first:  # noqa: BLE001 - e.g. no trained parameters for ds1's family
        for other in scenario_names():
            try:
                return make_estimator(name, scenario=get_scenario(other))
            except Exception:  # noqa: BLE001
                continue
        raise first
