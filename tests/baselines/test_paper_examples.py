"""Each adaptive filter on its own paper's example (issue 21, item 1), through the project's code
path: :class:`~fkn_bench.baselines.adaptive.AdaptiveKalmanFilter` with the method's rule on a
:class:`~fkn_bench.models.linear.LinearGaussianModel` (numpy, batched).

Examples
--------
* **VBAKF** -- Y. Huang, Y. Zhang, Z. Wu, N. Li and J. Chambers (2018), "A novel adaptive Kalman
  filter with inaccurate process and measurement noise covariance matrices", IEEE TAC 63(2),
  594-601, Algorithm 1 and its target-tracking simulation, with the settings of the authors'
  published MATLAB example: 2-D constant velocity, ``x = [px, py, vx, vy]``, ``T = 1 s``,
  ``F = [I T I; 0 I]``, ``H = [I 0]``, ``Q1 = q [T^3/3 I, T^2/2 I; T^2/2 I, T I]`` with ``q = 1``,
  ``R1 = r [1 0.5; 0.5 1]`` with ``r = 100``; true noise ``Q_t = (6.5 + 0.5 cos(pi t / 1000)) Q1``,
  ``R_t = (0.1 + 0.05 cos(pi t / 1000)) R1``; nominal ``Q~ = alpha I4`` (``alpha = 1``, ~7x too
  small) and ``R~ = beta I2`` (``beta = 100``, 7-20x too large); ``tau_P = tau_R = 3``,
  ``rho = 1 - exp(-4)``, ``N = 10``; ``x0 = [100, 100, 10, 10]``, ``P0 = 100 I``; 1000 Monte-Carlo
  runs of 1000 steps, RMSE of position and velocity plotted against time (Figs. 1-2) for the KF
  with the true noise (KFTCM), the KF with the nominal noise (KFNCM) and the proposed filter, and
  the error of the estimated ``R`` (square-root normalised Frobenius norm). The paper's own
  figures and tables were not at hand for this work (no numbers quoted from them); what is
  tested is the ordering the paper and its example state: KFTCM < proposed < KFNCM, the
  proposed filter close to KFTCM, its ``R`` closer to the truth than the nominal one.
* **Sage-Husa** -- A. P. Sage and G. W. Husa (1969), "Adaptive filtering with unknown prior
  statistics", Proc. JACC, 760-769: covariance matching of the innovation, the estimator of ``R``
  given the rest of the model (here with the fading memory ``b`` of :mod:`fkn_bench.baselines.sage_husa`).
  The standard setting of that estimator -- the process model right, ``R`` unknown -- on the
  same tracking model: ``Q`` given as ``6.5 Q1`` (the truth's mean, +-8 %), ``R`` started at
  ``100 I``. Claims: ``R^`` converges to the (slowly varying) true ``R``, and the filter to the
  KF with the true noise.
* **Akhlaghi** -- S. Akhlaghi, N. Zhou and Z. Huang (2017), "Adaptive adjustment of noise
  covariance in Kalman filter for dynamic state estimation", IEEE PES GM (arXiv:1702.00884),
  the innovation-based ``Q`` and residual-based ``R`` rules (``alpha = 0.3``) and the
  simulation: an EKF of a synchronous machine in Kundur's two-area system fed with PMU data,
  compared with the conventional EKF for wrong initial ``Q`` and ``R``; claim (abstract): the
  adaptive filter is "more robust against the initial errors in Q and R". The two-area
  simulation (network, machine and PMU data) is not reproducible from the paper alone; the most
  faithful linear example used here is the linearised swing equation of one machine
  (``delta``, ``omega`` in pu; ``H = 3.5 s``, synchronising coefficient 1.5 pu, damping 2 pu,
  60 Hz, sampled at 30 Hz, both states measured, ``sigma_Q = (1e-3, 1e-5)``, ``sigma_R = (1e-2,
  1e-4)``), started from ``Q`` and ``R`` scaled by 1e-2 or 1e2.

Initialisation: the project's recursion initialises at the first measurement (``x = [z0, 0, 0]``,
``P0``) where the authors draw ``x0 + N(0, P0)``; the reference KFs here are initialised the same
way, so the comparison is like for like, and the scores start after the transient (step 51).

Verdict: the three implementations reproduce their papers' examples (and match literal
transcriptions of the published recursions to 1e-9, test_adaptive_behaviour.py); what fails here
are the methods' own limits, pinned below (Sage-Husa's R runaway when Q is too small, Akhlaghi's
Q rule for F != I). On ds1 (4 test seeds, measured once with the same recursion, not in the
tests) the same limits show: the manual tuning overstates the attitude innovations ~5x (predicted
innovation variance 0.0136-0.0144 against 0.0019-0.0028 measured; position 0.0109 against
0.0099-0.0118), the estimators cut R accordingly, and they lose on position by their known
behaviours: VBAKF's R drifting low (position R^ 0.5-0.6 of the manual value, position RMSE
0.111 m against 0.040 in the last 800 steps), Akhlaghi's one-sample R (alpha = 0.3; 0.163 m),
Sage-Husa's collapse of R after the initialisation (0.141 m in steps 200-800, 0.046 after);
Akhlaghi's Q rule alone (adapt_r=False) has about the manual filter's position error (0.044
against 0.040 m) and a 16x smaller rate error (0.0009 against 0.0145 rad/s); Sage-Husa with a
50-update warm-up matches the manual filter's position error (0.040 m).

Budget: 20 runs of 150 steps (the first 15 % of the paper's 1000-step runs, same time-varying
noise), one seed; the whole module runs in about 1 s. Tolerances are stated per test, with the
measured values.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from fkn_bench.baselines.adaptive import AdaptiveKalmanFilter
from fkn_bench.baselines.akhlaghi import AkhlaghiRule
from fkn_bench.baselines.sage_husa import SageHusaRule
from fkn_bench.baselines.vbakf import VBAKFRule
from fkn_bench.models import LinearGaussianModel

# ------------------------------------------ Huang et al. (2018), target-tracking simulation
T, TS = 1.0, 1000  # sampling period, the paper's run length (in the noise profile)
F = np.block([[np.eye(2), T * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
H = np.eye(2, 4)
Q1 = np.block([[T**3 / 3 * np.eye(2), T**2 / 2 * np.eye(2)], [T**2 / 2 * np.eye(2), T * np.eye(2)]]) * 1.0
R1 = 100.0 * np.array([[1.0, 0.5], [0.5, 1.0]])
X0 = np.array([100.0, 100.0, 10.0, 10.0])
P0_STD = [10.0] * 4  # P0 = 100 I
NOMINAL_Q_STD, NOMINAL_R_STD = [1.0] * 4, [10.0] * 2  # alpha = 1, beta = 100
RUNS, STEPS, SCORED = 20, 150, slice(51, None)


def true_noise(t: int) -> tuple[np.ndarray, np.ndarray]:
    """The paper's ``Q_t``, ``R_t``."""
    return (6.5 + 0.5 * np.cos(np.pi * t / TS)) * Q1, (0.1 + 0.05 * np.cos(np.pi * t / TS)) * R1


def simulate(runs: int, steps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``truth (B, steps + 1, 4)`` and ``measurements (B, steps + 1, 2)`` from ``t = 0``."""
    rng = np.random.default_rng(seed)
    x = np.tile(X0, (runs, 1))
    truth, measured = np.empty((runs, steps + 1, 4)), np.empty((runs, steps + 1, 2))
    for t in range(steps + 1):
        Q, R = true_noise(t)
        if t > 0:
            x = x @ F.T + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(Q).T
        truth[:, t] = x
        measured[:, t] = x @ H.T + rng.standard_normal((runs, 2)) @ np.linalg.cholesky(R).T
    return truth, measured


def reference_kf(z: np.ndarray, noise) -> np.ndarray:  # noqa: ANN001
    """Batched textbook KF with ``noise(t) -> (Q, R)``, initialised like the adaptive filters."""
    runs, steps = z.shape[:2]
    x = np.concatenate((z[:, 0], np.zeros((runs, 2))), 1)
    P = np.broadcast_to(np.diag(np.square(P0_STD)), (runs, 4, 4)).copy()
    means = [x]
    for t in range(1, steps):
        Q, R = noise(t)
        x, P = x @ F.T, F @ P @ F.T + Q
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        x = x + (K @ (z[:, t] - x @ H.T)[:, :, None])[:, :, 0]
        P = P - K @ H @ P
        means.append(x)
    return np.stack(means, 1)


def rmse(means: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Time-averaged position and velocity RMSE over the scored steps (the paper's per-step
    RMSE over Monte-Carlo runs, ``sqrt(mean_runs(|e_pos|^2))``, averaged over time)."""
    error = (means - truth)[:, SCORED]
    per_step = np.sqrt((error[..., :2] ** 2).sum(-1).mean(0)), np.sqrt((error[..., 2:] ** 2).sum(-1).mean(0))
    return float(per_step[0].mean()), float(per_step[1].mean())


def adaptive(rule, z: np.ndarray, *, Q0: np.ndarray | None = None):  # noqa: ANN001, ANN201
    """Run the project's adaptive recursion on the tracking model (nominal noise of the paper,
    or the full matrix ``Q0``)."""
    f = AdaptiveKalmanFilter(rule, model=LinearGaussianModel(F, H), q_std=NOMINAL_Q_STD, r_std=NOMINAL_R_STD, p0_std=P0_STD)
    if Q0 is not None:
        f.Q0 = Q0  # a full (correlated) matrix: q_std only gives diagonal ones
    return f.run(z, np.ones(z.shape[:2], dtype=bool), dt=T)


@pytest.fixture(scope="module")
def tracking():  # noqa: ANN201
    truth, z = simulate(RUNS, STEPS, seed=0)
    kftcm = rmse(reference_kf(z, true_noise), truth)
    kfncm = rmse(reference_kf(z, lambda t: (np.eye(4), 100.0 * np.eye(2))), truth)
    return truth, z, kftcm, kfncm


def test_vbakf_reproduces_huang_2018_target_tracking(tracking) -> None:  # noqa: ANN001
    """Huang et al. (2018) target-tracking simulation, the authors' settings (module
    docstring). Claimed (plots, no numbers at hand): KFTCM < proposed < KFNCM in position and
    velocity RMSE, the proposed filter close to KFTCM, its ``R`` estimate far closer to the truth
    than the nominal one.

    Ours (seed 0, 20 runs, steps 51-150): position 4.43 (KFTCM) < 5.52 (VBAKF) < 9.92 (KFNCM)
    m, velocity 4.15 < 5.27 < 6.26 m/s; over the paper's full 1000 steps (50 runs, measured
    once, not in the test): position 3.67 < 4.01 < 9.68, velocity 3.81 < 4.50 < 6.16, final
    ``R^`` diagonal 4.2 against the true 5.0. Reproduces. Tolerances: VBAKF at most 0.7x KFNCM
    in position (measured 0.56x) and 0.95x in velocity (0.84x), at most 1.45x KFTCM in both
    (1.25x and 1.27x, 1.22x-1.29x for seeds 1-3; 1.09x and 1.18x over 1000 steps: the 150-step
    window still holds the adaptation transient); ``R^`` at step 150 within half the nominal's Frobenius error of the
    truth (measured: 23.9 against 121; its diagonal is still 2x the true 14.5 there)."""
    truth, z, kftcm, kfncm = tracking
    result = adaptive(VBAKFRule(floor=0.0), z)  # the paper's algorithm has no floor
    vb = rmse(result.means, truth)
    assert kftcm[0] < vb[0] <= 0.7 * kfncm[0], (kftcm, vb, kfncm)
    assert kftcm[1] < vb[1] <= 0.95 * kfncm[1], (kftcm, vb, kfncm)
    assert vb[0] <= 1.45 * kftcm[0] and vb[1] <= 1.45 * kftcm[1], (kftcm, vb)
    R_true = true_noise(STEPS)[1]
    R_hat = result.final.noise["U"] / (result.final.noise["u"] - 3.0)[:, None, None]  # U / (u - m - 1)
    error = np.linalg.norm(R_hat - R_true, axis=(1, 2)).mean()
    assert error < 0.5 * np.linalg.norm(100.0 * np.eye(2) - R_true), error


def test_sage_husa_recovers_r_with_the_process_model_right(tracking) -> None:  # noqa: ANN001
    """Sage & Husa (1969) covariance matching of ``R`` (forgetting factor ``b = 0.99``, the
    project's default) on the tracking model with ``Q = 6.5 Q1`` known and ``R`` started at
    ``100 I`` (module docstring). Claims: ``R^ -> R`` and the filter -> the KF with the true
    noise.

    Ours (seed 0, 20 runs): ``R^`` diagonal over the true one, mean over runs, 1.26 at step 50,
    1.02-1.07 over steps 101-150 (1.00-1.19 for seeds 0-5: a small upward bias, the start's
    tail and the eigenvalue clamp); RMSE (steps 51-150) 1.015x KFTCM in position and 1.009x in
    velocity (1.01-1.02x for seeds 1-3), better than the KF with ``Q`` right and ``R = 100 I``
    (1.24x and 1.18x). Reproduces. Tolerances: ``R^`` over steps 101-150 within 25 % of the
    truth; RMSE at most 1.08x KFTCM's in position and velocity and below the KF with the
    starting ``R``."""
    truth, z, kftcm, _ = tracking
    result = adaptive(SageHusaRule(forgetting=0.99), z, Q0=6.5 * Q1)
    true_r = np.array([np.diag(true_noise(t)[1]) for t in range(101, STEPS + 1)])
    ratio = (result.r_diag[:, 101:].mean(0) / true_r).mean(0)  # steps 101-150, mean over runs
    assert np.abs(ratio - 1.0).max() < 0.25, ratio
    sh = rmse(result.means, truth)
    fixed = rmse(reference_kf(z, lambda t: (6.5 * Q1, 100.0 * np.eye(2))), truth)
    assert sh[0] <= 1.08 * kftcm[0] and sh[1] <= 1.08 * kftcm[1], (sh, kftcm)
    assert sh[0] < fixed[0] and sh[1] < fixed[1], (sh, fixed)


def test_innovation_rules_fail_on_huang_2018_nominal_noise(tracking) -> None:  # noqa: ANN001
    """Measured, and the methods' own (not in their papers): on Huang et al.'s example with its
    nominal noise (``Q`` ~7x too small, ``R`` 7-20x too large), the rules that estimate ``R``
    from innovations do worse than not adapting at all.

    * Sage-Husa, ``R`` adapted (``b = 0.99``): the missing process noise shows up in the
      innovations and is booked to ``R``; a larger ``R`` slows the filter, which enlarges the
      innovations: in some runs ``R^`` runs away (here to 1.5e3, position error 61 m at step
      23 in the worst of the 20 runs; 4e4 and 270 m in the worst of 50 runs of another
      simulation). Position RMSE (steps 51-150) 13.4 m against KFNCM's 9.9 (1000 steps, 50
      runs: 10.6 against 9.7; 1.24x-1.6x KFNCM for seeds 1-3).
    * Akhlaghi et al. (``alpha = 0.3``): ``E[K nu nu^T K^T] = P- - P+``, which is ``Q`` only for
      ``F = I``; with a constant-velocity ``F`` the ``Q`` estimate grows without bound and the
      filter diverges (position RMSE 425 m over steps 51-150, 48x-61x KFNCM for seeds 1-3,
      14757 m over 1000 steps). The literal
      transcription does the same (tests/baselines/test_adaptive_behaviour.py).

    Our implementations match their transcriptions to 1e-9 (test_adaptive_behaviour.py), so
    these are the methods' behaviours. Thresholds: Sage-Husa worse than KFNCM in position;
    Akhlaghi more than 5x KFNCM."""
    truth, z, _, kfncm = tracking
    sh = rmse(adaptive(SageHusaRule(forgetting=0.99), z).means, truth)
    assert sh[0] > kfncm[0], (sh, kfncm)
    with np.errstate(over="ignore", invalid="ignore"):
        ak = rmse(adaptive(AkhlaghiRule(alpha=0.3), z).means, truth)
    assert not ak[0] <= 5 * kfncm[0], (ak, kfncm)  # `not <=`: a NaN RMSE counts as diverged


# ------------------------------------------------ Akhlaghi et al. (2017): linear swing example
def test_akhlaghi_is_robust_to_the_initial_noise_on_a_swing_equation() -> None:
    """Akhlaghi et al. (2017) simulation claim, on the linear example of the module docstring:
    the adaptive filter is robust to the initial ``Q`` and ``R`` where the conventional filter
    is not. 8 runs of 300 steps (10 s), scored from step 100, errors normalised by ``sigma_R``.

    Ours (seed 0), RMSE for initial (Q, R) scaled by (1, 1), (1e-2, 1e2), (1e2, 1e-2):
    conventional KF 0.35, 1.05, 0.99; Akhlaghi 0.76, 0.70, 0.77 (over the seven combinations of
    1, 1e-2 and 1e2 for Q and R: Akhlaghi 0.70-0.78, conventional 0.35-1.05; with only one of
    them wrong the adaptive filter wins in two of the four cases).
    Reproduces the robustness claim; not shown in the paper, the price of it: with the right
    noise the adaptive filter is about 2x worse than the conventional one (alpha = 0.3 is a
    memory of about 1.4 samples: the noise estimates are as noisy as single samples).
    Tolerances: the adaptive filter's spread over the three starts within 20 % (measured 11 %;
    4-10 % for seeds 1-3), its worst case below 0.9x the conventional filter's worst (0.74x;
    0.59x-0.74x), below the conventional one for both wrong starts, and above 1.5x it for the
    right start (2.2x; 2.1x-2.2x)."""
    dt, inertia, sync, damping, ws = 1 / 30, 3.5, 1.5, 2.0, 2 * np.pi * 60
    A = expm(np.array([[0.0, ws], [-sync / (2 * inertia), -damping / (2 * inertia)]]) * dt)
    q, r = np.array([1e-3, 1e-5]), np.array([1e-2, 1e-4])
    rng = np.random.default_rng(0)
    x, xs, zs = np.tile([0.1, 0.0], (8, 1)), [], []
    for t in range(300):
        if t:
            x = x @ A.T + rng.standard_normal((8, 2)) * q
        xs.append(x)
        zs.append(x + rng.standard_normal((8, 2)) * r)
    truth, z = np.stack(xs, 1), np.stack(zs, 1)
    model = LinearGaussianModel(A, np.eye(2))

    def score(alpha: float, q_scale: float, r_scale: float) -> float:
        f = AdaptiveKalmanFilter(AkhlaghiRule(alpha=alpha), model=model, q_std=q * np.sqrt(q_scale), r_std=r * np.sqrt(r_scale), p0_std=3 * r)
        means = f.run(z, np.ones(z.shape[:2], dtype=bool), dt=dt).means  # alpha = 1: the plain KF
        return float(np.sqrt((((means - truth)[:, 100:] / r) ** 2).mean()))

    starts = [(1.0, 1.0), (1e-2, 1e2), (1e2, 1e-2)]
    conventional = [score(1.0, *s) for s in starts]
    adapted = [score(0.3, *s) for s in starts]
    assert max(adapted) / min(adapted) < 1.2, adapted
    assert max(adapted) < 0.9 * max(conventional), (adapted, conventional)
    assert all(a < c for a, c in zip(adapted[1:], conventional[1:])), (adapted, conventional)
    assert adapted[0] > 1.5 * conventional[0], (adapted, conventional)  # the price, pinned
