"""Hyperparameter sweeps on optuna (``fkn-bench sweep``), following the paper's method: a random
search to narrow the space, then a grid search over the reduced space (TPE, random or grid search
alone as options).

* :mod:`~fkn_bench.sweep.space`: search spaces from TOML (packaged: ``paper``, ``quick``);
* :mod:`~fkn_bench.sweep.objective`: a trial = one training, reporting the validation RMSE per
  epoch and pruned by the study's pruner;
* :mod:`~fkn_bench.sweep.study`: storages (journal file or RDB URL), samplers and the reduced grid;
* :mod:`~fkn_bench.sweep.runner`: worker processes sharing one study, and the outputs
  (``best.toml``, ``trials.csv``, ``parallel_coordinates.png``, ``sweep.json``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fkn_bench.lazy import lazy_exports

# re-exported lazily (fkn_bench.lazy): the space's names without optuna, e.g. for the CLI's choices
_EXPORTS = {
    "SweepTask": ".objective",
    "TrialError": ".objective",
    "make_objective": ".objective",
    "trial_config": ".objective",
    "SweepError": ".runner",
    "SweepResult": ".runner",
    "SweepSettings": ".runner",
    "run_sweep": ".runner",
    "write_toml": ".runner",
    "PRUNERS": ".space",
    "SAMPLERS": ".space",
    "Knob": ".space",
    "PrunerSpec": ".space",
    "SearchSpace": ".space",
    "SpaceError": ".space",
    "load_space": ".space",
    "packaged_spaces": ".space",
    "parse_space": ".space",
    "resolve_space": ".space",
    "open_storage": ".study",
    "reduced_grid": ".study",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:
    from fkn_bench.sweep.objective import SweepTask, TrialError, make_objective, trial_config
    from fkn_bench.sweep.runner import SweepError, SweepResult, SweepSettings, run_sweep, write_toml
    from fkn_bench.sweep.space import (
        PRUNERS,
        SAMPLERS,
        Knob,
        PrunerSpec,
        SearchSpace,
        SpaceError,
        load_space,
        packaged_spaces,
        parse_space,
        resolve_space,
    )
    from fkn_bench.sweep.study import open_storage, reduced_grid

__all__ = [
    "Knob",
    "PRUNERS",
    "PrunerSpec",
    "SAMPLERS",
    "SearchSpace",
    "SpaceError",
    "SweepError",
    "SweepResult",
    "SweepSettings",
    "SweepTask",
    "TrialError",
    "load_space",
    "make_objective",
    "open_storage",
    "packaged_spaces",
    "parse_space",
    "reduced_grid",
    "resolve_space",
    "run_sweep",
    "trial_config",
    "write_toml",
]
