"""The sweep's parallel-coordinates figure is readable at a glance: every trial visible (no white
colour-scale end), integer knobs ticked at integers, every axis named with its unit, the colour
bar clear of the tick labels (:mod:`fkn_bench.plotting`)."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import to_rgb
from optuna.trial import create_trial

from fkn_bench.plotting import readability_problems
from fkn_bench.sweep.figure import parallel_coordinates_figure
from fkn_bench.sweep.space import load_space, resolve_space


def test_parallel_coordinates_of_the_quick_space() -> None:
    space = load_space(resolve_space("quick"))
    distributions = space.distributions()
    rows = [(16, 1, 1e-4, "tanh", 0.0190), (64, 3, 3e-3, "leaky_relu", 0.0154), (64, 2, 1e-2, "tanh", 0.0171),
            (16, 3, 5e-4, "leaky_relu", 0.0183)]
    trials = [create_trial(params=dict(zip(space.names, row[:4])), distributions=distributions, value=row[4])
              for row in rows]
    figure = parallel_coordinates_figure(trials, space, title="quick")
    assert readability_problems(figure) == []  # units, no overlaps (colour bar included), nothing near-white
    by_name = {ax.get_ylabel().split("\n")[0]: ax for ax in figure.axes[1:-1]}  # the host first, the colour bar last
    assert list(by_name) == ["validation 13-state RMSE", "hidden", "layers", "lr", "activation"]
    layers = by_name["layers"].yaxis
    low, high = sorted(layers.get_view_interval())
    shown = [t for t in layers.get_majorticklocs() if low <= t <= high]
    assert shown == [1.0, 2.0, 3.0]  # not 1.2, 1.4 ...
    assert by_name["lr"].get_yscale() == "log"
    assert [t.get_text() for t in by_name["activation"].get_yticklabels()] == ["leaky_relu", "tanh"]
    host = figure.axes[0]
    assert len(host.lines) == len(rows)
    assert max(to_rgb(line.get_color())[1] for line in host.lines) < 0.9  # the worst trial is not white
    assert host.lines[-1].get_linewidth() > host.lines[0].get_linewidth()  # the best on top, thickest
    assert np.isclose(host.lines[-1].get_ydata()[0], min(line.get_ydata()[0] for line in host.lines))
