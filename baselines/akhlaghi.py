"""Adaptive EKF of Akhlaghi, Zhou & Huang (2017) (``akhlaghi``).

S. Akhlaghi, N. Zhou and Z. Huang (2017), "Adaptive adjustment of noise covariance in Kalman
filter for dynamic state estimation", IEEE PES General Meeting (arXiv:1702.00884). After the
ordinary update with the previous ``R`` and ``Q``, both are moved towards one-sample estimates
with weight ``1 - alpha``:

    eps_k = z_k - H x+_k                                     (residual, after the update)
    R_k   = alpha R_{k-1} + (1 - alpha) (eps_k eps_k^T + H P+_k H^T)
    Q_k   = alpha Q_{k-1} + (1 - alpha) K_k nu_k nu_k^T K_k^T   (nu_k = z_k - H x-_k)

``R_k`` serves the next update and ``Q_k`` the next prediction. The residual form of ``R`` is
the paper's: ``E[eps eps^T] = R - H P+ H^T`` for an optimal filter, so the sample adds only
positive semi-definite terms (unlike Sage-Husa's innovation form). The measured quaternion is
aligned with the prediction before ``nu`` and ``eps`` are formed.

Floor: the rank-one samples and a short memory can leave ``R`` or ``Q`` nearly singular, so every
update also adds ``(1 - alpha) f I`` with ``f = floor`` times the smallest starting diagonal
entry (1e-4 by default: a standard deviation 1 % of the smallest starting one); by induction
``R_k >= f I`` and ``Q_k >= f I`` whenever they start there. With measurements every ``M``
prediction steps the process-noise sample is ``K nu nu^T K^T / M`` (see
:mod:`fkn_bench.baselines.adaptive`; ``M = 1`` is the paper's rule).

Known behaviour (measured; see the tests): the ``Q`` rule is exact only for ``F = I``
(``E[K nu nu^T K^T] = P- - P+``, which is ``Q`` for a random walk but not for a constant-velocity
model), and on a linear constant-velocity model it diverges, its literal transcription too. On
the pose model a gross outlier inflates ``R`` through the residual; the sluggish filter's own
error then keeps the residual, and ``R``, large: on ds1-flips (1% outliers) the estimate drifts
tens of degrees and metres off for long stretches (finite and positive definite throughout).
With ``R`` fixed (``adapt_r=False``) the ``Q`` rule alone does well on ds1.

Defaults: ``alpha = 0.3`` (the paper's value), both ``R`` and ``Q`` adapted (the paper's method;
``adapt_r`` / ``adapt_q`` switch either off), starting noise the paper's manual tuning.
``alpha = 1`` freezes the noise: the filter is then the manually tuned EKF.
"""

from __future__ import annotations

import numpy as np

from fkn_bench.baselines import adaptive as ad
from fkn_bench.types import ArrayF

__all__ = ["AkhlaghiRule", "AkhlaghiEstimator"]


class AkhlaghiRule(ad.NoiseRule):
    """Akhlaghi-Zhou-Huang noise adaptation (see module docstring).

    Args:
        alpha: weight of the previous estimate, in [0, 1] (paper: 0.3).
        adapt_r, adapt_q: adapt ``R`` / ``Q`` (both True by default).
        floor: eigenvalue floor as a fraction of the smallest starting diagonal entry.
    """

    name = "akhlaghi"
    knobs = ("alpha", "adapt_r", "adapt_q", "floor")

    def __init__(self, *, alpha: float = 0.3, adapt_r: bool = True, adapt_q: bool = True, floor: float = 1e-4) -> None:
        self.alpha = ad.check_range("alpha", alpha, closed_low=True)
        self.adapt_r, self.adapt_q = ad.check_flag("adapt_r", adapt_r), ad.check_flag("adapt_q", adapt_q)
        self.adapts_q = self.adapt_q
        self.floor = ad.check_range("floor", floor, high=1.0, closed_high=False, closed_low=True)
        if not (self.adapt_q or self.adapt_r):
            raise ValueError("adapt_q and adapt_r are both false: a filter that adapts neither Q nor R is the plain EKF "
                             "with its starting noise (manual-ekf, or q_std/r_std of a Kalman estimator), not this method")

    def initial(self, batch: int, Q0: ArrayF, R0: ArrayF) -> ad.Noise:
        return {
            **super().initial(batch, Q0, R0),
            "r_floor": ad.batched(ad.floor_from(R0, self.floor) * np.eye(len(R0)), batch),
            "q_floor": ad.batched(ad.floor_from(Q0, self.floor) * np.eye(len(Q0)), batch),
        }

    def update(self, ctx: ad.UpdateContext, noise: ad.Noise) -> tuple[ad.KalmanUpdate, ad.Noise]:
        result = ad.kalman_update(ctx.model, ctx.x_pred, ctx.P_pred, ctx.nu, noise["R"])
        a = self.alpha
        R, Q = noise["R"], noise["Q"]
        # R and Q stay exactly symmetric: weighted sums of symmetric matrices (R, Q, the floors,
        # the symmetrised P+ block) and outer products a a^T (a_i a_j == a_j a_i)
        if self.adapt_r and a < 1.0:
            residual = ctx.z - ctx.model.measure(result.x)
            sample = ad.outer(residual) + ad.projected_covariance(ctx.model, result.P) + noise["r_floor"]
            R = a * R + (1.0 - a) * sample
        if self.adapt_q and a < 1.0:
            correction = (result.K @ ctx.nu[:, :, None])[:, :, 0]
            Q = a * Q + (1.0 - a) * (ad.outer(correction) / ctx.steps[:, None, None] + noise["q_floor"])
        return result, {**noise, "R": R, "Q": Q}


class AkhlaghiEstimator(ad.AdaptiveEKFEstimator):
    """``akhlaghi``: the paper's additive EKF with Akhlaghi-Zhou-Huang adaptation (module docstring)."""

    name = "akhlaghi"
    description = "Adaptive EKF of Akhlaghi, Zhou & Huang 2017 (alpha 0.3: residual-based R, innovation-based Q)"
    rule_class = AkhlaghiRule
