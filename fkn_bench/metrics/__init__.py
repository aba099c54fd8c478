"""Metrics of state estimates against the truth, independent of how any estimator works.

Everything here takes arrays (truth, estimated states, covariances, innovations) and returns
per-run values; the harness (:mod:`fkn_bench.harness`) joins estimators, episodes and metrics.

* :mod:`~fkn_bench.metrics.errors`: component errors, group error magnitudes, the 12-dim error;
* :mod:`~fkn_bench.metrics.accuracy`: RMSE per component, the 13-state RMSE (primary score),
  RMSE / median / 95th percentile / maximum of the group errors;
* :mod:`~fkn_bench.metrics.settling`: settling time per group;
* :mod:`~fkn_bench.metrics.consistency`: NEES, NIS, ANEES with chi-square intervals;
* :mod:`~fkn_bench.metrics.stability`: divergence flags;
* :mod:`~fkn_bench.metrics.scoring`: all of them for one batch of runs (:func:`score_run`);
* :mod:`~fkn_bench.metrics.aggregate`: mean, median and IQR over seeds.
"""

from fkn_bench.metrics.accuracy import MAGNITUDE_STATISTICS, component_rmse, magnitude_statistics, state_rmse
from fkn_bench.metrics.aggregate import SUMMARY_FIELDS, Summary, summarize
from fkn_bench.metrics.consistency import (
    NEES_DOF,
    NIS_DOF,
    AverageStatistic,
    QuadraticForm,
    StatisticSums,
    average_statistic,
    chi2_interval,
    chi2_upper,
    normalized_squares,
    positive_definite,
    statistic_sums,
)
from fkn_bench.metrics.errors import GROUP_UNITS, GROUPS, attitude_error_deg, component_errors, error_state, group_errors
from fkn_bench.metrics.scoring import MetricSettings, RunScores, score_run
from fkn_bench.metrics.settling import (
    DEFAULT_PEAK_FRACTION,
    DEFAULT_TOLERANCES,
    SettlingResult,
    moving_rms,
    settling_band,
    settling_time,
)
from fkn_bench.metrics.stability import (
    DEFAULT_GROWTH_FLOORS,
    DIVERGENCE_REASONS,
    DivergenceFlags,
    error_growth,
    nees_high,
    window_rms,
)

__all__ = [
    "AverageStatistic",
    "DEFAULT_GROWTH_FLOORS",
    "DEFAULT_PEAK_FRACTION",
    "DEFAULT_TOLERANCES",
    "DIVERGENCE_REASONS",
    "DivergenceFlags",
    "GROUPS",
    "GROUP_UNITS",
    "MAGNITUDE_STATISTICS",
    "MetricSettings",
    "NEES_DOF",
    "NIS_DOF",
    "QuadraticForm",
    "RunScores",
    "SUMMARY_FIELDS",
    "SettlingResult",
    "StatisticSums",
    "Summary",
    "attitude_error_deg",
    "average_statistic",
    "chi2_interval",
    "chi2_upper",
    "component_errors",
    "component_rmse",
    "error_growth",
    "error_state",
    "group_errors",
    "magnitude_statistics",
    "moving_rms",
    "nees_high",
    "normalized_squares",
    "positive_definite",
    "score_run",
    "settling_band",
    "settling_time",
    "state_rmse",
    "statistic_sums",
    "summarize",
    "window_rms",
]
