"""Figures in the style of the FlexKalmanNet paper, drawn headless in the house style of
:mod:`fkn_bench.plotting` (Agg canvas, legends outside the data, units on every axis).

Quaternions are drawn sign-aligned to the truth (``q`` and ``-q`` are the same attitude).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from fkn_bench.geometry import quaternion as quat
from fkn_bench.harness.ratios import RatioConvergence
from fkn_bench.harness.trace import Trace
from fkn_bench.metrics import GROUP_UNITS, GROUPS, MetricSettings, group_errors, moving_rms, settling_time
from fkn_bench.plotting import STATE_RMSE_UNIT, legend_below, legend_beside, new_figure, save_png
from fkn_bench.reporting.figures import write_png
from fkn_bench.reporting.reference import QuotedRow
from fkn_bench.types import STATE_GROUPS, STATE_NAMES

__all__ = ["states_figure", "uncertainty_figure", "errors_figure", "ratio_figure", "COMPARISON_DIGITS", "comparison_data",
           "comparison_figure", "comparison_chart", "save_figure", "new_figure"]

_GROUP_LABELS = {
    "attitude": "orientation q (-)",
    "position": "position r (m)",
    "omega": "angular velocity ω (rad/s)",
    "velocity": "velocity v (m/s)",
}
_GROUP_NAMES = {"omega": "angular velocity"}  # the others are named as in the metrics
_STATE_UNITS = {"attitude": "-", "position": "m", "omega": "rad/s", "velocity": "m/s"}
_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")


def _component_unit(component: int) -> str:
    """The unit of state component ``component`` (0-12)."""
    return next(_STATE_UNITS[g] for g, index in STATE_GROUPS.items() if index.start <= component < index.stop)


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


def _component_legend(ax: Axes, names: Sequence[str], *, measured: bool) -> None:
    """Legend beside ``ax``: one colour per component, one line style per kind (measured dots,
    true dashed, estimate solid)."""
    handles = [Line2D([], [], color=_COLOURS[k], linewidth=2, label=name) for k, name in enumerate(names)]
    if measured:
        handles.append(Line2D([], [], color="0.3", marker=".", linestyle="none", label="measured"))
    handles += [Line2D([], [], color="0.3", linestyle="--", linewidth=1.0, label="true"),
                Line2D([], [], color="0.3", linestyle="-", linewidth=1.4, label="estimate")]
    legend_beside(ax, handles)


def states_figure(trace: Trace, *, steps: int | None = None, title: str = "") -> Figure:
    """Estimate (solid), measurement (dots) and truth (dashed) of the four state groups over time
    (s): orientation q (-), position r (m), angular velocity (rad/s), velocity (m/s); the paper's
    EKF result figures. ``title`` replaces the default one (estimator, scenario and seed)."""
    times, truth, means, measured, ok = _aligned(trace, steps)
    figure = new_figure(10, 10)
    axes = figure.subplots(4, 1, sharex=True)
    for ax, (group, index) in zip(axes, STATE_GROUPS.items()):
        has_measurement = index.start < 7
        for k, component in enumerate(range(index.start, index.stop)):
            colour = _COLOURS[k]
            if has_measurement:
                ax.plot(times[ok], measured[ok, component], ".", color=colour, alpha=0.35, markersize=3)
            ax.plot(times, truth[:, component], "--", color=colour, linewidth=1.0)
            ax.plot(times, means[:, component], "-", color=colour, linewidth=1.4)
        ax.set_ylabel(_GROUP_LABELS[group])
        _component_legend(ax, [STATE_NAMES[c] for c in range(index.start, index.stop)], measured=has_measurement)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    figure.suptitle(title or _title(trace) + ": estimate, measurement and truth")
    return figure


def uncertainty_figure(trace: Trace, *, steps: int | None = None) -> Figure:
    """Each of the 13 components (in its unit) over time (s): estimate, truth and the +- 2 sigma
    band (~95.4%) from the estimator's 13x13 state covariance (the paper's uncertainty figure).
    The legend sits in the free panel of the 4 x 4 grid."""
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
                                linewidth=0)
            ax.plot(times, truth[:, component], "k--", linewidth=1.0)
            ax.plot(times, means[:, component], color="tab:blue", linewidth=1.2)
            ax.set_ylabel(f"{STATE_NAMES[component]} ({_component_unit(component)})")
            ax.grid(alpha=0.3)
    handles = [Line2D([], [], color="k", linestyle="--", linewidth=1.0, label="true"),
               Line2D([], [], color="tab:blue", linewidth=1.2, label="estimate")]
    if sigma is not None:
        handles.append(Patch(color="tab:blue", alpha=0.2, linewidth=0, label="estimate ± 2σ"))
    axes[1, 3].legend(handles=handles, loc="center", fontsize=10)  # an empty panel: over no data
    axes[0, 3].xaxis.set_tick_params(labelbottom=True)  # the panel below it is empty
    axes[0, 3].set_xlabel("time (s)")
    for ax in axes[-1, :3]:
        ax.set_xlabel("time (s)")
    figure.suptitle(_title(trace) + ": estimates with 2σ uncertainty bands")
    return figure


def errors_figure(trace: Trace, *, settings: MetricSettings | None = None, steps: int | None = None) -> Figure:
    """Group errors over time (s): attitude (deg), position (m), angular velocity (rad/s) and
    velocity (m/s), with the moving RMS, the settling band and time
    (:mod:`fkn_bench.metrics.settling`) and the unscored transient (before the cut) shaded."""
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
            ax.plot([], [], color="tab:red", linestyle="none", marker="x", label="never settled")
        ax.set_ylabel(f"{_GROUP_NAMES.get(group, group)} error ({GROUP_UNITS[group]})")
        legend_beside(ax)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    figure.suptitle(_title(trace) + ": errors and settling")
    return figure


def ratio_figure(results: list[RatioConvergence], *, threshold: float = 0.02, at: float = 600.0) -> Figure:
    """Inertia-ratio error ``max |k_est - k_true|`` (-, log scale) over time (s) per scenario: the
    median and the 10-90% band over seeds, the threshold and the time at which it is checked
    marked; the legend below the axes."""
    figure = new_figure(9.0, 4.4)
    ax = figure.add_subplot(1, 1, 1)
    for result in results:
        median = np.nanmedian(result.errors, axis=0)
        low, high = np.nanpercentile(result.errors, [10, 90], axis=0)
        share = result.share_below(threshold, at)
        line = ax.semilogy(result.times, median, label=f"{result.scenario} (median; {share:.0%} of "
                                                       f"{len(result.seeds)} seeds < {threshold} at {at:g} s)")[0]
        ax.fill_between(result.times, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
    ax.axhline(threshold, color="k", linestyle="--", linewidth=0.8, label=f"threshold {threshold:g}")
    ax.axvline(at, color="k", linestyle=":", linewidth=0.8, label=f"checked at {at:g} s")
    ax.set(xlabel="time since the first sample (s)", ylabel="max |k_est - k_true| (-)",
           title=f"{results[0].estimator}: inertia-ratio error (band: 10-90% of seeds)")
    legend_below(figure, ax.get_legend_handles_labels()[0], ncols=1 if len(results) > 1 else 3)
    return figure


def _rmse_label(name: str, diverged: float, value: float, off_scale: bool) -> str:
    """An estimator's tick label, with its diverged share and its RMSE when the bar is off the scale."""
    notes = [f"{100 * diverged:.0f}% diverged"] if diverged > 0 else []
    notes += [f"RMSE {value:.2g}, off scale"] if off_scale else []
    return name + (f"  [{'; '.join(notes)}]" if notes else "")


def _rmse_limit(values: np.ndarray, spans: np.ndarray) -> tuple[float, np.ndarray]:
    """The right end of the RMSE axis and which ``values`` lie beyond it: a value above ten times
    the median (a diverged filter's 1e30) would squash every other bar, so it is left off the
    scale; the axis ends 10% beyond the largest remaining value or interval end."""
    finite = values[np.isfinite(values) & (values > 0)]
    cap = 10.0 * float(np.median(finite)) if finite.size else np.inf
    off = np.isfinite(values) & (values > cap)
    shown = np.concatenate([values[~off], spans[np.isfinite(spans) & (spans <= cap)]])
    shown = shown[np.isfinite(shown)]
    return (1.1 * float(shown.max()) if shown.size and shown.max() > 0 else 1.0), off


COMPARISON_DIGITS = 6
"""Significant digits of the numbers a comparison chart plots (:func:`comparison_data`): far
beyond what a figure resolves, and the same on every CPU whatever the order of its sums."""


def _rounded(value: Any) -> float | None:
    """``value`` to :data:`COMPARISON_DIGITS` significant digits; None when missing or not finite."""
    if value is None or not np.isfinite(float(value)):
        return None
    return float(f"{float(value):.{COMPARISON_DIGITS}g}")


def comparison_data(scenario: str, summaries: Sequence[dict[str, Any]], quoted: Sequence[QuotedRow] = ()) -> dict[str, Any]:
    """Exactly the numbers :func:`comparison_figure` plots, JSON-compatible: per estimator (in the
    order given, best first) its label, mean 13-state RMSE over seeds, 95% interval
    (``state_rmse_ci`` of :func:`fkn_bench.harness.summary.summarize_pair`; None when it has none)
    and diverged share; then the quoted paper rows (label and value). Numbers are rounded to
    :data:`COMPARISON_DIGITS` significant digits; a missing or non-finite value is None."""
    rows = []
    for s in summaries:
        ci = s.get("state_rmse_ci")
        rows.append({
            "estimator": s["estimator"],
            "mean": _rounded(s["state_rmse"]),
            "ci": [_rounded(ci[0]), _rounded(ci[1])] if ci else None,
            "diverged": _rounded(s.get("diverged_fraction") or 0.0),
        })
    return {"scenario": scenario, "estimators": rows,
            "quoted": [{"label": q.label, "mean": _rounded(q.state_rmse)} for q in quoted]}


def comparison_figure(scenario: str, summaries: Sequence[dict[str, Any]], quoted: Sequence[QuotedRow] = ()) -> Figure:
    """:func:`comparison_chart` of :func:`comparison_data`."""
    return comparison_chart(comparison_data(scenario, summaries, quoted))


def comparison_chart(data: dict[str, Any]) -> Figure:
    """Horizontal bar chart of the 13-state RMSE (mixed SI units) per estimator of ``data``
    (:func:`comparison_data`), in its order (best first, at the top): the bar is the mean over
    seeds, the black line spans its 95% confidence interval; quoted paper rows are hatched at the
    bottom. A diverged share, and the value of a bar beyond ten times the median (drawn to the
    axis' end), are written in the estimator's tick label (red), clear of the bars and lines."""
    estimators, quoted = data["estimators"], data["quoted"]
    nan = float("nan")
    values = np.asarray([nan if r["mean"] is None else r["mean"] for r in [*estimators, *quoted]], dtype=float)
    spans = [(r["ci"][0], r["ci"][1]) if r["ci"] and None not in r["ci"] else (nan, nan) for r in estimators]
    limit, off = _rmse_limit(values, np.asarray([high for _, high in spans], dtype=float))
    diverged = [float(r["diverged"] or 0.0) for r in estimators] + [0.0] * len(quoted)
    names = [r["estimator"] for r in estimators] + [q["label"] for q in quoted]
    labels = [_rmse_label(n, d, v, o) for n, d, v, o in zip(names, diverged, values, off)]
    # wide enough for the longest tick label beside a 5-inch bar area (about 0.08 in per character)
    figure = new_figure(max(8.0, 5.2 + 0.08 * max(map(len, labels), default=0)), max(3.0, 0.32 * len(labels) + 1.8))
    ax = figure.subplots()
    y = np.arange(len(labels))
    bars = ax.barh(y, np.minimum(np.nan_to_num(values, nan=0.0), limit), height=0.7, color="tab:blue")
    for bar in bars[len(estimators):]:
        bar.set_facecolor("white")
        bar.set_edgecolor("tab:gray")
        bar.set_hatch("//")
    for i, (low, high) in enumerate(spans):
        if np.isfinite(low) and np.isfinite(high):
            ax.plot([low, min(high, limit)], [i, i], color="black", linewidth=2, solid_capstyle="butt")
    ax.set_yticks(y, labels)
    for tick, d, o in zip(ax.get_yticklabels(), diverged, off):
        if d > 0 or o:
            tick.set_color("tab:red")
    ax.set_xlim(0.0, limit)
    ax.invert_yaxis()  # best at the top
    ax.set_xlabel(f"13-state RMSE ({STATE_RMSE_UNIT})\nbar: mean over seeds; line: 95% confidence interval (Student-t)")
    ax.set_ylabel("estimator, best first")
    ax.set_title(f"{data['scenario']}: estimators compared (lower is better)")
    ax.grid(axis="x", alpha=0.3)
    ax.set_axisbelow(True)
    return figure


def save_figure(figure: Figure, path: str | Path, *, dpi: int = 100, command: str | None = None, data: Any = None) -> Path:
    """Write ``figure`` as PNG atomically (:func:`fkn_bench.plotting.save_png`); returns the path.
    With ``command`` (the command that draws it) the PNG's text chunks name it, and hold ``data``
    (the numbers it plots) with their fingerprint when given (:mod:`fkn_bench.reporting.figures`)."""
    if command is None:
        return save_png(figure, path, dpi=dpi)
    return write_png(figure, path, command=command, data=data, dpi=dpi)
