"""Online ``reset()`` + ``step()`` of every registered estimator (unavailable ones are skipped)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from fkn_bench.estimators import estimator_names, make_estimator
from fkn_bench.gates.speed import episodes_for
from fkn_bench.scenarios import get_scenario


STEPS = 400


@pytest.mark.parametrize("name", estimator_names())
def test_online_step(benchmark: Any, name: str) -> None:
    try:
        estimator = make_estimator(name, scenario=get_scenario("ds1"))
    except Exception as exc:  # noqa: BLE001 - e.g. learned parameters not committed
        pytest.skip(f"{name} is not available: {exc}")
    z, m, dt = episodes_for("ds1", 1, STEPS)
    observations = [np.where(ok, row, np.nan) for row, ok in zip(z[0], m[0])]

    def run() -> None:
        estimator.reset(dt=dt)
        for observation in observations:
            estimator.step(observation)

    benchmark.pedantic(run, rounds=5, warmup_rounds=1)
    benchmark.extra_info.update(steps=STEPS, what=f"{name} reset() + step(), ds1 seed 0")


def test_online_ekf_predict_update(benchmark: Any) -> None:
    """One predict + update of the lean numpy EKF (:mod:`fkn_bench.filters.online_ekf`) that the
    EKF estimators' ``step()`` runs: the filter core's online target is measured on this."""
    from fkn_bench.filters import online_ekf

    z, m, dt = episodes_for("ds1", 1, STEPS)
    noise = make_estimator("manual-ekf").noise_parameters()
    Q, R, P0 = (t.numpy() for t in (noise.process, noise.measurement, noise.initial))
    z0 = online_ekf.sanitize_measurement(z[0, 0])
    x0 = online_ekf.initial_state(z0)
    measurement = online_ekf.sanitize_measurement(z[0, int(np.flatnonzero(m[0])[1])])

    def predict_update() -> Any:
        x, P = online_ekf.predict(x0, P0, Q, dt)
        return online_ekf.update(x, P, measurement, R)

    benchmark(predict_update)
    benchmark.extra_info.update(steps=1, what="online_ekf.predict + update (numpy), one step")
