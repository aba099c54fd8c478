"""Reproduce the FlexKalmanNet paper's results section with one command (``fkn-bench reproduce``).

* :mod:`~fkn_bench.reproduce.pipeline`: training on ds1 and ds2, evaluation, figures, report;
* :mod:`~fkn_bench.reproduce.evaluation`: the paper's evaluation protocol over several seeds;
* :mod:`~fkn_bench.reproduce.tables`: the paper's tables with the quoted values beside ours;
* :mod:`~fkn_bench.reproduce.figures`: the paper's figures;
* :mod:`~fkn_bench.reproduce.differences`: the "differences from the paper", generated;
* :mod:`~fkn_bench.reproduce.report`: Markdown, HTML and CSV output.
"""

from fkn_bench.reproduce.pipeline import (
    DEFAULT_EVAL_SEEDS,
    QUICK_EVAL_SEEDS,
    QUICK_OVERRIDES,
    Reproduction,
    ReproduceSettings,
    TrainedModel,
    run_reproduction,
)

__all__ = [
    "DEFAULT_EVAL_SEEDS",
    "QUICK_EVAL_SEEDS",
    "QUICK_OVERRIDES",
    "Reproduction",
    "ReproduceSettings",
    "TrainedModel",
    "run_reproduction",
]
