"""Sage-Husa adaptive EKF with a forgetting factor (``sage-husa``).

A. P. Sage and G. W. Husa (1969), "Adaptive filtering with unknown prior statistics", Proc.
Joint Automatic Control Conference, pp. 760-769: covariance matching of the innovation. The
fading-memory form used here (the common "Sage-Husa with forgetting factor" formulation, e.g.
the improved Sage-Husa filters of the integrated-navigation literature) weights the sample of update ``i`` by ``b^(k-i)``:

    d_k = (1 - b) / (1 - b^(k+1))
    R_k = (1 - d_k) R_{k-1} + d_k (nu_k nu_k^T - H P-_k H^T)          (before the gain)
    Q_k = (1 - d_k) Q_{k-1} + d_k (K_k nu_k nu_k^T K_k^T + P+_k - F P+_{k-1} F^T)   (optional)

with innovation ``nu_k = z_k - H x-_k`` (after the quaternion sign alignment). ``R_k`` is
estimated first and used in the same step's gain; ``Q_k`` after the update, for the next
prediction. ``k`` counts measurement updates from 1 (the initialising measurement is ``k = 0``),
so the starting ``R`` weighs as one sample: with ``b = 1`` the rule is the running mean of the
starting value and the ``k`` samples, the original unbiased estimator.

Positive definiteness: ``nu nu^T - H P- H^T`` is indefinite, and so can ``R_k`` become (the
method's known weakness). After every adaptation the eigenvalues of ``R`` (and ``Q``) are clamped
to at least ``floor`` times the smallest diagonal entry of the starting matrix (1e-4 by default:
1e-6 for the pose model's ``R``, a 1 mm / 0.001 standard deviation), the nearest positive
definite matrix in the Frobenius norm. With measurements every ``M`` prediction steps the
process-noise sample is ``Q_{k-1} + (K nu nu^T K^T + P+ - P-) / M`` (with ``M = 1`` exactly
``K nu nu^T K^T + P+ - F P+ F^T``; see :mod:`fkn_bench.baselines.adaptive`).

Defaults: ``forgetting = 0.99`` (the usual range is 0.95-0.995: a memory of about 100 updates,
long enough for a stationary noise, short enough to follow changes), ``R`` adapted, ``Q`` fixed
(joint ``Q`` and ``R`` covariance matching is not identifiable in general and is the variant that
diverges in the literature; ``adapt_q=True`` turns it on), adaptation from the first update
(``warmup = 0``). Starting noise: the paper's manual tuning.

Known behaviour (measured): the sample ``nu nu^T - H P- H^T`` is unbiased only when ``P-`` is
right. Just after the initialisation ``P-`` is dominated by the deliberately conservative ``P0``
(0.2 rad/s on the rates), the samples are strongly negative, and the clamped ``R`` collapses to
the floor in most directions at the first update; the filter then follows the measurements until
``R`` is rebuilt (some 50 updates on ds1). ``warmup = W`` holds the noise at its starting values
for the first ``W`` updates, the usual practical remedy (not part of the published method).
"""

from __future__ import annotations

import numpy as np

from fkn_bench.baselines import adaptive as ad
from fkn_bench.types import ArrayF

__all__ = ["SageHusaRule", "SageHusaEstimator"]


class SageHusaRule(ad.NoiseRule):
    """Sage-Husa covariance matching with forgetting factor (see module docstring).

    Args:
        forgetting: ``b`` in (0, 1]; 1 is the unweighted running mean.
        adapt_r: estimate ``R`` (default True).
        adapt_q: estimate ``Q`` too (default False).
        floor: eigenvalue floor as a fraction of the smallest starting diagonal entry.
        warmup: updates with the starting noise before the adaptation begins (default 0).
    """

    name = "sage-husa"
    knobs = ("forgetting", "adapt_r", "adapt_q", "floor", "warmup")

    def __init__(
        self, *, forgetting: float = 0.99, adapt_r: bool = True, adapt_q: bool = False, floor: float = 1e-4, warmup: int = 0
    ) -> None:
        self.forgetting = ad.check_range("forgetting", forgetting)
        self.adapt_r, self.adapt_q = ad.check_flag("adapt_r", adapt_r), ad.check_flag("adapt_q", adapt_q)
        self.adapts_q = self.adapt_q
        self.floor = ad.check_range("floor", floor, high=1.0, closed_high=False)
        if not (self.adapt_q or self.adapt_r):
            raise ValueError("adapt_q and adapt_r are both false: a filter that adapts neither Q nor R is the plain EKF "
                             "with its starting noise (manual-ekf, or q_std/r_std of a Kalman estimator), not this method")
        self.warmup = ad.check_int("warmup", warmup, 0)

    def weight(self, k: ArrayF) -> ArrayF:
        """``d_k`` for update counts ``k (B,)`` (>= 1)."""
        b = self.forgetting
        if b == 1.0:
            return 1.0 / (k + 1.0)
        return (1.0 - b) / (1.0 - b ** (k + 1.0))

    def initial(self, batch: int, Q0: ArrayF, R0: ArrayF) -> ad.Noise:
        return {
            **super().initial(batch, Q0, R0),
            "k": np.full(batch, -float(self.warmup)),
            "r_floor": np.full(batch, ad.floor_from(R0, self.floor)),
            "q_floor": np.full(batch, ad.floor_from(Q0, self.floor)),
        }

    def update(self, ctx: ad.UpdateContext, noise: ad.Noise) -> tuple[ad.KalmanUpdate, ad.Noise]:
        k = noise["k"] + 1.0  # adapted samples so far (<= 0 during the warm-up: d = 0)
        d = np.where(k >= 1.0, self.weight(np.maximum(k, 1.0)), 0.0)[:, None, None]
        R, Q = noise["R"], noise["Q"]
        if self.adapt_r:
            # sums of exactly symmetric terms; clamp_eigenvalues symmetrises what it rebuilds
            sample = ad.outer(ctx.nu) - ad.projected_covariance(ctx.model, ctx.P_pred)
            R = ad.clamp_eigenvalues((1.0 - d) * R + d * sample, noise["r_floor"])
        result = ad.kalman_update(ctx.model, ctx.x_pred, ctx.P_pred, ctx.nu, R)
        if self.adapt_q:
            correction = (result.K @ ctx.nu[:, :, None])[:, :, 0]
            # exactly symmetric: an outer product plus the symmetrised P+ and P- (no symmetrisation needed)
            excess = (ad.outer(correction) + result.P - ctx.P_pred) / ctx.steps[:, None, None]
            Q = ad.clamp_eigenvalues((1.0 - d) * Q + d * (Q + excess), noise["q_floor"])
        return result, {**noise, "R": R, "Q": Q, "k": k}


class SageHusaEstimator(ad.AdaptiveEKFEstimator):
    """``sage-husa``: the paper's additive EKF with Sage-Husa noise adaptation (module docstring)."""

    name = "sage-husa"
    description = "Sage-Husa adaptive EKF (forgetting factor 0.99, R adapted, eigenvalue clamping)"
    rule_class = SageHusaRule
