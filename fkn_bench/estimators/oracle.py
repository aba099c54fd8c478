"""Noise parameters of the additive pose-twist EKF derived from a scenario's true noise.

The "oracle" reads the ground truth that the filter never sees and measures, in the filter's own
parameterisation, how far reality departs from the filter's model:

* ``sigma_Q``: root mean square, per state component, of the model residual
  ``x_{k+1} - f(x_k)`` along the true trajectory (zero for the paper's exact forced rotation
  except the quaternion's first-order discretisation error; non-zero rates for free tumbling),
  floored at :data:`PROCESS_FLOOR` so ``Q`` stays positive definite;
* ``sigma_R``: root mean square, per component, of ``y_k - h(x_k)`` over the measurements that
  exist, with the measured quaternion sign-aligned to the truth (for ds1 this is
  ``0.1 * sqrt(3/4) / 2`` per quaternion component, the projection of the 0.1 rad error rotation
  onto the unit sphere, and 0.1 m per position axis). Outliers count: they are part of the noise.

Computed on the train split of the scenario's ``dataset_seed`` episode; for an episode-split
scenario (a prior family: every episode its own truth) on the first
:data:`~fkn_bench.scenarios.PRIOR_EPISODES` episodes of its training pool, pooled (one episode's
residuals would be one drawn rate's: a slow one left the oracle sure of a model that fast
tumbles break, and it lost 82% of free-tumble's test episodes).

It is the true noise, not the best tuning: where the model is wrong in a smooth, correlated way
(free tumbling, whose world-frame rate drifts, or the first-order quaternion model at ds2's
rates), a white process noise with the residuals' RMS is too small and the oracle filter is
overconfident (the leaderboard's consistency columns show it).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.scenarios import PRIOR_EPISODES, Scenario
from fkn_bench.types import ArrayF

__all__ = ["oracle_noise", "PROCESS_FLOOR", "model_prediction"]

PROCESS_FLOOR = 1e-7
"""Smallest process-noise standard deviation the oracle reports (per step)."""


def model_prediction(x: ArrayF, dt: float) -> ArrayF:
    """The paper's model ``f`` on ``(..., 13)`` states (numpy): ``q + dt/2 [0, w] (x) q``,
    ``r + dt v``, ``w``, ``v``."""
    out = np.array(x, dtype=float)
    w = x[..., 7:10]
    dq = quat.multiply(np.concatenate((np.zeros(w.shape[:-1] + (1,)), w), axis=-1), x[..., 0:4])
    out[..., 0:4] = x[..., 0:4] + 0.5 * dt * dq
    out[..., 4:7] = x[..., 4:7] + dt * x[..., 10:13]
    return out


@lru_cache(maxsize=32)
def _oracle_noise_cached(scenario: Scenario) -> tuple[tuple[float, ...], tuple[float, ...]]:
    from fkn_bench.envs import generate_episodes

    count = PRIOR_EPISODES if scenario.split_mode == "episodes" else 1  # a prior: many truths, pooled
    episodes = generate_episodes(scenario, [scenario.dataset_seed + i for i in range(count)], split="train")
    truth, measured, valid = episodes.truth, episodes.measurements, episodes.valid
    residual = (truth[:, 1:] - model_prediction(truth[:, :-1], scenario.dt)).reshape(-1, truth.shape[-1])
    truth, measured, valid = truth.reshape(-1, truth.shape[-1]), measured.reshape(-1, 7), valid.reshape(-1)
    q_std = np.maximum(np.sqrt(np.mean(residual**2, axis=0)), PROCESS_FLOOR)
    y, x = measured[valid], truth[valid]
    if len(y) == 0:
        raise ValueError(f"scenario {scenario.name!r} has no measurements in its training split")
    y = y.copy()
    y[:, :4] = quat.align_sign(y[:, :4], x[:, :4])
    r_std = np.sqrt(np.mean((y - x[:, :7]) ** 2, axis=0))
    return tuple(q_std.tolist()), tuple(r_std.tolist())


def oracle_noise(scenario: Scenario) -> tuple[ArrayF, ArrayF]:
    """``(sigma_Q (13,), sigma_R (7,))`` of the additive EKF for ``scenario`` (see module docstring)."""
    q_std, r_std = _oracle_noise_cached(scenario)
    return np.array(q_std), np.array(r_std)
