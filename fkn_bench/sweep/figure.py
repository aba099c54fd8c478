"""The sweep's figure: hyperparameters against the validation RMSE, in parallel coordinates.

Drawn with matplotlib in the house style of :mod:`fkn_bench.plotting` (not optuna's own plot,
whose colour scale ends in white and whose axes are ticked as floats): one vertical axis per
searched hyperparameter, on the search space's range (log axes for log ranges, integer ticks for
integer knobs, the declared choices for categorical ones), after the validation 13-state RMSE on
the first axis. Every completed trial is a line coloured by its RMSE on a colour scale without
white (viridis, its light end clipped); the best trial is drawn last and thickest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.cm import ScalarMappable
from matplotlib.colors import ListedColormap, Normalize
from matplotlib.figure import Figure
from optuna.trial import FrozenTrial

from fkn_bench.plotting import STATE_RMSE_UNIT, integer_axis, new_figure
from fkn_bench.sweep.space import Knob, SearchSpace

__all__ = ["HYPERPARAMETER_UNITS", "parallel_coordinates_figure"]

HYPERPARAMETER_UNITS: dict[str, str] = {
    "lr": "-", "weight_decay": "-", "dropout": "-", "output_scale": "-", "min_improvement": "-",
    "hidden": "neurons", "layers": "count", "windows_per_batch": "count", "episodes": "count", "epochs": "count",
    "lbfgs_iterations": "count", "lbfgs_history": "count", "seed": "-",
    "window": "samples", "history": "samples", "samples_per_window": "samples", "stride": "samples",
    "loss_cut": "steps", "train_measurement_every": "steps", "patience": "epochs", "scheduler_patience": "epochs",
}
"""Units of the configuration fields a sweep searches (``-``: dimensionless); others are labelled
"as configured"."""

OBJECTIVE_LABEL = f"validation 13-state RMSE\n({STATE_RMSE_UNIT})"
_COLOURS = ListedColormap(colormaps["viridis"](np.linspace(0.0, 0.85, 256)), name="viridis-no-light-end")
_PAD = 0.05  # of each axis' range, so that lines at the ends stay clear of the figure's edges


@dataclass(frozen=True)
class _Scale:
    """One vertical axis: maps a value to the common height 0..1 and sets up its own ticks."""

    label: str
    low: float = 0.0
    high: float = 1.0
    log: bool = False
    integer: bool = False
    categories: tuple[Any, ...] = ()

    def _span(self) -> tuple[float, float]:
        low, high = (math.log10(self.low), math.log10(self.high)) if self.log else (self.low, self.high)
        if self.categories:
            low, high = -0.5, len(self.categories) - 0.5
        elif high <= low:
            low, high = low - 0.5, high + 0.5
        pad = 0.0 if self.categories else _PAD * (high - low)
        return low - pad, high + pad

    def height(self, value: Any) -> float:
        """The height (0..1) of ``value`` on this axis; NaN when it has none."""
        if value is None:
            return math.nan
        if self.categories:
            x = float(next((i for i, c in enumerate(self.categories) if repr(c) == repr(value)), math.nan))
        else:
            x = math.log10(value) if self.log else float(value)
        low, high = self._span()
        return (x - low) / (high - low)

    def draw(self, axis: Axes) -> None:
        """Limits, scale and ticks of ``axis``, a twin of the host axes."""
        low, high = self._span()
        if self.log:
            axis.set_yscale("log")
            axis.set_ylim(10 ** low, 10 ** high)
        else:
            axis.set_ylim(low, high)
        if self.categories:
            axis.set_yticks(range(len(self.categories)), [str(c) for c in self.categories])
        elif self.integer:
            integer_axis(axis.yaxis)


def _knob_scale(knob: Knob, values: Sequence[Any]) -> _Scale:
    label = f"{knob.name}\n({HYPERPARAMETER_UNITS.get(knob.name, 'as configured')})"
    if knob.kind == "categorical":
        extra = tuple(v for v in dict.fromkeys(values) if all(repr(v) != repr(c) for c in knob.values))
        categories = tuple(knob.values) + extra
        named = all(isinstance(c, str) for c in categories)  # activation functions: no unit
        return _Scale(knob.name if named else label, categories=categories)
    numbers = [float(v) for v in values if v is not None]
    low = min([float(knob.low)] + numbers) if knob.low is not None else min(numbers)
    high = max([float(knob.high)] + numbers) if knob.high is not None else max(numbers)
    return _Scale(label, low, high, log=knob.log and low > 0, integer=knob.kind == "int")


def _objective_scale(values: Sequence[float]) -> _Scale:
    return _Scale(OBJECTIVE_LABEL, min(values), max(values))


def _place(axis: Axes, position: float, label: str) -> None:
    """Put ``axis``' spine at ``position`` (0..1 of the host width), its name below it."""
    side = "left" if position == 0.0 else "right"
    for name, spine in axis.spines.items():
        spine.set_visible(name == side)
    axis.spines[side].set_position(("axes", position))
    axis.yaxis.set_ticks_position(side)
    axis.set_ylabel(label, rotation=0, ha="center", va="top", fontsize=9)
    axis.yaxis.set_label_coords(position, -0.03)


def parallel_coordinates_figure(trials: Sequence[FrozenTrial], space: SearchSpace, *, title: str = "",
                                params: Sequence[str] | None = None) -> Figure:
    """Parallel coordinates of ``trials`` (completed ones, with values): the validation RMSE, then
    ``params`` (default: the knobs whose value differs between trials, else all), each on its own
    vertical axis in its unit; lines coloured by the RMSE (colour bar on the right)."""
    done = sorted((t for t in trials if t.value is not None and math.isfinite(t.value)), key=lambda t: -t.value)
    if not done:
        raise ValueError("no completed trial with a finite value to draw")
    knobs = {k.name: k for k in space.knobs}
    if params is None:
        params = [n for n in space.names if len({repr(t.params.get(n)) for t in done}) > 1] or space.names
    values = [t.value for t in done]
    scales = [_objective_scale(values)] + [_knob_scale(knobs[n], [t.params.get(n) for t in done]) for n in params]
    height = 5.0
    figure = new_figure(max(7.0, 1.5 * len(scales) + 1.5), height)
    # constrained layout does not see the axis names set below the twins: keep 0.6 in free for them
    figure.get_layout_engine().set(rect=(0.0, 0.6 / height, 1.0, 1.0 - 0.6 / height))
    host = figure.subplots()
    host.set(xlim=(0, len(scales) - 1), ylim=(0, 1))
    host.xaxis.set_visible(False)
    host.yaxis.set_visible(False)
    for spine in host.spines.values():
        spine.set_visible(False)
    for i, scale in enumerate(scales):
        axis = host.twinx()
        scale.draw(axis)
        _place(axis, i / (len(scales) - 1) if len(scales) > 1 else 0.0, scale.label)
    norm = Normalize(min(values), max(values) if max(values) > min(values) else min(values) + 1e-12)
    x = np.arange(len(scales))
    for rank, trial in enumerate(done):  # worst first: the best ends on top
        heights = [scales[0].height(trial.value)] + [s.height(trial.params.get(n)) for s, n in zip(scales[1:], params)]
        best = rank == len(done) - 1
        host.plot(x, heights, color=_COLOURS(norm(trial.value)), linewidth=2.6 if best else 1.3,
                  alpha=1.0 if best else 0.85, zorder=3 if best else 2, marker="o", markersize=3)
    bar = figure.colorbar(ScalarMappable(norm=norm, cmap=_COLOURS), ax=host, location="right", pad=0.02,
                          fraction=0.03)
    bar.set_label(OBJECTIVE_LABEL.replace("\n", " "), fontsize=9)
    host.set_title(title + ("\n" if title else "") + f"{len(done)} completed trials; thick line: the best", fontsize=10)
    return figure
