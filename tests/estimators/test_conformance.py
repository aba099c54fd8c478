"""Every registered estimator follows the estimator API's input rules
(:func:`fkn_bench.estimators.conformance.check_input_rules`), and the checker catches an
estimator that does not."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.estimators import estimator_names, make_estimator
from fkn_bench.estimators.conformance import check_input_rules, hostile_measurements
from fkn_bench.scenarios import get_scenario


@pytest.fixture(scope="module")
def hostile():  # noqa: ANN201
    return hostile_measurements()


@pytest.mark.parametrize("name", estimator_names())
def test_registered_estimator_follows_the_input_rules(name: str, hostile) -> None:
    try:
        estimator = make_estimator(name, scenario=get_scenario("ds1"))
    except Exception as exc:  # noqa: BLE001 - e.g. a third-party estimator without ds1 parameters
        pytest.skip(f"{name} does not build for ds1: {exc}")
    check_input_rules(estimator, hostile)


class _ZeroFilled:
    """Wraps an estimator and "repairs" non-finite measurement values to zero before filtering,
    so that a measurement with a NaN component is used instead of skipped (a broken rule)."""

    def __init__(self, inner) -> None:  # noqa: ANN001
        self.inner = inner

    def estimate(self, z, mask, dt):  # noqa: ANN001, ANN201
        return self.inner.estimate(np.nan_to_num(np.asarray(z), nan=0.0, posinf=0.0, neginf=0.0), mask, dt)


def test_the_checker_names_the_broken_rule(hostile) -> None:
    with pytest.raises(AssertionError, match="unusable measurement at"):
        check_input_rules(_ZeroFilled(make_estimator("manual-ekf")), hostile)
