"""The committed-results gate, split in two halves that pytest-xdist (``--dist loadfile``) runs on
its two workers: ``test_accuracy_gate.py`` gates the estimators of the paper's constant-rate model
(and runs the checks over the whole registry: orphans, coverage), ``test_accuracy_gate_rigid_body.py``
the estimators on the rigid-body model. Each half's report is a session fixture, built on the
worker that runs its file.

Every estimator is gated on part of the named scenarios (:data:`GATED_ON`): ``manual-ekf`` gates
the EKF and the measurement stream's shared handling (dropouts, gaps, sign flips, noise) on every
scenario but the prior families' stress variants (:data:`PRIOR_STRESS`: their family's truths with
ds1's variants' streams, both gated); every committed file of the prior families (``spin``,
``free-tumble``) is gated once, on its family's headline scenario; the UKF and MEKF are gated on :data:`STREAM_SCENARIOS`, the
adaptive filters' code (their papers' settings, ``*-default``) on its three stream variants and
their tuned settings once per committed file; the rigid-body EKF (known and estimated inertia) on ds1 and two free
tumbles, FlexKalmanNet on it once per committed parameter file, the rigid-body UKF and MEKF on two
free tumbles (the rigid-body model's prediction is the same code in every filter); every free
tumble is gated by at least one rigid-body estimator. The learned-gain networks are gated once per
committed weights file (ds1, ds2, and tumble-fast for the tumble mixture's; spin and free-tumble
for the prior families'; 2-6 s a pair), and
KalmanNet also on the two scenarios that exercise its recursion's own handling of the stream
(ds1-gap100: long predictions; ds1-flips: sign-flipped quaternions and outliers), which Recursive
KalmanNet shares. The EKFs with committed parameter files (FlexKalmanNet's, the tuned ones) are
gated once per file (ds1, ds2, tumble-fast), the oracle EKF on four scenarios of distinct noise:
the EKF itself is gated on every scenario by ``manual-ekf``, and the adaptive filters, UKF and
MEKF by their own entries. The files of the ds1-noise-step family (the tuned adaptive settings,
FlexKalmanNet's constant and time-varying networks, the tuned EKFs, KalmanNet) are gated there
once each, every ``-gated`` variant once on ds1-flips, where its gate acts, the model-matched oracle
and its smoother on spin. (The gate's cost is the batched filters'
per-step overhead: about 1.5 s per pair on the rigid-body model, nearly the same for one seed or
two; gating all 70 of their pairs took 175 s of the test command's 300.)
"""

from __future__ import annotations

from pathlib import Path

import pytest

from fkn_bench.gates import accuracy
from fkn_bench.scenarios import PRIOR_FAMILIES, scenario_names

RESULTS = Path(__file__).resolve().parents[2] / "leaderboards" / "results"

EXCLUDED: dict[str, str] = {}
"""Estimators the gate leaves out on purpose, ``{name: reason}`` (README, "Add your estimator to
the gates"). Everything else that is registered and builds for a scenario must have committed
results for it."""

FREE_TUMBLES = ("tumble-fast", "tumble-flip", "tumble-slow", "tumble-inertia-error")
STREAM_SCENARIOS = ("ds1", "ds1-noise5x", "ds1-gap100", "ds1-flips", "tumble-fast")
"""ds1 and the variants whose measurement stream differs most (5x noise, 100-step gaps, sign flips
and outliers), and a free tumble: where a filter variant's own handling of the stream is gated."""

PRIOR_HEADLINES = tuple(PRIOR_FAMILIES)
"""The prior families' headline scenarios (spin, free-tumble): where their committed files are gated."""
PRIOR_STRESS = tuple(name for names in PRIOR_FAMILIES.values() for name in names[1:])
"""The prior families' stress variants, not gated: each is its family's truths (gated on the
headline) with the measurement stream of one of ds1's variants (noise x5, 100-step gaps, dropout,
flips and outliers, a noise step: gated there), and ten more manual-ekf pairs of 3000 steps cost 7 s
of the test command's 300."""

GATED_ON = {
    "rigid-body-ekf": ("ds1", "tumble-slow", "tumble-flip"),
    "rigid-body-ekf-ratios": ("ds1", "tumble-fast", "tumble-inertia-error"),
    "flexkalmannet-rigid-body": ("ds1", "ds2", "tumble-fast"),  # once per committed parameter file
    **{name: ("tumble-fast", "tumble-flip") for name in ("rigid-body-ukf", "rigid-body-ukf-ratios", "rigid-body-mekf", "rigid-body-mekf-ratios")},
    **{name: STREAM_SCENARIOS for name in ("manual-ukf", "manual-mekf")},
    # the adaptive filters: their code on the stream variants (the papers' settings), and each
    # committed file of tuned settings once (ds1, ds2, tumble-fast for the tumble family's)
    **{f"{name}-default": ("ds1-noise5x", "ds1-gap100", "ds1-flips") for name in ("sage-husa", "akhlaghi", "vbakf")},
    **{name: ("ds1", "ds2", "tumble-fast") for name in ("sage-husa", "akhlaghi", "vbakf")},
    "kalmannet": ("ds1", "ds2", "ds1-gap100", "ds1-flips", "tumble-fast"),
    "recursive-kalmannet": ("ds1", "ds2", "tumble-fast"),
    # the EKF with a committed parameter file per family: the filter is gated on every scenario
    # by manual-ekf, so each file once, on its family's scenario (ds1's file runs on ds1 and its
    # four variants; the tumble file on the three tumbles)
    **{name: ("ds1", "ds2", "tumble-fast") for name in ("flexkalmannet", "nll-tuned-ekf", "direct-tuned-ekf")},
    # the EKF with each scenario's true noise: the noise differs between ds1 and its noisier variant
    "oracle-ekf": ("ds1", "ds2", "ds1-noise5x", "tumble-fast"),
    # the time-varying FlexKalmanNet: its one committed network, on its family's scenario
    "flexkalmannet-tv": ("ds1-noise-step",),
    # the -gated variants: their base's code with the gate, where the gate acts (the gate's code is
    # the Kalman filters' or the adaptive filters' own: each variant once)
    **{f"{name}-gated": ("ds1-flips",) for name in ("manual-ekf", "flexkalmannet", "sage-husa", "akhlaghi", "vbakf")},
    # the model-matched references on spin: their own code (the prior-matched P0, the noise
    # schedule, the backward pass) is model-free; the MEKF on the rigid body is gated by
    # rigid-body-mekf-ratios, and oracle-matched on free-tumble would add 6 s
    "oracle-matched": ("spin",),
    "smoother-matched": ("spin",),
}
for _name in ("flexkalmannet", "nll-tuned-ekf", "direct-tuned-ekf", "sage-husa", "akhlaghi", "vbakf", "kalmannet"):
    GATED_ON[_name] += ("ds1-noise-step",)  # the committed files of the ds1-noise-step family, once each
for _name in ("flexkalmannet", "flexkalmannet-rigid-body", "flexkalmannet-tv", "nll-tuned-ekf", "direct-tuned-ekf",
              "sage-husa", "akhlaghi", "vbakf", "kalmannet", "recursive-kalmannet"):
    GATED_ON[_name] += PRIOR_HEADLINES  # the committed files of the prior families, once each
for _name in ("split-kalmannet", "cholesky-kalmannet"):  # trained on ds1 and the prior families, so far
    GATED_ON[_name] = ("ds1",) + PRIOR_HEADLINES
GATED_ON["manual-ekf"] = tuple(name for name in scenario_names() if name not in PRIOR_STRESS)

"""The estimators on the rigid-body model, and Recursive KalmanNet, are gated on part of the named
scenarios (module docstring)."""


def _rigid_body(name: str) -> bool:
    return name.startswith("rigid-body-")


def _in_half(name: str, path: Path) -> bool:
    """Whether the gate file ``path`` gates estimator ``name``."""
    return name not in EXCLUDED and _rigid_body(name) == path.name.endswith("_rigid_body.py")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """``gated_estimator``: every registered estimator of the test file's half of the gate."""
    if "gated_estimator" in metafunc.fixturenames:
        from fkn_bench.estimators import estimator_names

        metafunc.parametrize("gated_estimator", [n for n in estimator_names() if _in_half(n, metafunc.definition.path)])


@pytest.fixture(scope="session")
def constant_rate_report() -> accuracy.AccuracyReport:
    """The gate over every registered estimator but the rigid-body ones (orphans checked too)."""
    from fkn_bench.estimators import estimator_names

    others = {n: "gated by test_accuracy_gate_rigid_body.py" for n in estimator_names() if _rigid_body(n)}
    report = accuracy.run_accuracy_gate(RESULTS, exclude={**EXCLUDED, **others}, scenarios_of=GATED_ON)
    print("\n" + report.summary())
    return report


@pytest.fixture(scope="session")
def rigid_body_report() -> accuracy.AccuracyReport:
    """The gate over the rigid-body estimators (the UKF/MEKF combinations on the free tumbles)."""
    from fkn_bench.estimators import estimator_names

    names = [n for n in estimator_names() if _rigid_body(n) and n not in EXCLUDED]
    report = accuracy.run_accuracy_gate(RESULTS, estimators=names, scenarios_of=GATED_ON)
    print("\n" + report.summary())
    return report


def check_estimator(report: accuracy.AccuracyReport, estimator: str) -> None:
    """Pass, skip (the estimator builds for no named scenario) or fail with the gate's message."""
    compared = [c for c in report.compared if c[0] == estimator]
    if not compared and not report.problems_of(estimator):
        reasons = sorted({reason for name, _, reason in report.skipped if name == estimator})
        pytest.skip(f"{estimator} builds for no named scenario ({'; '.join(reasons)})")
    assert report.passed(estimator), report.message(estimator)


@pytest.fixture
def free_tumbles() -> tuple[str, ...]:
    """:data:`FREE_TUMBLES`, for the test files (which cannot import this module)."""
    return FREE_TUMBLES


@pytest.fixture
def gate_check():
    """:func:`check_estimator`, for the test files (which cannot import this module)."""
    return check_estimator
