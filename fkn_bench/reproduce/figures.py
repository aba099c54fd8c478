"""The figures of the paper's results section, drawn headless into the report directory.

The pipeline draws the other figures with the project's figure functions: the two training
figures of :mod:`fkn_bench.training.plots` (loss curves, the 20 learned standard deviations
over epochs) and the state figure of :mod:`fkn_bench.reporting.plots` (estimate, measurement and
truth of the four state groups). :func:`omega_uncertainty_figure` is the paper's uncertainty
figure: the three angular-rate components with the estimate's 2-sigma band over the first samples
of a run.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from fkn_bench.harness.trace import Trace
from fkn_bench.plotting import legend_beside, new_figure
from fkn_bench.types import OMEGA, STATE_NAMES

__all__ = ["omega_sigma", "omega_uncertainty_figure"]


def omega_sigma(trace: Trace, steps: int | None = None) -> np.ndarray:
    """``(T, 3)`` standard deviations of the angular-rate error (from the 12-dim error covariance,
    ``dw`` block; the state covariance's rate block when only that is reported)."""
    n = len(trace.times) if steps is None else min(int(steps), len(trace.times))
    estimates = trace.estimates
    if estimates.error_covariances is not None:
        variances = np.diagonal(estimates.error_covariances[0, :n], axis1=-2, axis2=-1)[:, 6:9]
    elif estimates.covariances is not None:
        variances = np.diagonal(estimates.covariances[0, :n], axis1=-2, axis2=-1)[:, OMEGA]
    else:
        return np.full((n, 3), np.nan)
    return np.sqrt(np.clip(variances, 0.0, None))


def omega_uncertainty_figure(trace: Trace, *, steps: int = 500, title: str = "") -> Figure:
    """Angular-rate estimate, truth and ``estimate +- 2 sigma`` (rad/s) over time (s) for the first
    ``steps`` samples (the paper's figure of the uncertainties of the angular-rate estimates,
    2 sigma ~ 95.4%); the legend beside the top panel."""
    n = min(int(steps), len(trace.times))
    times = trace.times[:n]
    means = trace.estimates.means[0, :n, OMEGA]
    truth = trace.truth[:n, OMEGA]
    sigma = omega_sigma(trace, n)
    figure = new_figure(8, 7.5)
    axes = figure.subplots(3, 1, sharex=True)
    # one half-width for the three axes, around each axis' true rate: the band starts wide (P0)
    half = max(0.1, 2.0 * float(np.nanmax(np.abs(truth)))) if n else 0.1
    for k, ax in enumerate(axes):
        ax.fill_between(times, means[:, k] - 2 * sigma[:, k], means[:, k] + 2 * sigma[:, k], color="tab:blue",
                        alpha=0.2, linewidth=0, label="estimate ± 2σ")
        ax.plot(times, truth[:, k], "k--", linewidth=1.0, label="true x")
        ax.plot(times, means[:, k], color="tab:blue", linewidth=1.3, label="estimate x̂")
        ax.set_ylabel(f"{STATE_NAMES[OMEGA.start + k]} (rad/s)")
        centre = float(np.nanmean(truth[:, k])) if n else 0.0
        ax.set_ylim(centre - half, centre + half)
        ax.grid(alpha=0.3)
    legend_beside(axes[0], fontsize=8)
    axes[-1].set_xlabel(f"time (s); first {n} samples")
    figure.suptitle(title or f"{trace.estimator} on {trace.scenario}, seed {trace.seed}: angular-rate uncertainty")
    return figure

