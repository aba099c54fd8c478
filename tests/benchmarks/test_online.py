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



@pytest.mark.parametrize("name", estimator_names())
def test_online_update_step(benchmark: Any, name: str) -> None:
    """One ``step()`` with a usable measurement (predict + update; the adaptive filters also adapt
    their noise): the per-step latency at a measurement, after 100 steps of ds1 seed 0."""
    try:
        estimator = make_estimator(name, scenario=get_scenario("ds1"))
    except Exception as exc:  # noqa: BLE001 - e.g. learned parameters not committed
        pytest.skip(f"{name} is not available: {exc}")
    z, m, dt = episodes_for("ds1", 1, STEPS)
    estimator.reset(dt=dt)
    for row, ok in zip(z[0, :100], m[0, :100]):
        estimator.step(np.where(ok, row, np.nan))
    observation = z[0, int(np.flatnonzero(m[0])[10])]  # the filter keeps stepping on one pose

    benchmark(lambda: estimator.step(observation))
    benchmark.extra_info.update(steps=1, what=f"{name} step() with a measurement")

def _first_states() -> tuple[Any, ...]:
    """``(dt, Q, R, P0, x0 (13,), measurement (7,))`` of ds1 seed 0 for the one-step benchmarks."""
    from fkn_bench.models import PoseTwistModel

    z, m, dt = episodes_for("ds1", 1, STEPS)
    noise = make_estimator("manual-ekf").noise_parameters()
    Q, R, P0 = (t.numpy() for t in (noise.process, noise.measurement, noise.initial))
    model = PoseTwistModel()
    z0 = model.sanitize(z[0, :1], np.ones(1, dtype=bool))[0]
    measurement = model.sanitize(z[0, int(np.flatnonzero(m[0])[1])][None], np.ones(1, dtype=bool))[0]
    return dt, Q, R, P0, model.initial_state(z0)[0], measurement[0]


def test_online_ekf_predict_update(benchmark: Any) -> None:
    """One predict + update of the EKF step on numpy arrays (batch 1) that the EKF estimators'
    ``step()`` runs: the filter core's online target is measured on this."""
    from fkn_bench.filters import ExtendedKalmanFilter, FilterState

    dt, Q, R, P0, x0, measurement = _first_states()
    ekf, state, z = ExtendedKalmanFilter(), FilterState(x0[None], P0[None]), measurement[None]

    def predict_update() -> Any:
        return ekf.update(ekf.predict(state, Q, dt), z, R)

    benchmark(predict_update)
    benchmark.extra_info.update(steps=1, what="ExtendedKalmanFilter predict + update (numpy, batch 1), one step")


def test_filterpy_ekf_predict_update(benchmark: Any) -> None:
    """The same predict + update with filterpy's ExtendedKalmanFilter (the issue's comparison),
    with the paper's model written out as filterpy expects it (f, F, H = [I7 0], standard form)."""
    from filterpy.kalman import ExtendedKalmanFilter as FilterpyEKF

    dt, Q, R, P0, x0, measurement = _first_states()
    H = np.eye(7, 13)

    def theta(q: np.ndarray) -> np.ndarray:
        w, x, y, zq = q
        return np.array([[-x, -y, -zq], [w, zq, -y], [-zq, w, x], [y, -x, w]])

    def jacobian(x: np.ndarray) -> np.ndarray:
        wx, wy, wz = x[7:10]
        omega = np.array([[0, -wx, -wy, -wz], [wx, 0, -wz, wy], [wy, wz, 0, -wx], [wz, -wy, wx, 0]])
        F = np.eye(13)
        F[0:4, 0:4] += 0.5 * dt * omega
        F[0:4, 7:10] = 0.5 * dt * theta(x[0:4])
        F[4:7, 10:13] = dt * np.eye(3)
        return F

    ekf = FilterpyEKF(dim_x=13, dim_z=7)
    ekf.Q, ekf.R = Q, R

    def predict_update() -> None:
        ekf.x, ekf.P = x0.copy(), P0.copy()
        x = ekf.x
        ekf.F = jacobian(x)
        x_pred = x.copy()
        x_pred[0:4] = x[0:4] + 0.5 * dt * theta(x[0:4]) @ x[7:10]
        x_pred[4:7] = x[4:7] + dt * x[10:13]
        ekf.predict_x = lambda u=0: None  # the mean is propagated above (nonlinear f)
        ekf.x = x_pred
        ekf.predict()
        ekf.update(measurement, HJacobian=lambda _x: H, Hx=lambda state: state[0:7])

    benchmark(predict_update)
    benchmark.extra_info.update(steps=1, what="filterpy ExtendedKalmanFilter predict + update, one step")
