"""The adaptive filters against their published behaviour, on linear constant-velocity models.

* literal transcriptions of the published recursions (Sage & Husa with forgetting factor;
  Akhlaghi, Zhou & Huang 2017; Huang et al. 2018 Algorithm 1, as in the authors' example code)
  give the same estimates as the batched implementations;
* R converges to the truth (Sage-Husa; VBAKF with its nominal P- trusted);
* started from the true noise, an adaptive filter stays within 5% of the plain KF's RMSE;
* measured limitations are pinned down: VBAKF's R estimate drifts low with the paper's tau = 3,
  and Akhlaghi's Q rule diverges on a constant-velocity model (F != I).
"""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.baselines.adaptive import AdaptiveKalmanFilter
from fkn_bench.baselines.akhlaghi import AkhlaghiRule
from fkn_bench.baselines.sage_husa import SageHusaRule
from fkn_bench.baselines.vbakf import VBAKFRule
from fkn_bench.filters.linear import linear_kalman_filter

pytestmark = pytest.mark.slow(seconds=40)  # runs of 3000 and 5000 steps

P0_STD = np.ones(4)


def _run(cv, rule, z, *, q_std=None, r_std=None):  # noqa: ANN001, ANN202
    f = AdaptiveKalmanFilter(rule, model=cv.torch_model(), q_std=cv.q if q_std is None else q_std, r_std=cv.r if r_std is None else r_std, p0_std=P0_STD)
    return f.run(z, np.ones(z.shape[:2], dtype=bool), dt=cv.dt)


def _kalman_rmse(cv, truth, z, cut):  # noqa: ANN001, ANN202
    """RMSE of the textbook KF with the true noise, initialised like the adaptive filters."""
    means = []
    for b in range(len(z)):
        x0 = np.concatenate((z[b, 0], [0.0, 0.0]))
        m, _ = linear_kalman_filter(cv.A, cv.H, cv.Q, cv.R, x0, np.diag(P0_STD**2), z[b, 1:], np.ones(len(z[b]) - 1, dtype=bool))
        means.append(np.concatenate((x0[None], m)))
    return np.sqrt(((np.array(means) - truth)[:, cut:] ** 2).mean())


# ---------------------------------------------------------------------------- transcriptions
def _sage_husa_reference(cv, z, R0, Q0, b, adapt_q, floor_fraction):  # noqa: ANN001, ANN202
    """Sage-Husa with forgetting factor, written out for one sequence (standard-form update)."""
    x, P = np.concatenate((z[0], [0.0, 0.0])), np.diag(P0_STD**2)
    R, Q = R0.copy(), Q0.copy()
    r_floor, q_floor = floor_fraction * np.diag(R0).min(), floor_fraction * np.diag(Q0).min()

    def clamp(M, floor):  # noqa: ANN001, ANN202
        w, V = np.linalg.eigh(M)
        return M if w.min() >= floor else V @ np.diag(np.maximum(w, floor)) @ V.T

    out = [x]
    for k in range(1, len(z)):
        P_prev = P
        x, P = cv.A @ x, cv.A @ P @ cv.A.T + Q
        nu = z[k] - cv.H @ x
        d = (1 - b) / (1 - b ** (k + 1))
        R = clamp((1 - d) * R + d * (np.outer(nu, nu) - cv.H @ P @ cv.H.T), r_floor)
        K = P @ cv.H.T @ np.linalg.inv(cv.H @ P @ cv.H.T + R)
        x, P = x + K @ nu, (np.eye(4) - K @ cv.H) @ P
        if adapt_q:
            Kn = K @ nu
            Q = clamp((1 - d) * Q + d * (np.outer(Kn, Kn) + P - cv.A @ P_prev @ cv.A.T), q_floor)
        out.append(x)
    return np.array(out), R


def _akhlaghi_reference(cv, z, R0, Q0, alpha):  # noqa: ANN001, ANN202
    """Akhlaghi, Zhou & Huang (2017), written out for one sequence (no floor)."""
    x, P, R, Q = np.concatenate((z[0], [0.0, 0.0])), np.diag(P0_STD**2), R0.copy(), Q0.copy()
    out = [x]
    for k in range(1, len(z)):
        x, P = cv.A @ x, cv.A @ P @ cv.A.T + Q
        d = z[k] - cv.H @ x
        K = P @ cv.H.T @ np.linalg.inv(cv.H @ P @ cv.H.T + R)
        x, P = x + K @ d, (np.eye(4) - K @ cv.H) @ P
        eps = z[k] - cv.H @ x
        R = alpha * R + (1 - alpha) * (np.outer(eps, eps) + cv.H @ P @ cv.H.T)
        Q = alpha * Q + (1 - alpha) * (K @ np.outer(d, d) @ K.T)
        out.append(x)
    return np.array(out), R


def _vbakf_reference(cv, z, R0, Q0, tau, rho, N):  # noqa: ANN001, ANN202
    """Huang et al. (2018) Algorithm 1 as in the authors' published MATLAB example (inverses
    and all), for one sequence."""
    n, m = 4, 2
    x, P = np.concatenate((z[0], [0.0, 0.0])), np.diag(P0_STD**2)
    u, U = m + 1 + tau, tau * R0
    out = [x]
    for k in range(1, len(z)):
        xk1k, Pk1k = cv.A @ x, cv.A @ P @ cv.A.T + Q0
        tk1k, Tk1k = n + 1 + tau, tau * Pk1k
        uk1k, Uk1k = rho * (u - m - 1) + m + 1, rho * U
        x, P = xk1k, Pk1k
        for _ in range(N):
            Ak = np.outer(x - xk1k, x - xk1k) + P
            tkk, Tkk = tk1k + 1, Tk1k + Ak
            E_inv_P = (tkk - n - 1) * np.linalg.inv(Tkk)
            Bk = np.outer(z[k] - cv.H @ x, z[k] - cv.H @ x) + cv.H @ P @ cv.H.T
            u, U = uk1k + 1, Uk1k + Bk
            E_inv_R = (u - m - 1) * np.linalg.inv(U)
            D_P, D_R = np.linalg.inv(E_inv_P), np.linalg.inv(E_inv_R)
            K = D_P @ cv.H.T @ np.linalg.inv(cv.H @ D_P @ cv.H.T + D_R)
            x = xk1k + K @ (z[k] - cv.H @ xk1k)
            P = D_P - K @ cv.H @ D_P
        out.append(x)
    return np.array(out), U / (u - m - 1)


@pytest.mark.parametrize("adapt_q", [False, True])
def test_sage_husa_matches_its_transcription(sensor_limited, adapt_q: bool) -> None:
    cv = sensor_limited
    _, z = cv.simulate(2, 300, seed=3)
    R0, Q0 = np.diag((2 * cv.r) ** 2), np.diag(cv.q**2)
    result = _run(cv, SageHusaRule(forgetting=0.97, adapt_q=adapt_q), z, r_std=2 * cv.r)
    for b in range(2):
        means, R = _sage_husa_reference(cv, z[b], R0, Q0, 0.97, adapt_q, 1e-4)
        np.testing.assert_allclose(result.means[b], means, rtol=0, atol=1e-9)
        np.testing.assert_allclose(result.r_diag[b, -1], np.diag(R), rtol=1e-9)


def test_akhlaghi_matches_its_transcription(balanced) -> None:
    cv = balanced
    _, z = cv.simulate(2, 300, seed=4)
    result = _run(cv, AkhlaghiRule(alpha=0.3, floor=0.0), z)
    for b in range(2):
        means, R = _akhlaghi_reference(cv, z[b], cv.R, cv.Q, 0.3)
        np.testing.assert_allclose(result.means[b], means, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(result.r_diag[b, -1], np.diag(R), rtol=1e-8)


def test_vbakf_matches_the_authors_algorithm(sensor_limited) -> None:
    cv = sensor_limited
    _, z = cv.simulate(2, 300, seed=5)
    R0 = np.diag((3 * cv.r) ** 2)
    result = _run(cv, VBAKFRule(floor=0.0), z, r_std=3 * cv.r)
    for b in range(2):
        means, R = _vbakf_reference(cv, z[b], R0, cv.Q, 3.0, 1.0 - np.exp(-4.0), 10)
        np.testing.assert_allclose(result.means[b], means, rtol=0, atol=1e-9)
        np.testing.assert_allclose(result.r_diag[b, -1], np.diag(R), rtol=1e-8)


# ---------------------------------------------------------------------------- R converges
@pytest.fixture(scope="module")
def long_sensor_limited(sensor_limited):  # noqa: ANN001, ANN201
    return sensor_limited.simulate(4, 5000, seed=0)


def test_sage_husa_r_converges_to_the_truth(sensor_limited, long_sensor_limited) -> None:
    """From R0 = diag(1, 1) (2x and 3.3x the true standard deviations), 5000 steps: with the
    default forgetting factor the R estimate fluctuates around the truth (memory ~100 updates),
    its mean over the last 2000 steps within 10% of each true variance; with b = 0.999 the final
    estimate itself is within 10%."""
    cv = sensor_limited
    _, z = long_sensor_limited
    tail = _run(cv, SageHusaRule(), z, r_std=[1.0, 1.0]).r_diag[:, -2000:].mean(1) / cv.r**2
    assert np.abs(tail - 1).max() < 0.10, tail
    final = _run(cv, SageHusaRule(forgetting=0.999), z, r_std=[1.0, 1.0]).r_diag[:, -1] / cv.r**2
    assert np.abs(final - 1).max() < 0.10, final


def test_vbakf_r_converges_when_the_nominal_prediction_is_trusted(sensor_limited, long_sensor_limited) -> None:
    """With a confident nominal P- (tau_p = 1e6: VB infers R only), R converges to the truth:
    the mean over the last 2000 steps within 10% of each true variance."""
    cv = sensor_limited
    _, z = long_sensor_limited
    tail = _run(cv, VBAKFRule(tau_p=1e6), z, r_std=[1.0, 1.0]).r_diag[:, -2000:].mean(1) / cv.r**2
    assert np.abs(tail - 1).max() < 0.10, tail


def test_vbakf_paper_defaults_drift_below_the_true_r(sensor_limited, long_sensor_limited) -> None:
    """Measured limitation (documented in fkn_bench.baselines.vbakf): with tau_p = 3 the fixed
    point explains large innovations by P- and the R estimate settles well below the truth
    (0.15 to 0.5 of it here), even from the true nominal Q and an overestimated start."""
    cv = sensor_limited
    _, z = long_sensor_limited
    tail = _run(cv, VBAKFRule(), z, r_std=[1.0, 1.0]).r_diag[:, -2000:].mean(1) / cv.r**2
    assert (tail < 0.6).all(), tail


# ---------------------------------------------------------------------------- RMSE vs the KF
@pytest.fixture(scope="module")
def from_the_true_noise(sensor_limited, balanced):  # noqa: ANN001, ANN201
    """``data(setting) -> (cv, truth, z, kf_rmse)``: 8 sequences of 3000 steps (seed 0) of the
    ``sensor_limited`` or ``balanced`` model and the textbook KF's RMSE on them from step 100,
    computed once per model for the tests below."""
    models, cache = {"sensor_limited": sensor_limited, "balanced": balanced}, {}

    def data(setting: str):  # noqa: ANN202
        if setting not in cache:
            cv = models[setting]
            truth, z = cv.simulate(8, 3000, seed=0)
            cache[setting] = (cv, truth, z, _kalman_rmse(cv, truth, z, 100))
        return cache[setting]

    return data


@pytest.mark.parametrize(
    ("setting", "rule"),
    [
        ("sensor_limited", SageHusaRule()),
        ("sensor_limited", VBAKFRule(tau_p=1e6)),
        ("balanced", SageHusaRule()),
        ("balanced", VBAKFRule()),
        ("balanced", AkhlaghiRule(adapt_q=False)),
    ],
    ids=["sage-husa-sensor", "vbakf-nominal-p-sensor", "sage-husa-balanced", "vbakf-balanced", "akhlaghi-r-balanced"],
)
def test_adaptive_filter_from_the_true_noise_stays_near_the_kalman_filter(setting: str, rule, from_the_true_noise) -> None:  # noqa: ANN001
    """Started from the true Q and R, 8 sequences of 3000 steps, scored from step 100: within 5%
    of the textbook KF's RMSE."""
    cv, truth, z, kf = from_the_true_noise(setting)
    adaptive = np.sqrt(((_run(cv, rule, z).means - truth)[:, 100:] ** 2).mean())
    assert adaptive / kf < 1.05, adaptive / kf


def test_measured_limitations_on_the_constant_velocity_model(balanced, from_the_true_noise) -> None:  # noqa: ANN001
    """Pinned down so that they stay visible: from the true noise, VBAKF with the paper's tau_p
    and Akhlaghi's R rule lose >10% on the sensor-limited model, and Akhlaghi's Q rule (exact
    only for F = I: E[K nu nu^T K^T] = P- - P+, not Q) diverges on the balanced one (its literal
    transcription too)."""
    sensor_limited, truth, z, kf = from_the_true_noise("sensor_limited")
    for rule in (VBAKFRule(), AkhlaghiRule(adapt_q=False)):
        assert np.sqrt(((_run(sensor_limited, rule, z).means - truth)[:, 100:] ** 2).mean()) / kf > 1.10
    truth, z = balanced.simulate(2, 3000, seed=0)
    kf = _kalman_rmse(balanced, truth, z, 100)
    ours = np.sqrt(((_run(balanced, AkhlaghiRule(), z).means - truth)[:, 100:] ** 2).mean())
    reference, _ = _akhlaghi_reference(balanced, z[0], balanced.R, balanced.Q, 0.3)
    assert ours / kf > 10 and np.sqrt(((reference - truth[0])[100:] ** 2).mean()) / kf > 10
