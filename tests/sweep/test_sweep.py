"""Sweeps end to end: a tiny two-stage sweep with two worker processes on one journal file (with
pruning), invalid and failing trials, another trainable estimator (pruned too), and the CLI's
usage errors."""

from __future__ import annotations

import csv
import json
import os
import tomllib
from pathlib import Path
from typing import Any

import optuna
import pytest
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import FrozenTrial, TrialState

from fkn_bench.cli import main
from fkn_bench.flexkalmannet import FlexKalmanNetConfig
from fkn_bench.scenarios import get_scenario
from fkn_bench.sweep import SweepTask, make_objective, parse_space
from fkn_bench.sweep.objective import CATCH

pytestmark = pytest.mark.slow(seconds=15)  # a sweep in two worker processes

SCENARIO_FILE = """
[scenario.sweep-tiny]
base = "ds1"
n_steps = 3000
"""

# a small network on 3000 samples: a trial takes about a second per epoch
FIXED = """
[fixed]
hidden = 8
layers = 1
epochs = 2
window = 200
loss_cut = 50
samples_per_window = 8
windows_per_batch = 4
episodes = 1
"""

SPACE = FIXED + """
[sweep]
scenario = "sweep-tiny"
sampler = "random-grid"
trials = 4
grid_trials = 2
top_k = 2

[sweep.pruner]
kind = "median"
n_startup_trials = 1
n_warmup_steps = 0

[params.lr]
values = [1e-6, 0.1]

[params.patience]
values = [2, 3]
"""


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The tiny sweep, run once. Its random stage is seeded through the journal with two good
    trials (lr 0.1: the validation RMSE drops in the first epoch; they differ only in the early-
    stopping patience, which two epochs never reach, so their losses are identical and neither
    prunes the other) followed by two that cannot learn (lr 1e-6): with two workers each bad trial
    starts after a good one finished, so the median pruner stops it after its first epoch whatever
    the scheduling."""
    root = tmp_path_factory.mktemp("sweep")
    (root / "scenarios.toml").write_text(SCENARIO_FILE)
    (root / "space.toml").write_text(SPACE)
    journal = root / "study.journal"
    storage = JournalStorage(JournalFileBackend(str(journal)))
    study = optuna.create_study(storage=storage, study_name="tiny.random", direction="minimize")
    for lr, patience in ((0.1, 2), (0.1, 3), (1e-6, 2), (1e-6, 3)):
        study.enqueue_trial({"lr": lr, "patience": patience})
    argv = ["sweep", "--space", str(root / "space.toml"), "--scenario-file", str(root / "scenarios.toml"),
            "--workers", "2", "--storage", str(journal), "--study-name", "tiny", "--out", str(root / "out"),
            "--no-progress"]
    code = main(argv)
    return {"root": root, "out": root / "out", "journal": journal, "code": code, "argv": argv}


def test_tiny_sweep_with_two_workers_on_one_journal(sweep: dict[str, Any]) -> None:
    assert sweep["code"] == 0
    out = sweep["out"]
    rows = _rows(out / "trials.csv")
    random_stage = [r for r in rows if r["stage"] == "random"]
    grid_stage = [r for r in rows if r["stage"] == "grid"]
    assert len(random_stage) == 4 and len(grid_stage) == 2
    states = [(float(r["params_lr"]), r["state"]) for r in random_stage]
    assert sorted(states) == [(1e-6, "PRUNED"), (1e-6, "PRUNED"), (0.1, "COMPLETE"), (0.1, "COMPLETE")]
    pruned = [r for r in random_stage if r["state"] == "PRUNED"]
    assert all(r["last_epoch_reported"] == "1" for r in pruned)
    assert all(r["state"] == "COMPLETE" for r in grid_stage)
    # every trial ran in a worker process, not in the test's
    assert all(int(float(r["user_attrs_process"])) != os.getpid() for r in rows)
    # the reduced grid spans the best two random trials within the budget of 2 points
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["grid"] == {"lr": [0.1], "patience": [2, 3]}
    assert summary["counts"]["random"]["pruned"] == 2
    names = optuna.get_all_study_names(JournalStorage(JournalFileBackend(str(sweep["journal"]))))
    assert sorted(names) == ["tiny.grid", "tiny.random"]


def test_sweep_outputs_best_config_csv_and_figure(sweep: dict[str, Any]) -> None:
    out = sweep["out"]
    config = FlexKalmanNetConfig.from_toml(out / "best.toml")
    assert config.hidden == 8 and config.window == 200 and config.lr == 0.1 and config.patience in (2, 3)
    rows = [r for r in _rows(out / "trials.csv") if r["state"] == "COMPLETE"]
    best = min(rows, key=lambda r: float(r["value"]))
    assert float(best["params_lr"]) == config.lr and int(best["params_patience"]) == config.patience
    assert (out / "parallel_coordinates.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    header = (out / "best.toml").read_text().splitlines()[0]
    assert header.startswith("# Best configuration of fkn-bench sweep study 'tiny'")


def test_rerunning_a_finished_sweep_adds_no_trials(sweep: dict[str, Any]) -> None:
    assert main(sweep["argv"]) == 0
    assert len(_rows(sweep["out"] / "trials.csv")) == 6


def test_an_invalid_trial_fails_without_stopping_the_study(tmp_path: Path) -> None:
    text = FIXED.replace("loss_cut = 50\n", "") + "\n[params.loss_cut]\nvalues = [50, 300]\n"
    space = parse_space(tomllib.loads(text), "inline")
    task = SweepTask("flexkalmannet", get_scenario("ds1", n_steps=3000), space)
    study = optuna.create_study(direction="minimize")
    study.enqueue_trial({"loss_cut": 300})  # loss_cut >= window: refused
    study.enqueue_trial({"loss_cut": 50})
    study.optimize(make_objective(task), n_trials=2, catch=CATCH)
    failed, done = study.trials
    assert failed.state == TrialState.FAIL and "loss_cut" in failed.user_attrs["error"]
    assert done.state == TrialState.COMPLETE and done.user_attrs["epochs_run"] == 2
    assert sorted(done.intermediate_values) == [1, 2] and done.value == min(done.intermediate_values.values())


def test_any_trainable_estimator_is_swept_and_pruned_through_on_epoch(tmp_path: Path) -> None:
    """The sweep names no estimator: a tuned EKF trains through the same fit() and on_epoch, so
    its trials report every epoch, are pruned, and fail on invalid options."""
    space = parse_space({"fixed": {"window": 200, "loss_cut": 50, "episodes": 1, "epochs": 2, "lbfgs_iterations": 2},
                         "params": {"lr": {"values": [-1.0, 1.0, 1e-9]}}}, "inline")
    class PruneTinySteps(optuna.pruners.BasePruner):
        def prune(self, study: optuna.Study, trial: FrozenTrial) -> bool:
            return trial.params["lr"] < 1e-6

    study = optuna.create_study(direction="minimize", pruner=PruneTinySteps())
    for lr in (-1.0, 1.0, 1e-9):
        study.enqueue_trial({"lr": lr})
    task = SweepTask("direct-tuned-ekf", get_scenario("ds1", n_steps=3000), space)
    study.optimize(make_objective(task), n_trials=3, catch=CATCH)
    failed, done, pruned = study.trials
    assert failed.state == TrialState.FAIL and "lr" in failed.user_attrs["error"]
    assert done.state == TrialState.COMPLETE and sorted(done.intermediate_values) == [1, 2]
    assert done.value == done.intermediate_values[done.user_attrs["best_epoch"]]
    assert pruned.state == TrialState.PRUNED and sorted(pruned.intermediate_values) == [1]
    assert not any(tmp_path.iterdir())  # trials write no files


def test_a_non_trainable_estimator_is_swept_over_its_options(tmp_path: Path) -> None:
    """Issue 21: an adaptive filter's options are searched with FlexKalmanNet's objective, the
    validation 13-state RMSE of one run over the val split; invalid options fail their trial."""
    import math

    import numpy as np
    import torch

    from fkn_bench.estimators import make_estimator
    from fkn_bench.sweep.objective import _validation_data
    from fkn_bench.training.objectives import state_mse

    scenario = get_scenario("ds1", n_steps=3000)
    space = parse_space({"fixed": {"warmup": 20}, "params": {"forgetting": {"values": [1.5, 0.97]}}}, "inline")
    study = optuna.create_study(direction="minimize")
    for forgetting in (1.5, 0.97):
        study.enqueue_trial({"forgetting": forgetting})
    study.optimize(make_objective(SweepTask("sage-husa-default", scenario, space)), n_trials=2, catch=CATCH)
    failed, done = study.trials
    assert failed.state == TrialState.FAIL and "forgetting" in failed.user_attrs["error"]
    val, cut = _validation_data(scenario)
    means = make_estimator("sage-husa-default", forgetting=0.97, warmup=20).estimate(
        val.measurements.numpy().copy(), val.mask.numpy().copy(), scenario.dt).means
    expected = math.sqrt(float(state_mse(torch.from_numpy(np.ascontiguousarray(means)), val.truth, cut)))
    assert done.value == pytest.approx(expected, rel=1e-12) and done.intermediate_values == {1: done.value}
    # a validation split no longer than the loss cut fails the trial (it was a traceback out of the sweep)
    short = optuna.create_study(direction="minimize")
    short.enqueue_trial({"forgetting": 0.97})  # valid options: the split is what fails (no unseeded draw)
    short.optimize(make_objective(SweepTask("sage-husa-default", get_scenario("ds1", n_steps=1000), space)), n_trials=1,
                   catch=CATCH)
    assert short.trials[0].state == TrialState.FAIL and "loss_cut 100 leaves no steps" in short.trials[0].user_attrs["error"]


def test_cli_usage_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    space = tmp_path / "space.toml"
    space.write_text("[params.hiddn]\nvalues = [8, 16]\n")
    assert main(["sweep", "--space", str(space), "--out", str(tmp_path / "o")]) == 2
    assert "hiddn" in capsys.readouterr().err
    assert main(["sweep", "--space", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "not found" in capsys.readouterr().err
    space.write_text("[params.lr]\nlow = 1e-4\nhigh = 1e-2\n")
    assert main(["sweep", "--space", str(space), "--sampler", "grid", "--out", str(tmp_path / "o")]) == 2
    assert "grid_points" in capsys.readouterr().err
    assert main(["sweep", "--space", "quick", "--estimator", "manual-ekf", "--out", str(tmp_path / "o")]) == 2
    assert "manual-ekf is not trainable, so a sweep searches its options" in capsys.readouterr().err
    assert main(["sweep", "--space", "quick", "--write-artifact", "--out", str(tmp_path / "o")]) == 2
    assert "train flexkalmannet with the sweep's best.toml instead" in capsys.readouterr().err
    assert main(["sweep", "--space", "quick", "--workers", "0", "--out", str(tmp_path / "o")]) == 2
    assert "workers" in capsys.readouterr().err
    space.write_text("[fixed]\nepochs = 0\n[params.lr]\nvalues = [0.01]\n")
    assert main(["sweep", "--space", str(space), "--out", str(tmp_path / "o")]) == 2
    assert "epochs" in capsys.readouterr().err


KILL_SCENARIO = '[scenario.sweep-kill]\nbase = "ds1"\nn_steps = 1500\n'  # (1200 train samples, 150 val)
KILL_SPACE = """
[sweep]
estimator = "sage-husa-default"   # not trained: a trial is one filter run over the val split
scenario = "sweep-kill"
sampler = "random-grid"
trials = 2
grid_trials = 2
top_k = 2

[params.forgetting]
low = 0.9
high = 0.999
grid_points = 2

[params.warmup]
values = [0, 20]
"""


def _finished(out: Path) -> list[tuple[str, str, str, str]]:
    """(stage, forgetting, warmup, value) of the trials of a sweep that ran, in order."""
    return [(r["stage"], r["params_forgetting"], r["params_warmup"], r["value"]) for r in _rows(out / "trials.csv")
            if r["state"] == "COMPLETE"]


def test_a_killed_sweep_retries_its_interrupted_trials_to_the_uninterrupted_result(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 34, finding 6: a killed sweep left its trial RUNNING, counted against --trials, and a
    new invocation drew the first invocation's points again. Killed in the random stage, stopped by
    Ctrl-C in the grid stage, and run again each time, the sweep gives the uninterrupted one's
    trials and values; a second sweep into the same directory is refused while one runs."""
    from fkn_bench.io import directory_lock
    from fkn_bench.sweep import runner
    from tests.conftest import SimulatedKill

    (tmp_path / "scenarios.toml").write_text(KILL_SCENARIO)
    (tmp_path / "space.toml").write_text(KILL_SPACE)
    monkeypatch.setattr(runner, "parallel_coordinates", lambda *args: None)  # (the figure: a second per sweep)

    def sweep(out: str) -> int:
        return main(["sweep", "--space", str(tmp_path / "space.toml"), "--scenario-file", str(tmp_path / "scenarios.toml"),
                     "--out", str(tmp_path / out), "--no-progress"])

    assert sweep("straight") == 0
    real, kills = runner.make_objective, {("random", 1), ("grid", 1)}

    def dying(task: SweepTask):  # noqa: ANN202 - SIGKILL while the trial runs: optuna leaves it RUNNING
        objective = real(task)

        def run(trial: optuna.Trial) -> float:
            point = (trial.study.study_name.rpartition(".")[2], trial.number)
            if point in kills:
                kills.discard(point)
                task.space.suggest(trial)
                raise SimulatedKill(f"killed in {point}") if point[0] == "random" else KeyboardInterrupt
            return objective(trial)

        return run

    monkeypatch.setattr(runner, "make_objective", dying)
    with pytest.raises(SimulatedKill):  # SIGKILL in the random stage: optuna leaves the trial RUNNING
        sweep("killed")
    storage = JournalStorage(JournalFileBackend(str(tmp_path / "killed" / "study.journal")))
    study = optuna.load_study(study_name="sage-husa-default-sweep-kill.random", storage=storage)
    assert [t.number for t in study.trials if t.state == TrialState.RUNNING] == [1]
    assert sweep("killed") == 130  # Ctrl-C in the grid stage: optuna fails the trial
    assert "run the same command again to go on" in capsys.readouterr().err
    with directory_lock(tmp_path / "killed"):
        assert sweep("killed") == 2
    assert "in use by another fkn-bench process" in capsys.readouterr().err
    assert sweep("killed") == 0
    assert _finished(tmp_path / "killed") == _finished(tmp_path / "straight")
    counts = json.loads((tmp_path / "killed" / "sweep.json").read_text())["counts"]
    assert counts == {stage: {"complete": n, "pruned": 0, "fail": 0, "running": 0, "interrupted": 1}
                      for stage, n in (("random", 2), ("grid", 2))}
    settings = [[line for line in (tmp_path / out / "best.toml").read_text().splitlines() if not line.startswith("#")]
                for out in ("killed", "straight")]  # (the header names the best trial's number: the retry's)
    assert settings[0] == settings[1]
