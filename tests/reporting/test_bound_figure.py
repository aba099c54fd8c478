"""The bound-over-time figure (:mod:`fkn_bench.reporting.bound_figure`): readable, and its error
curve the root mean square over episodes."""

from __future__ import annotations

import numpy as np

from fkn_bench.metrics import GROUPS
from fkn_bench.metrics.bound import posterior_bound
from fkn_bench.plotting import readability_problems
from fkn_bench.reporting.bound_figure import bound_figure, error_curves
from fkn_bench.scenarios import get_scenario


def test_error_curves_are_the_rms_over_initialised_episodes() -> None:
    truth = np.zeros((2, 3, 13))
    truth[..., 0] = 1.0
    means = truth.copy()
    means[0, :, 4] = 3.0  # position errors 3 and 4 m
    means[1, :, 4] = 4.0
    initialised = np.array([[True, True, True], [False, True, True]])
    curves = error_curves(truth, means, initialised)
    assert set(curves) == set(GROUPS)
    np.testing.assert_allclose(curves["position"], [3.0, np.sqrt(12.5), np.sqrt(12.5)])
    np.testing.assert_allclose(curves["velocity"], 0.0)
    assert np.isnan(error_curves(truth, np.full_like(means, np.nan))["omega"]).all()


def test_bound_figure_is_readable() -> None:
    free = get_scenario("free-tumble", n_steps=300)
    bound = posterior_bound(free, 2, cut=50)
    known = posterior_bound(free, 2, cut=50, inertia="known")
    curves = {g: 2.0 * bound.curves[g] for g in GROUPS}
    figure = bound_figure(bound, {"an estimator": curves}, known=known)
    assert len(figure.axes) == len(GROUPS)
    assert all(ax.get_yscale() == "log" for ax in figure.axes)
    assert readability_problems(figure) == []
