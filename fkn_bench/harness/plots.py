"""Figures in the style of the FlexKalmanNet paper, drawn headless (matplotlib's Agg canvas; no
GUI backend is touched and pyplot's global state is never used).

Quaternions are drawn sign-aligned to the truth (``q`` and ``-q`` are the same attitude).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fkn_bench.geometry import quaternion as quat
from fkn_bench.harness.reference import QuotedRow
from fkn_bench.harness.trace import Trace
from fkn_bench.io import atomic_path
from fkn_bench.metrics import GROUP_UNITS, GROUPS, MetricSettings, group_errors, moving_rms, settling_time
from fkn_bench.types import STATE_GROUPS, STATE_NAMES

__all__ = ["states_figure", "uncertainty_figure", "errors_figure", "comparison_figure", "save_figure"]

_GROUP_TITLES = {
    "attitude": "orientation q (-)",
    "position": "position r (m)",
    "omega": "angular velocity w (rad/s)",
    "velocity": "velocity v (m/s)",
}
_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")


def new_figure(width: float, height: float) -> Figure:
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _aligned(trace: Trace, steps: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    n = len(trace.times) if steps is None else min(int(steps), len(trace.times))
    truth = trace.truth[:n]
    means = np.array(trace.estimates.means[0, :n])
    means[:, 0:4] = quat.align_sign(means[:, 0:4], truth[:, 0:4])
    measured = np.array(trace.measurements[:n])
    ok = trace.valid[:n] & np.all(np.isfinite(measured), axis=1)
    measured[~ok] = np.nan
    measured[ok, 0:4] = quat.align_sign(measured[ok, 0:4], truth[ok, 0:4])
    return trace.times[:n], truth, means, measured, ok


def _title(trace: Trace) -> str:
    return f"{trace.estimator} on {trace.scenario}, seed {trace.seed}"


def states_figure(trace: Trace, *, steps: int | None = None, title: str = "") -> Figure:
    """Estimate (solid), measurement (dots) and truth (dashed) of the four state groups (the paper's
    EKF result figures); ``title`` replaces the default one (estimator, scenario and seed)."""
    times, truth, means, measured, ok = _aligned(trace, steps)
    figure = new_figure(10, 10)
    axes = figure.subplots(4, 1, sharex=True)
    for ax, (group, index) in zip(axes, STATE_GROUPS.items()):
        for k, component in enumerate(range(index.start, index.stop)):
            colour = _COLOURS[k]
            name = STATE_NAMES[component]
            if component < 7:
                ax.plot(times[ok], measured[ok, component], ".", color=colour, alpha=0.35, markersize=3,
                        label=f"{name} measured")
            ax.plot(times, truth[:, component], "--", color=colour, linewidth=1.0, label=f"{name} true")
            ax.plot(times, means[:, component], "-", color=colour, linewidth=1.4, label=f"{name} estimate")
        ax.set_title(_GROUP_TITLES[group], fontsize=10)
        ax.legend(ncol=4, fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    figure.suptitle(title or _title(trace) + ": estimate, measurement and truth")
    return figure


def uncertainty_figure(trace: Trace, *, steps: int | None = None) -> Figure:
    """Each of the 13 components: estimate, truth and the +- 2 sigma band (~95.4%) from the
    estimator's 13x13 state covariance (the paper's uncertainty figure)."""
    times, truth, means, _, _ = _aligned(trace, steps)
    covariances = trace.estimates.covariances
    sigma = (None if covariances is None
             else np.sqrt(np.clip(np.diagonal(covariances[0, : len(times)], axis1=-2, axis2=-1), 0.0, None)))
    figure = new_figure(14, 10)
    axes = figure.subplots(4, 4, sharex=True)
    for row, (group, index) in enumerate(STATE_GROUPS.items()):
        for column in range(4):
            ax = axes[row, column]
            component = index.start + column
            if component >= index.stop:
                ax.axis("off")
                continue
            if sigma is not None:
                ax.fill_between(times, means[:, component] - 2 * sigma[:, component],
                                means[:, component] + 2 * sigma[:, component], color="tab:blue", alpha=0.2,
                                linewidth=0, label="estimate ± 2σ")
            ax.plot(times, truth[:, component], "k--", linewidth=1.0, label="true")
            ax.plot(times, means[:, component], color="tab:blue", linewidth=1.2, label="estimate")
            ax.set_title(STATE_NAMES[component], fontsize=10)
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    figure.suptitle(_title(trace) + ": estimates with 2σ uncertainty bands")
    return figure


def errors_figure(trace: Trace, *, settings: MetricSettings | None = None, steps: int | None = None) -> Figure:
    """Group errors over the run with the settling band and time (:mod:`fkn_bench.metrics.settling`)
    and the unscored transient (before the cut) shaded."""
    settings = settings or MetricSettings()
    errors = group_errors(trace.truth[None], trace.estimates.means)
    n = len(trace.times) if steps is None else min(int(steps), len(trace.times))
    figure = new_figure(10, 10)
    axes = figure.subplots(4, 1, sharex=True)
    for ax, group in zip(axes, GROUPS):
        result = settling_time(errors[group], trace.dt, tolerance=settings.settling_tolerances[group],
                               window=settings.settling_window, peak_fraction=settings.peak_fraction)
        smoothed = moving_rms(errors[group], settings.settling_window)[0]
        t = trace.times[:n]
        ax.plot(t, errors[group][0, :n], color="0.6", linewidth=0.8, label="error")
        ax.plot(t, smoothed[:n], color="tab:blue", linewidth=1.4, label=f"{settings.settling_window}-step moving RMS")
        ax.axhline(result.band[0], color="tab:green", linestyle="--", linewidth=1.0, label="settling band")
        ax.axvspan(0, settings.cut * trace.dt, color="0.9", label="not scored (cut)")
        if result.settled[0]:
            ax.axvline(result.time[0], color="tab:red", linewidth=1.2, label=f"settled at {result.time[0]:.1f} s")
        else:
            ax.text(0.99, 0.9, "never settled", transform=ax.transAxes, ha="right", color="tab:red")
        ax.set_ylabel(f"{group} ({GROUP_UNITS[group]})")
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    figure.suptitle(_title(trace) + ": errors and settling")
    return figure


def comparison_figure(scenario: str, summaries: Sequence[dict[str, Any]], quoted: Sequence[QuotedRow] = ()) -> Figure:
    """Bar chart of the 13-state RMSE per estimator on ``scenario`` (mean over seeds; the line
    spans the interquartile range; diverged shares annotated; quoted paper rows hatched)."""
    labels = [s["estimator"] for s in summaries] + [q.label for q in quoted]
    values = [s["state_rmse"] for s in summaries] + [q.state_rmse for q in quoted]
    figure = new_figure(max(6.0, 1.2 * len(labels) + 2), 5)
    ax = figure.subplots()
    x = np.arange(len(labels))
    bars = ax.bar(x, np.nan_to_num(np.asarray(values, dtype=float), nan=0.0), color="tab:blue")
    for bar in bars[len(summaries):]:
        bar.set_facecolor("white")
        bar.set_edgecolor("tab:gray")
        bar.set_hatch("//")
    for i, s in enumerate(summaries):
        st = s["statistics"]["state_rmse"]
        if np.isfinite(st["q25"]) and np.isfinite(st["q75"]):
            ax.plot([i, i], [st["q25"], st["q75"]], color="black", linewidth=2)
        if s["diverged_fraction"] and s["diverged_fraction"] > 0:
            ax.annotate(f"{100 * s['diverged_fraction']:.0f}% diverged", (i, values[i]), ha="center",
                        va="bottom", fontsize=8, color="tab:red", xytext=(0, 3), textcoords="offset points")
    ax.set_xticks(x, labels, rotation=20, ha="right")
    ax.set_ylabel("13-state RMSE (mean over seeds; line: IQR)")
    ax.set_title(f"{scenario}: estimators compared (lower is better)")
    ax.grid(axis="y", alpha=0.3)
    return figure


def save_figure(figure: Figure, path: str | Path, *, dpi: int = 120) -> Path:
    """Write ``figure`` as PNG atomically; returns the path."""
    with atomic_path(path, suffix=".png") as tmp:
        figure.savefig(tmp, format="png", dpi=dpi)
    return Path(path)
