"""The posterior Cramér-Rao bound over time against estimators' error curves (``fkn-bench bound
--plot``), drawn headless in the house style of :mod:`fkn_bench.plotting`.

One panel per state group (attitude angle deg, position m, angular rate rad/s, velocity m/s), log
y axis, time from the split's first sample (s): the bound's curve (:attr:`Bound.curves
<fkn_bench.metrics.bound.Bound.curves>`, ``sqrt(mean_b tr B_k[g])`` over the episodes ``b``), for a
free tumble with unknown inertia also the bound with the inertia known, and each estimator's error
curve on the same episodes, the root mean square over episodes at each step,
``sqrt(mean_b |e_bk[g]|^2)`` (:func:`error_curves`), which an efficient estimator would follow.
The scored window's start (``cut``) is marked.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from fkn_bench.metrics import GROUP_UNITS, GROUPS, group_errors
from fkn_bench.metrics.bound import Bound
from fkn_bench.plotting import legend_below, new_figure
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = ["error_curves", "bound_figure"]

_GROUP_NAMES = {"attitude": "attitude angle", "omega": "angular rate"}


def error_curves(truth: Float[ArrayF, "B T 13"], means: Float[ArrayF, "B T 13"],
                 initialised: Bool[ArrayB, "B T"] | None = None) -> dict[str, Float[ArrayF, "T"]]:
    """``{group: (T,)}``: the root mean square over episodes of each group's error magnitude
    (:func:`fkn_bench.metrics.group_errors`, attitude in degrees) at each step; an episode counts
    from its initialisation on (``initialised``), NaN at a step where none has a finite error."""
    errors = group_errors(truth, means)
    out = {}
    for group in GROUPS:
        squared = np.square(errors[group])
        if initialised is not None:
            squared = np.where(initialised, squared, np.nan)
        squared = np.where(np.isfinite(squared), squared, np.nan)
        counted = np.sum(np.isfinite(squared), axis=0)
        total = np.nansum(squared, axis=0)
        out[group] = np.sqrt(np.divide(total, counted, out=np.full(total.shape, np.nan), where=counted > 0))
    return out


def bound_figure(bound: Bound, estimators: Mapping[str, Mapping[str, ArrayF]] | None = None, *,
                 known: Bound | None = None) -> Figure:
    """The bound of ``bound``'s episodes over time against ``estimators`` (``{label: {group:
    (T,)}}``, :func:`error_curves` on the same episodes and split), and ``known`` (the same
    episodes with the inertia known) where given (module docstring)."""
    times = bound.times - bound.times[0]
    dt = float(times[1] - times[0]) if times.size > 1 else 0.0
    figure = new_figure(10, 10)
    axes = figure.subplots(len(GROUPS), 1, sharex=True)
    inertia = ", inertia estimated" if bound.inertia == "estimated" else ""
    for ax, group in zip(axes, GROUPS):
        ax.semilogy(times, _finite(bound.curves[group]), color="k", linewidth=1.6, label=f"bound (PCRB{inertia})")
        if known is not None:
            ax.semilogy(times, _finite(known.curves[group]), color="k", linestyle="--", linewidth=1.0,
                        label="bound (PCRB, inertia known)")
        for label, curves in (estimators or {}).items():
            ax.semilogy(times, _finite(curves[group]), linewidth=1.0, label=f"{label} (RMS over episodes)")
        ax.axvline(bound.cut * dt, color="tab:red", linestyle=":", linewidth=1.0,
                   label=f"scored from step {bound.cut} ({bound.cut * dt:g} s)")
        ax.set_ylabel(f"{_GROUP_NAMES.get(group, group)} ({GROUP_UNITS[group]})")
        ax.grid(alpha=0.3, which="both")
    axes[-1].set_xlabel("time from the split's first sample (s)")
    handles = axes[0].get_legend_handles_labels()[0]
    legend_below(figure, handles, ncols=2)
    figure.suptitle(f"{bound.scenario}, {bound.split} split, {len(bound.seeds)} episodes: the posterior "
                    f"Cramér-Rao bound and error curves")
    return figure


def _finite(values: ArrayF) -> ArrayF:
    """``values`` with infinities as NaN (not drawn: a component not yet observable)."""
    values = np.asarray(values, dtype=float)
    return np.where(np.isfinite(values), values, np.nan)
