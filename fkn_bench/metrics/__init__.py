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

from fkn_bench.metrics import accuracy, aggregate, consistency, errors, scoring, settling, stability
from fkn_bench.metrics.accuracy import *  # noqa: F403  (the public API of each module, republished)
from fkn_bench.metrics.aggregate import *  # noqa: F403
from fkn_bench.metrics.consistency import *  # noqa: F403
from fkn_bench.metrics.errors import *  # noqa: F403
from fkn_bench.metrics.scoring import *  # noqa: F403
from fkn_bench.metrics.settling import *  # noqa: F403
from fkn_bench.metrics.stability import *  # noqa: F403

__all__ = sorted(
    accuracy.__all__ + aggregate.__all__ + consistency.__all__ + errors.__all__ + scoring.__all__
    + settling.__all__ + stability.__all__
)
