"""The paper's two training figures: loss curves (Fig. 3) and learned parameters over epochs (Fig. 4).

Drawn headless in the house style of :mod:`fkn_bench.plotting` (Agg canvas, no pyplot state;
epochs ticked as integers, legends beside the data); files written atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from fkn_bench.plotting import STATE_RMSE_UNIT, integer_axis, legend_beside, new_figure
from fkn_bench.plotting import save_png as _save_png

__all__ = ["loss_figure", "parameters_figure", "plot_losses", "plot_parameters", "save_png"]

_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")
_GROUP_STYLES = {"q": "-", "r": "--", "w": "-.", "v": ":"}  # orientation, position, rate, velocity
_R_UNITS = "q: -, r: m"
_Q_UNITS = "q: -, r: m, ω: rad/s, v: m/s"


def save_png(figure: Figure, path: str | Path, *, dpi: int = 100) -> Path:
    """Write ``figure`` as PNG atomically; returns the path."""
    return _save_png(figure, path, dpi=dpi)


def _scale(axis: Axes, values: pd.DataFrame) -> None:
    """Log y scale when the positive ``values`` span more than a decade; else linear, plain numbers."""
    finite = values.to_numpy(dtype=float)
    finite = finite[np.isfinite(finite)]
    if finite.size and (finite > 0).all() and finite.max() > 10 * finite.min():
        axis.set_yscale("log")
    else:
        axis.ticklabel_format(axis="y", style="plain", useOffset=False)


def _epoch_axis(axis: Axes) -> None:
    axis.set_xlabel("epoch (-)")
    integer_axis(axis.xaxis)


def _loss_label(loss: str) -> str:
    """The y label of a loss axis for objective label ``loss`` (e.g. ``13-state RMSE``,
    ``innovation NLL``; empty: either), with its unit (NLLs in nats: natural logarithms)."""
    if not loss:
        return "loss (13-state RMSE:\nmixed SI; NLL: nats)"
    return f"{loss}\n({'nats' if 'NLL' in loss else STATE_RMSE_UNIT if 'RMSE' in loss else '-'})"


def loss_figure(history: pd.DataFrame, *, title: str = "", best_epoch: int | None = None, loss: str = "") -> Figure:
    """Training and validation loss per epoch, the best epoch marked; ``loss`` names the objective
    (the 13-state RMSE in mixed SI units, or an NLL in nats) for the y label. Log scale when the
    losses span more than a decade."""
    figure = new_figure(7.0, 3.6)
    axis = figure.subplots()
    axis.plot(history["epoch"], history["train_loss"], marker=".", label="training loss", color="tab:blue")
    axis.plot(history["epoch"], history["val_loss"], marker=".", label="validation loss", color="tab:orange")
    if best_epoch:
        axis.axvline(best_epoch, color="0.5", linestyle="--", linewidth=1, label=f"best epoch {best_epoch}")
    axis.set(ylabel=_loss_label(loss), title=title)
    _epoch_axis(axis)
    _scale(axis, history[["train_loss", "val_loss"]])
    axis.grid(True, alpha=0.3)
    legend_beside(axis, fontsize=8)
    return figure


def _parameter_lines(axis: Axes, history: pd.DataFrame, tag: str) -> bool:
    """One line per ``<tag><component>`` column: colour by the component's place in its group
    (as in the state figures: qw, rx, wx, vx blue ...), line style by group (q solid, r dashed, ω dash-dot, v dotted). False when there is none."""
    columns = [c for c in history.columns if c.startswith(tag)]
    seen: dict[str, int] = {}  # components drawn so far per group
    for column in columns:
        component = column[len(tag):]
        k = seen[component[:1]] = seen.get(component[:1], -1) + 1
        colour = _COLOURS[k % len(_COLOURS)]
        axis.plot(history["epoch"], history[column], label=component, linewidth=1.3, color=colour,
                  linestyle=_GROUP_STYLES.get(component[0], "-"))
    if columns:
        _scale(axis, history[columns])
        legend_beside(axis, ncols=2 if len(columns) > 7 else 1)
    return bool(columns)


def parameters_figure(history: pd.DataFrame, *, title: str = "") -> Figure:
    """The learned standard deviations over epochs: measurement noise sigma_R (q: -, r: m) in the
    upper panel, process noise sigma_Q per step (q: -, r: m, ω: rad/s, v: m/s) in the lower one;
    log scale where they span more than a decade."""
    figure = new_figure(8.0, 6.0)
    axes = figure.subplots(2, 1, sharex=True)
    for axis, tag, label in ((axes[0], "sigma_R_", f"σ_R, measurement noise\n({_R_UNITS})"),
                             (axes[1], "sigma_Q_", f"σ_Q, process noise per step\n({_Q_UNITS})")):
        _parameter_lines(axis, history, tag)
        axis.set_ylabel(label)
        axis.grid(True, alpha=0.3)
    _epoch_axis(axes[1])
    figure.suptitle(title)
    return figure


def plot_losses(history: pd.DataFrame, path: str | Path, *, title: str = "", best_epoch: int | None = None,
                loss: str = "") -> Path:
    """Write :func:`loss_figure` to ``path`` (PNG)."""
    return save_png(loss_figure(history, title=title, best_epoch=best_epoch, loss=loss), path)


def plot_parameters(history: pd.DataFrame, path: str | Path, *, title: str = "") -> Path:
    """Write :func:`parameters_figure` to ``path`` (PNG)."""
    return save_png(parameters_figure(history, title=title), path)
