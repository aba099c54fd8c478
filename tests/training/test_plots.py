"""The training figures are readable at a glance: epochs ticked as integers even for a short run,
every axis labelled with its unit, legends beside the data (:mod:`fkn_bench.plotting`)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fkn_bench.plotting import readability_problems
from fkn_bench.training.plots import loss_figure, parameters_figure
from fkn_bench.types import STATE_NAMES


def _history(epochs: int) -> pd.DataFrame:
    """A history as the trainer writes it: losses and the 20 learned standard deviations per epoch."""
    epoch = np.arange(1, epochs + 1)
    columns = {"epoch": epoch, "train_loss": 0.0188 - 1e-5 * epoch, "val_loss": 0.0185 - 1e-5 * epoch}
    columns |= {f"sigma_Q_{n}": (5e-3 if n[0] in "qw" else 1e-4) * (1 - 1e-3 * epoch) for n in STATE_NAMES}
    columns |= {f"sigma_R_{n}": 0.1 * (1 + 1e-3 * epoch) for n in STATE_NAMES[:7]}
    return pd.DataFrame(columns)


def _ticks_shown(axis) -> np.ndarray:  # noqa: ANN001
    low, high = sorted(axis.get_view_interval())
    ticks = axis.get_majorticklocs()
    return ticks[(ticks >= low) & (ticks <= high)]


@pytest.mark.parametrize("epochs", [3])
def test_epoch_axes_are_ticked_at_integers(epochs: int) -> None:
    history = _history(epochs)
    for figure in (loss_figure(history, best_epoch=epochs), parameters_figure(history)):
        assert readability_problems(figure) == []  # draws the figure
        ticks = _ticks_shown(figure.axes[-1].xaxis)
        assert len(ticks) >= 2 and all(float(t).is_integer() for t in ticks), ticks


def test_parameters_figure_labels_both_panels_with_units() -> None:
    figure = parameters_figure(_history(3))
    labels = [ax.get_ylabel() for ax in figure.axes]
    assert "σ_R" in labels[0] and "m" in labels[0] and "σ_Q" in labels[1] and "rad/s" in labels[1]
    assert [len(ax.get_legend().get_texts()) for ax in figure.axes] == [7, 13]
    assert loss_figure(_history(3), loss="innovation NLL").axes[0].get_ylabel() == "innovation NLL\n(nats)"
