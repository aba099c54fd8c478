"""``fkn-bench reproduce``: regenerate the paper's results section from scratch.

Steps (:func:`run_reproduction`), all deterministic for a given seed:

1. **Train** FlexKalmanNet on ds1 and on ds2 (:func:`fkn_bench.flexkalmannet.train_flexkalmannet`)
   with :class:`~fkn_bench.flexkalmannet.FlexKalmanNetConfig`'s defaults (or ``--config``), into
   ``OUT/training/<data set>/`` (checkpoint, history, the learned parameters).
2. **Evaluate** the learned filters, the paper's manual tuning (``manual-<variant>``) and the
   oracle EKF (the simulation's true noise) on the test split of ``eval_seeds`` seeds, the paper's
   protocol (a measurement every 10 steps, scored from step 100): ds1 and ds2 with both learned
   parameter sets (the matched and the cross-data-set runs), and the robustness runs ds1-noise5x
   and ds1-gap100 with the DS1 parameters (:mod:`fkn_bench.reproduce.evaluation`).
3. **Figures** from seed ``figure_seed``: the paper's Figs. 3-8, the training figures of DS1 and
   the cross-data-set runs.
4. **Tables** with the paper's quoted values beside ours (:mod:`fkn_bench.reproduce.tables`) and
   the **differences from the paper** generated from the numbers
   (:mod:`fkn_bench.reproduce.differences`).
5. **Report**: ``OUT/index.md``, ``OUT/index.html``, ``OUT/figures/*.png``, ``OUT/tables/*.csv``
   and ``OUT/results.json`` (every number, the configuration and provenance).

``--quick`` (:data:`QUICK_OVERRIDES`) trains a much smaller network for a few epochs and evaluates
fewer seeds: the same pipeline in well under two minutes, labelled QUICK throughout the report.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from fkn_bench.estimators import Estimator, make_estimator
from fkn_bench.filters import make_filter
from fkn_bench.flexkalmannet import FlexKalmanNetConfig, FlexKalmanNetEstimator, train_flexkalmannet
from fkn_bench.training.plots import plot_losses, plot_parameters
from fkn_bench.io import directory_lock, read_json, remove_temporaries, write_json_atomic
from fkn_bench.reporting.plots import save_figure, states_figure
from fkn_bench.reporting.reference import PAPER_TITLE
from fkn_bench.reproduce import figures as figs
from fkn_bench.reproduce.differences import Context, differences
from fkn_bench.reproduce.evaluation import Evaluation, evaluate, run_trace
from fkn_bench.reproduce.report import Block, Bullets, FigureRef, Heading, Paragraph, Table, write_report
from fkn_bench.reproduce.tables import (
    cross_dataset_table,
    hyperparameter_table,
    learned_std_table,
    rmse_table,
    robustness_table,
    training_table,
)
from fkn_bench.scenarios import get_scenario

__all__ = [
    "QUICK_OVERRIDES",
    "QUICK_EVAL_SEEDS",
    "DEFAULT_EVAL_SEEDS",
    "ReproduceSettings",
    "TrainedModel",
    "Reproduction",
    "run_reproduction",
]

DATASETS = ("ds1", "ds2")
DEFAULT_EVAL_SEEDS = 20
QUICK_EVAL_SEEDS = 5
QUICK_OVERRIDES: dict[str, Any] = {"hidden": 32, "layers": 2, "epochs": 3, "patience": 3, "episodes": 1}
"""What ``--quick`` changes in the training configuration (everything else: the defaults)."""

LABELS = {
    "learned-ds1": "learned DS1",
    "learned-ds2": "learned DS2",
    "manual": "manual tuning",
    "oracle": "oracle EKF (true noise)",
}

Log = Callable[[str], None]


def stderr_log(message: str) -> None:
    """The default :data:`Log`: the message on stderr, flushed."""
    print(message, file=sys.stderr, flush=True)


@dataclass(frozen=True)
class ReproduceSettings:
    """What a reproduction runs.

    Attributes:
        seed: training seed (network initialisation and window order; the config's ``seed``).
        eval_seeds: number of test-split seeds per evaluation (default 20, quick 5).
        quick: the ``--quick`` pipeline (:data:`QUICK_OVERRIDES`).
        config: base training configuration (default ``FlexKalmanNetConfig()``, read when the
            settings are used, so that new defaults apply).
        config_source: where ``config`` came from (a file name, for the report).
        figure_seed: seed of the episodes the figures show.
        uncertainty_steps: samples of the angular-rate uncertainty figure (the paper: 500).
        figures: draw the figures (``--no-figures``: tables, report and results only, about 40%
            faster; the report then lists no figures).
    """

    seed: int = 0
    eval_seeds: int | None = None
    quick: bool = False
    config: FlexKalmanNetConfig | None = None
    config_source: str | None = None
    figure_seed: int = 0
    uncertainty_steps: int = 500
    figures: bool = True

    def __post_init__(self) -> None:
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0 (got {self.seed})")
        if self.eval_seeds is not None and self.eval_seeds < 1:
            raise ValueError(f"eval_seeds must be >= 1 (got {self.eval_seeds})")
        if self.uncertainty_steps < 2:
            raise ValueError(f"uncertainty_steps must be >= 2 (got {self.uncertainty_steps})")

    @property
    def n_eval_seeds(self) -> int:
        if self.eval_seeds is not None:
            return int(self.eval_seeds)
        return QUICK_EVAL_SEEDS if self.quick else DEFAULT_EVAL_SEEDS

    def training_config(self) -> FlexKalmanNetConfig:
        base = self.config if self.config is not None else FlexKalmanNetConfig()
        return base.replace(seed=self.seed, **(QUICK_OVERRIDES if self.quick else {}))


@dataclass(frozen=True)
class TrainedModel:
    """A trained FlexKalmanNet and what the report needs from its training."""

    dataset: str
    out: Path
    artifact: Path
    estimator: FlexKalmanNetEstimator
    history: pd.DataFrame
    best_epoch: int
    best_val_rmse: float
    test_rmse: float
    seconds_per_epoch: float
    epochs_run: int
    output_size: int
    windows: int
    learned_std: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        """JSON-compatible facts (paths as text; the estimator and the history left out)."""
        return {f.name: str(v) if isinstance(v := getattr(self, f.name), Path) else v
                for f in fields(self) if f.name not in ("estimator", "history")}


@dataclass
class Reproduction:
    """Everything a reproduction produced (see :func:`run_reproduction`)."""

    out: Path
    settings: ReproduceSettings
    config: FlexKalmanNetConfig
    trained: dict[str, TrainedModel]
    evaluations: dict[tuple[str, str], Evaluation]
    tables: dict[str, Table]
    figures: list[FigureRef]
    differences: list[str]
    seconds: dict[str, float] = field(default_factory=dict)


def named_std(estimator: Any, variant: str) -> dict[str, float]:
    """``sigma_R_<label>`` then ``sigma_Q_<label>`` (the paper's table order) of a constant
    Kalman estimator in ``variant``'s layout."""
    layout = make_filter(variant).layout
    out = {f"sigma_R_{label}": float(v) for label, v in zip(layout.r_labels, estimator.r_std)}
    out.update({f"sigma_Q_{label}": float(v) for label, v in zip(layout.q_labels, estimator.q_std)})
    return out


def _train(dataset: str, config: FlexKalmanNetConfig, out: Path, progress: bool) -> TrainedModel:
    outcome = train_flexkalmannet(dataset, config, out=out, progress=progress, plots=False)
    history = outcome.history
    estimator = FlexKalmanNetEstimator.from_artifact(outcome.artifact)
    document = read_json(outcome.artifact)
    best = history[history["epoch"] == outcome.best_epoch]
    best_val = float(best["val_rmse"].iloc[0]) if len(best) else math.nan
    return TrainedModel(
        dataset=dataset,
        out=out,
        artifact=outcome.artifact,
        estimator=estimator,
        history=history,
        best_epoch=int(outcome.best_epoch),
        best_val_rmse=best_val,
        test_rmse=float(outcome.test["test_rmse"]),
        seconds_per_epoch=float(history["seconds"].mean()) if len(history) else math.nan,
        epochs_run=len(history),
        output_size=int(outcome.model.parameter_set.size),
        windows=int(document.get("training", {}).get("data", {}).get("windows", 0)),
        learned_std=named_std(estimator, config.variant),
    )


def _uncertainty_steps(trace: Any, window: int) -> float:
    """Steps until the angular-rate sigma (norm over the axes) has made 90% of its decrease
    between the first sample and sample ``window``."""
    sigma = figs.omega_sigma(trace, window)
    norm = np.sqrt(np.sum(np.square(sigma), axis=1))
    if len(norm) < 2 or not np.all(np.isfinite(norm)):
        return math.nan
    start, end = norm[0], norm[-1]
    if start <= end:
        return math.nan
    below = np.nonzero(norm <= end + 0.1 * (start - end))[0]
    return float(below[0]) if below.size else math.nan


def _config_summary(config: FlexKalmanNetConfig, quick: bool) -> str:
    plural = lambda n, word: f"{n} {word}" + ("" if n == 1 else "s")  # noqa: E731
    text = (f"{plural(config.layers, 'hidden layer')} of {config.hidden}, lr {config.lr:g}, up to "
            f"{plural(config.epochs, 'epoch')} (early stop {config.patience}), windows of {config.window} samples, "
            f"{plural(config.episodes, 'training recording')}, variant {config.variant}")
    return ("quick run: " if quick else "") + text


def _draw_figures(settings: ReproduceSettings, trained: dict[str, TrainedModel], constant: dict[str, Estimator],
                  ds1_trace: Any, fig_dir: Path, quick_tag: str) -> None:
    """The report's figures (paper Figs. 3-8 and the cross-data-set and training figures) into ``fig_dir``."""
    for dataset in ("ds2", "ds1"):
        model = trained[dataset]
        if len(model.history):
            plot_losses(model.history, fig_dir / f"training_loss_{dataset}.png",
                        title=f"Training and validation loss, {dataset.upper()}{quick_tag}", best_epoch=model.best_epoch)
            plot_parameters(model.history, fig_dir / f"parameters_{dataset}.png",
                            title=f"Learned standard deviations over epochs, {dataset.upper()}{quick_tag}")
    seed = settings.figure_seed
    title = f"EKF with the parameters learned from DS1, on DS1 (test split, seed {seed}){quick_tag}"
    save_figure(states_figure(ds1_trace, title=title), fig_dir / "states_ds1.png", dpi=110)
    title = (f"Angular-rate estimates with 2σ bands, DS1 parameters on DS1, first {settings.uncertainty_steps} "
             f"samples{quick_tag}")
    save_figure(figs.omega_uncertainty_figure(ds1_trace, steps=settings.uncertainty_steps, title=title),
                fig_dir / "omega_uncertainty_ds1.png", dpi=110)
    for scenario_name, label, stem, title in (
        ("ds1-noise5x", "learned-ds1", "states_ds1_noise5x", "DS1 parameters on DS1 with five times the noise"),
        ("ds1-gap100", "learned-ds1", "states_ds1_gap100", "DS1 parameters on DS1 with a measurement every 100 steps"),
        ("ds2", "learned-ds2", "states_ds2", "DS2 parameters on DS2"),
        ("ds2", "learned-ds1", "states_ds1_params_on_ds2", "DS1 parameters on DS2 (cross-data-set)"),
        ("ds1", "learned-ds2", "states_ds2_params_on_ds1", "DS2 parameters on DS1 (cross-data-set)"),
    ):
        trace = run_trace(constant[label], LABELS[label], get_scenario(scenario_name), seed)
        save_figure(states_figure(trace, title=f"EKF, {title} (test split, seed {seed}){quick_tag}"),
                    fig_dir / f"{stem}.png", dpi=110)


def run_reproduction(
    out: str | Path,
    settings: ReproduceSettings | None = None,
    *,
    progress: bool = True,
    log: Log | None = stderr_log,
) -> Reproduction:
    """Run the whole pipeline (module docstring) into ``out`` and return what it produced. ``out``
    is locked meanwhile (:func:`fkn_bench.io.directory_lock`: a second reproduction into it raises
    :class:`~fkn_bench.io.LockedError`); a file that cannot be written (a full disk) raises
    :class:`~fkn_bench.io.WriteError` naming it, and leaves what it would have replaced."""
    with directory_lock(out, "a reproduction"):
        for directory in (Path(out), Path(out) / "figures", Path(out) / "tables"):
            remove_temporaries(directory, recursive=False)  # (a killed run's; training/ cleans its own)
        return _run_reproduction(Path(out), settings or ReproduceSettings(), progress, log)


def _run_reproduction(out: Path, settings: ReproduceSettings, progress: bool, log: Log | None) -> Reproduction:
    say = log or (lambda message: None)
    config = settings.training_config()
    seeds = list(range(settings.n_eval_seeds))
    seconds: dict[str, float] = {}
    began = time.perf_counter()

    # 1. training
    trained: dict[str, TrainedModel] = {}
    for dataset in DATASETS:
        say(f"[reproduce] training FlexKalmanNet on {dataset} ({_config_summary(config, settings.quick)})")
        t0 = time.perf_counter()
        trained[dataset] = _train(dataset, config, out / "training" / dataset, progress)
        seconds[f"train_{dataset}"] = time.perf_counter() - t0
        model = trained[dataset]
        say(f"[reproduce]   {model.epochs_run} epochs, best {model.best_epoch}, val RMSE {model.best_val_rmse:.5f}, "
            f"{seconds[f'train_{dataset}']:.0f} s")

    # 2. evaluation
    say(f"[reproduce] evaluating on {len(seeds)} test seeds")
    t0 = time.perf_counter()
    constant: dict[str, Estimator] = {
        "learned-ds1": trained["ds1"].estimator,
        "learned-ds2": trained["ds2"].estimator,
        "manual": make_estimator(f"manual-{config.variant}"),  # the paper's manual tuning, same variant
    }
    plan = {
        "ds1": ("learned-ds1", "learned-ds2", "manual", "oracle"),
        "ds2": ("learned-ds2", "learned-ds1", "manual", "oracle"),
        "ds1-noise5x": ("learned-ds1", "manual", "oracle"),
        "ds1-gap100": ("learned-ds1", "manual", "oracle"),
    }
    oracles = {name: make_estimator("oracle-ekf", scenario=get_scenario(name)) for name in plan}  # true noise
    evaluations: dict[tuple[str, str], Evaluation] = {}
    for scenario_name, labels in plan.items():
        for label in labels:
            estimator = oracles[scenario_name] if label == "oracle" else constant[label]
            evaluations[(label, scenario_name)] = evaluate(estimator, label, get_scenario(scenario_name), seeds)
    seconds["evaluate"] = time.perf_counter() - t0

    # 3. figures (the DS1 trace also feeds the differences section, so it is computed either way)
    say("[reproduce] drawing figures" if settings.figures else "[reproduce] no figures (--no-figures)")
    t0 = time.perf_counter()
    fig_dir = out / "figures"
    quick_tag = " [QUICK RUN]" if settings.quick else ""
    ds1_trace = run_trace(constant["learned-ds1"], "learned DS1", get_scenario("ds1"), settings.figure_seed)
    uncertainty_steps = _uncertainty_steps(ds1_trace, settings.uncertainty_steps)
    if settings.figures:
        _draw_figures(settings, trained, constant, ds1_trace, fig_dir, quick_tag)
    captions = {
        "training_loss_ds2": "Paper Fig. 3: training (blue) and validation (orange) RMSE per epoch, DS2.",
        "parameters_ds2": "Paper Fig. 4: the 20 learned standard deviations over the epochs, DS2.",
        "training_loss_ds1": "Training and validation loss per epoch, DS1 (not shown in the paper).",
        "parameters_ds1": "The learned standard deviations over the epochs, DS1 (not shown in the paper).",
        "states_ds1": "Paper Fig. 5: EKF with the DS1 parameters on DS1: estimate, measurement and truth of the four "
                      "state groups.",
        "omega_uncertainty_ds1": "Paper Fig. 6: angular-rate estimates with their 2σ band over the first "
                                 f"{settings.uncertainty_steps} samples of DS1.",
        "states_ds1_noise5x": "Paper Fig. 7: DS1 parameters on DS1 with five times the measurement noise.",
        "states_ds1_gap100": "Paper Fig. 8: DS1 parameters on DS1 with a measurement every 100 steps.",
        "states_ds2": "DS2 parameters on DS2 (the paper omits this plot for brevity).",
        "states_ds1_params_on_ds2": "Cross-data-set: DS1 parameters on DS2 (the paper describes it in words only).",
        "states_ds2_params_on_ds1": "Cross-data-set: DS2 parameters on DS1 (the paper describes it in words only).",
    }
    figure_list = [FigureRef(f"figures/{stem}.png", caption + quick_tag) for stem, caption in captions.items()
                   if (fig_dir / f"{stem}.png").is_file()]
    seconds["figures"] = time.perf_counter() - t0

    # 4. tables and differences
    manual_std = named_std(constant["manual"], config.variant)
    oracle_std = named_std(oracles["ds1"], "ekf")
    tables = {
        "hyperparameters": hyperparameter_table(config, trained["ds1"].output_size, quick=settings.quick),
        "training_results": training_table(trained),
        "learned_std": learned_std_table(trained, manual_std, oracle_std),
        "rmse_learned_vs_manual": rmse_table(evaluations[("learned-ds1", "ds1")], evaluations[("manual", "ds1")],
                                             evaluations.get(("oracle", "ds1"))),
        "cross_dataset": cross_dataset_table(evaluations, LABELS),
        "robustness": robustness_table(evaluations, LABELS),
    }
    context = Context(
        trained=trained,
        evaluations=evaluations,
        true_std=oracle_std,
        uncertainty_steps=uncertainty_steps,
        uncertainty_window=settings.uncertainty_steps,
        quick=settings.quick,
        config_summary=_config_summary(config, settings.quick),
        epoch_summary=(f"{trained['ds1'].windows} training windows of {config.window} samples from "
                       f"{_recordings(config.episodes)}, {config.windows_per_batch} per step, plus one validation "
                       "pass"),
    )
    bullets = differences(context)
    seconds["total"] = time.perf_counter() - began

    reproduction = Reproduction(out, settings, config, trained, evaluations, tables, figure_list, bullets, seconds)
    _write(reproduction)
    say(f"[reproduce] report written to {out / 'index.md'} and {out / 'index.html'} ({seconds['total']:.0f} s)")
    return reproduction


def _recordings(count: int) -> str:
    return "recording 0" if count == 1 else f"recordings 0-{count - 1}"


def _figures(reproduction: Reproduction, *stems: str) -> list[Block]:
    """The drawn figures among ``stems``, in that order."""
    drawn = {f.path: f for f in reproduction.figures}
    return [drawn[path] for stem in stems if (path := f"figures/{stem}.png") in drawn]


def _blocks(r: Reproduction) -> list[Block]:
    s = r.settings
    quick = s.quick
    title = "Reproduction of FlexKalmanNet's results" + (" — QUICK RUN (not a reproduction)" if quick else "")
    command = ("fkn-bench reproduce" + (" --quick" if quick else "") + f" --seed {s.seed} --seeds {s.n_eval_seeds}"
               + (f" --config {s.config_source}" if s.config_source else ""))
    blocks: list[Block] = [Heading(title, 1)]
    if quick:
        blocks.append(Paragraph(
            "**QUICK RUN.** Generated by `fkn-bench reproduce --quick`: a much smaller network trained for a few "
            "epochs and fewer evaluation seeds, to test the pipeline. Run `fkn-bench reproduce` for the real numbers."
        ))
    blocks += [
        Paragraph(
            f"Every table and figure of the results section of {PAPER_TITLE}, regenerated from scratch (simulated data, "
            f"training, evaluation) by `{command}` in {r.seconds.get('total', math.nan):.0f} s. Columns and rows marked "
            "\"paper (quoted)\" are the paper's printed numbers; everything else was computed by this run. Training: "
            f"{_config_summary(r.config, quick)}, seed {r.config.seed}, on the train splits (first 80%) of "
            f"{_recordings(r.config.episodes)} of each data set. Evaluation: the test splits (last 10%, never trained "
            f"on) of {_recordings(s.n_eval_seeds)}, a measurement every 10 steps, scored from step 100 (the paper's "
            f"protocol); figures from recording {s.figure_seed}."
        ),
        Heading("Differences from the paper (generated from the numbers)"),
        Bullets(tuple(r.differences)),
        Heading("Training"),
        r.tables["hyperparameters"],
        r.tables["training_results"],
        *_figures(r, "training_loss_ds2", "parameters_ds2", "training_loss_ds1", "parameters_ds1"),
        Heading("Learned parameters"),
        r.tables["learned_std"],
        Heading("Evaluation on DS1"),
        *_figures(r, "states_ds1", "omega_uncertainty_ds1"),
        r.tables["rmse_learned_vs_manual"],
        Heading("Robustness: 5x noise and 100-step gaps"),
        *_figures(r, "states_ds1_noise5x", "states_ds1_gap100"),
        r.tables["robustness"],
        Heading("Cross-data-set runs"),
        r.tables["cross_dataset"],
        *_figures(r, "states_ds2", "states_ds1_params_on_ds2", "states_ds2_params_on_ds1"),
        Heading("Files"),
        Bullets((
            "`training/ds1/`, `training/ds2/`: checkpoint, `history.csv` and the learned parameters "
            "(`parameters.json`: `make_estimator(\"flexkalmannet\", parameters=\"training/ds1/parameters.json\")` "
            "runs the learned filter)",
            "`tables/*.csv`: every table above; `results.json`: every number, the configuration, timings and provenance",
            "`figures/*.png`: the figures above; `index.html`: this report as HTML",
        )),
    ]
    return blocks


def _write(r: Reproduction) -> None:
    from fkn_bench.training.artifacts import run_provenance

    write_report(r.out, _blocks(r), title="FlexKalmanNet reproduction" + (" (quick)" if r.settings.quick else ""))
    write_json_atomic(r.out / "results.json", {
        "quick": r.settings.quick,
        "seed": r.settings.seed,
        "config_source": r.settings.config_source,
        "eval_seeds": r.settings.n_eval_seeds,
        "figure_seed": r.settings.figure_seed,
        "config": r.config.to_dict(),
        "training": {k: v.to_dict() for k, v in r.trained.items()},
        "evaluations": [e.to_dict() for e in r.evaluations.values()],
        "differences": r.differences,
        "figures": [f.path for f in r.figures],
        "tables": sorted(r.tables),
        "seconds": r.seconds,
        "provenance": run_provenance(),
    })
