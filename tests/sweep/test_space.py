"""Search-space parsing, its errors, the packaged spaces, the reduced grid and the TOML writer."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import optuna
import pytest
from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution
from optuna.trial import FrozenTrial, TrialState

from fkn_bench.flexkalmannet import FlexKalmanNetConfig
from fkn_bench.sweep import (
    SpaceError,
    load_space,
    packaged_spaces,
    parse_space,
    reduced_grid,
    resolve_space,
    trial_config,
    write_toml,
)

FIELDS = [f.name for f in dataclasses.fields(FlexKalmanNetConfig)]


def _space(text: str):
    return parse_space(tomllib.loads(text), "test.toml")


def test_kinds_distributions_and_grids() -> None:
    space = _space("""
        [sweep]
        sampler = "tpe"
        trials = 5
        [sweep.pruner]
        kind = "percentile"
        percentile = 40.0
        [fixed]
        epochs = 3
        [params.hidden]
        values = [16, 32]
        [params.layers]
        low = 1
        high = 3
        [params.lr]
        low = 1e-4
        high = 1e-2
        log = true
        grid_points = 3
        [params.dropout]
        low = 0.0
        high = 0.2
        step = 0.1
        [params.learn]
        values = ["q_std,r_std", "q_chol,r_std"]
    """)
    assert space.names == ["hidden", "layers", "lr", "dropout", "learn"]
    assert space.fixed == {"epochs": 3} and space.defaults == {"sampler": "tpe", "trials": 5}
    assert space.pruner.kind == "percentile" and isinstance(space.pruner.make(), optuna.pruners.PercentilePruner)
    distributions = space.distributions()
    assert isinstance(distributions["hidden"], CategoricalDistribution)
    assert distributions["layers"] == IntDistribution(1, 3)
    assert distributions["lr"] == FloatDistribution(1e-4, 1e-2, log=True)
    grid = space.grid()
    assert grid["layers"] == [1, 2, 3] and grid["dropout"] == [0.0, 0.1, 0.2]
    assert grid["lr"] == pytest.approx([1e-4, 1e-3, 1e-2])
    space.check_fields(FIELDS, "FlexKalmanNetConfig")
    config = trial_config("flexkalmannet", space, {"hidden": 16, "layers": 2, "lr": 1e-3, "dropout": 0.1, "learn": "q_chol,r_std"})
    assert config.learn == ("q_chol", "r_std") and config.epochs == 3 and config.hidden == 16


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[params.hidden]\nvalues = []", "non-empty list"),
        ("[params.hidden]\nvalues = [1, 1]", "duplicates"),
        ("[params.hidden]\nvalues = [1]\nlow = 1", "cannot be combined"),
        ("[params.hidden]\nlow = 1", "both `low` and `high`"),
        ("[params.lr]\nlow = 0.1\nhigh = 0.01", "low < high"),
        ("[params.lr]\nlow = 0.0\nhigh = 0.1\nlog = true", "low > 0"),
        ("[params.lr]\nlow = 0.1\nhigh = 1.0\nlog = true\nstep = 0.1", "`step` cannot"),
        ("[params.lr]\nlow = 0.1\nhigh = 1.0\ngrid = [2.0]", "outside"),
        ("[params.lr]\nlow = 0.1\nhigh = 1.0\ngrid = [0.5]\ngrid_points = 3", "not both"),
        ("[params.lr]\nlow = 0.1\nhigh = 1.0\nlogg = true", "unknown key(s) logg"),
        ("[params.lr]\nlow = 1.5\nhigh = 3\ntype = \"int\"", "integer bounds"),
        ("[params.lr]\nlow = 1\nhigh = 3\ntype = \"str\"", "`type`"),
        ("[params.hidden]\nvalues = [[1]]", "numbers, strings or booleans"),
        ("[fixed]\nhidden = 3\n[params.hidden]\nvalues = [1, 2]", "both fixed and searched"),
        ("[sweep]\nsampler = \"bayes\"\n[params.hidden]\nvalues = [1, 2]", "sampler must be one of"),
        ("[sweep]\ntrials = 0\n[params.hidden]\nvalues = [1, 2]", "trials must be an integer >= 1"),
        ("[sweep]\nworkers = 2\n[params.hidden]\nvalues = [1, 2]", "unknown key(s) workers"),
        ("[sweep.pruner]\nkind = \"asha\"\n[params.hidden]\nvalues = [1, 2]", "kind must be one of"),
        ("[searchspace]\nx = 1\n[params.hidden]\nvalues = [1, 2]", "unknown table(s) searchspace"),
        ("[fixed]\nepochs = 3", "no knobs"),
    ],
)
def test_invalid_spaces_are_refused_with_the_reason(text: str, message: str) -> None:
    with pytest.raises(SpaceError, match="test.toml") as info:
        _space(text)
    assert message in str(info.value)


def test_field_and_grid_errors() -> None:
    space = _space("[fixed]\nepochz = 3\n[params.hiddn]\nvalues = [1, 2]\n[params.lr]\nlow = 0.1\nhigh = 1.0")
    with pytest.raises(SpaceError, match="hiddn, epochz"):
        space.check_fields(FIELDS, "FlexKalmanNetConfig")
    with pytest.raises(SpaceError, match=r"\[params.lr\] is a continuous range"):
        space.grid()
    wide = _space("[params.window]\nlow = 100\nhigh = 1000")
    with pytest.raises(SpaceError, match="901 integer values"):
        wide.grid()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('[fixed]\nepochs = true\n[params.lr]\nvalues = [0.1]', r"test.toml: \[fixed\] epochs must be an integer \(got True\)"),
        ('[params.lr]\nvalues = ["0.1", 0.2]', r"test.toml: \[params.lr\] value '0.1' is not a finite number, the kind of lr"),
        ("[params.hidden]\nlow = 8.0\nhigh = 16.0", r"\[params.hidden\] value 8.0 is not an integer"),
        ("[params.lr]\nvalues = [nan]", r"\[params.lr\] value nan is not a finite number"),
    ],
)
def test_values_of_the_wrong_kind_for_their_field_are_refused(text: str, message: str) -> None:
    """Issue 34, finding 5: a space's numbers are numbers of the field's kind, checked before any
    trial (a trial with lr = "0.1" failed only when it ran)."""
    import typing

    with pytest.raises(SpaceError, match=message):
        _space(text).check_kinds(typing.get_type_hints(FlexKalmanNetConfig))


def test_files_and_packaged_spaces(tmp_path: Path) -> None:
    assert {"paper", "quick"} <= set(packaged_spaces())
    for name in ("paper", "quick"):
        space = load_space(resolve_space(name))
        space.check_fields(FIELDS, "FlexKalmanNetConfig")
        trial_config("flexkalmannet", space, {})
        assert space.defaults["sampler"] == "random-grid"
    seeds = load_space(resolve_space("kalmannet-seeds"))  # KalmanNet's training robustness: ten seeds
    assert seeds.defaults["estimator"] == "kalmannet" and seeds.pruner.kind == "none"
    assert [trial_config("kalmannet", seeds, {"seed": s}).train_config().seed for s in (0, 9)] == [0, 9]
    study = load_space(resolve_space("seeds"))  # any trainable estimator's training-seed study
    assert "estimator" not in study.defaults and study.pruner.kind == "none" and study.names == ["seed"]
    from fkn_bench.estimators.registry import estimator_specs

    for name in sorted(s.name for s in estimator_specs() if s.trainable is not None):
        assert [trial_config(name, study, {"seed": s}).train_config().seed for s in (0, 2)] == [0, 2], name
    paper = load_space(resolve_space("paper"))
    assert {"hidden", "layers", "lr", "window", "loss_cut", "dropout", "weight_decay", "activation", "variant",
            "objective"} <= set(paper.names)
    with pytest.raises(SpaceError, match="packaged spaces: .*paper"):
        resolve_space(tmp_path / "missing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("[params.hidden\nvalues = [1]")
    with pytest.raises(SpaceError, match="not valid TOML"):
        load_space(broken)


def _trial(number: int, value: float | None, state: TrialState = TrialState.COMPLETE, **params) -> FrozenTrial:
    distributions = {
        "hidden": CategoricalDistribution([16, 32, 64]),
        "lr": FloatDistribution(1e-4, 1e-1, log=True),
        "layers": IntDistribution(1, 4),
    }
    return FrozenTrial(number=number, state=state, value=value, datetime_start=None, datetime_complete=None,
                       params=params, distributions=distributions, user_attrs={}, system_attrs={},
                       intermediate_values={}, trial_id=number)


def test_reduced_grid_takes_the_best_trials_values_within_the_budget() -> None:
    space = _space("""
        [params.hidden]
        values = [16, 32, 64]
        [params.lr]
        low = 1e-4
        high = 1e-1
        log = true
        [params.layers]
        low = 1
        high = 4
    """)
    trials = [
        _trial(0, 0.30, hidden=16, lr=0.012345, layers=1),
        _trial(1, 0.10, hidden=64, lr=0.0123456, layers=3),   # best
        _trial(2, 0.20, hidden=32, lr=0.00051, layers=3),     # second
        _trial(3, 0.15, hidden=64, lr=0.0021, layers=2),      # third
        _trial(4, None, TrialState.PRUNED, hidden=16, lr=0.09, layers=4),
        _trial(5, None, TrialState.FAIL, hidden=16, lr=0.09, layers=4),
    ]
    grid = reduced_grid(trials, space, top_k=3, budget=100)
    assert grid == {"hidden": [64, 32], "lr": [0.000510, 0.00210, 0.0123], "layers": [2, 3]}
    # over budget: drop the values whose best trial ranks lowest until the grid fits
    small = reduced_grid(trials, space, top_k=3, budget=4)
    assert math.prod(len(v) for v in small.values()) <= 4
    assert small["hidden"][0] == 64 and 0.0123 in small["lr"] and 3 in small["layers"]
    assert reduced_grid(trials, space, top_k=3, budget=1) == {"hidden": [64], "lr": [0.0123], "layers": [3]}
    with pytest.raises(ValueError, match="no completed trial"):
        reduced_grid(trials[4:], space, top_k=3, budget=4)


def test_written_toml_reads_back_as_a_config(tmp_path: Path) -> None:
    config = FlexKalmanNetConfig(hidden=24, lr=3e-4, learn=("q_std", "r_std"), dropout=0.0, max_grad_norm=None)
    path = write_toml(tmp_path / "best.toml", config.to_dict(), table="flexkalmannet", header="line one\nline two")
    text = path.read_text()
    assert text.startswith("# line one\n# line two\n") and "# max_grad_norm: None" in text
    assert FlexKalmanNetConfig.from_toml(path) == config
