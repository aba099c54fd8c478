"""Training-seed studies: the median-validation choice, the installed study, every seed buildable
with training_seed=K, and the leaderboards' training-seed spread (a study, then the harness)."""

from __future__ import annotations

import io
import json
import math
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest

from fkn_bench.estimators import make_estimator, registry
from fkn_bench.filters import ParameterSet, make_filter
from fkn_bench.harness import ResultStore, SimulatedSource, build_grid, run_grid, select_estimators
from fkn_bench.reporting.leaderboard import build_leaderboards
from fkn_bench.reporting.report import format_number
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import DirectParameters, Trainable, TrainConfig
from fkn_bench.training import artifacts
from fkn_bench.training.artifacts import ArtifactError, read_artifact, seed_artifact_path
from fkn_bench.training.seeds import install_seed_study, median_seed, train_seeds

SHORT = get_scenario("ds1", n_steps=2000)
OPTIONS = {"window": 200, "loss_cut": 50, "episodes": 1, "epochs": 2, "lr": 0.05, "windows_per_batch": 2}
NAME = "seed-study-test-ekf"
REPO = Path(__file__).resolve().parents[2]


def test_the_median_validation_seed_is_chosen() -> None:
    assert median_seed({0: 0.3, 1: 0.1, 2: 0.2}) == 2
    assert median_seed({5: 0.2, 3: 0.2, 9: 0.2}) == 5  # ties ordered by seed: 3, 5, 9
    assert median_seed({0: 0.4, 1: 0.1, 2: 0.3, 3: 0.2}) == 3  # an even count: the lower middle
    assert median_seed({0: math.nan, 1: 0.5, 2: 0.1}) == 2  # a diverged seed takes no part
    with pytest.raises(ValueError, match="no seed has a finite validation RMSE"):
        median_seed({0: math.inf})


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[object, Path]]:
    """A third-party trainable estimator's 3-seed study, installed into a params folder of its own."""
    params = tmp_path_factory.mktemp("params")
    trainable = Trainable(config=lambda options: TrainConfig(**{**OPTIONS, **options}),
                          build=lambda config, data: DirectParameters(ParameterSet(make_filter(config.variant).layout)))
    registry.register_estimator(NAME, artifacts.artifact_factory(NAME), trainable=trainable, overwrite=True,
                                params_package="fkn_bench")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(artifacts, "params_dir", lambda package: params)
        study = train_seeds(NAME, [SHORT], {}, [0, 1, 2], out=tmp_path_factory.mktemp("study"), progress=False)
        install_seed_study(study)
        yield study, params
    registry._REGISTRY.pop(NAME, None)


def test_a_study_trains_every_seed_and_installs_the_median_one(installed: tuple[object, Path]) -> None:
    study, params = installed
    values = {run.seed: run.val_rmse for run in study.runs}
    assert [run.status for run in study.runs] == ["ok"] * 3 and len(set(values.values())) == 3  # seeds differ
    assert study.chosen == median_seed(values)
    recorded = json.loads((Path(study.chosen_run.out).parent / "seed_study.json").read_text())
    assert recorded["chosen_seed"] == study.chosen and [r["seed"] for r in recorded["runs"]] == [0, 1, 2]
    main = read_artifact(params / f"{NAME}-ds1.json")
    assert main["training"]["seed_study"]["chosen_seed"] == study.chosen
    others = sorted(p.name for p in (params / "seeds").iterdir())
    assert others == sorted(f"{NAME}-ds1-seed{s}.json" for s in (0, 1, 2) if s != study.chosen)


def test_every_training_seed_builds_and_an_unknown_one_is_refused(installed: tuple[object, Path]) -> None:
    study, _ = installed
    for run in study.runs:
        built = make_estimator(NAME, scenario=SHORT, training_seed=run.seed)
        own = read_artifact(Path(run.out) / "parameters.json")["estimator_config"]["q_std"]
        assert built.q_std == pytest.approx(own, rel=1e-12)
    assert make_estimator(NAME, scenario=SHORT).q_std == pytest.approx(
        make_estimator(NAME, scenario=SHORT, training_seed=study.chosen).q_std, rel=0)
    with pytest.raises(ArtifactError, match="trained seeds 0, 1, 2"):
        make_estimator(NAME, scenario=SHORT, training_seed=7)
    with pytest.raises(ValueError, match="not both"):
        make_estimator(NAME, scenario=SHORT, training_seed=1, parameters="x.json")


def test_a_missing_seed_file_is_named(installed: tuple[object, Path], tmp_path: Path) -> None:
    study, _ = installed
    other = next(r.seed for r in study.runs if r.seed != study.chosen)
    path = seed_artifact_path(NAME, "ds1", other)
    saved = path.read_bytes()
    path.unlink()
    try:
        with pytest.raises(ArtifactError, match=f"seed{other}.json is missing"):
            make_estimator(NAME, scenario=SHORT, training_seed=other)
    finally:
        path.write_bytes(saved)


def test_the_leaderboard_shows_the_spread_over_training_seeds(installed: tuple[object, Path], tmp_path: Path) -> None:
    study, _ = installed
    selection = select_estimators([NAME, "manual-ekf"], [SHORT], training_seeds=True)
    assert sorted(dict(r.options).get("training_seed", -1) for r in selection.resolved) == sorted(
        [-1, -1, *(r.seed for r in study.runs if r.seed != study.chosen)])
    stress = get_scenario("ds1-noise5x", n_steps=2000)  # ds1's family, not its headline: no replicas
    assert [dict(r.options) for r in select_estimators([NAME], [stress], training_seeds=True).resolved] == [{}]
    store = ResultStore(tmp_path)
    run_grid(build_grid(selection.resolved, [SimulatedSource(SHORT)], range(3)), store=store, progress=False)
    files = build_leaderboards(store.load())
    ranking = pd.read_csv(io.StringIO(files["ds1.csv"]))
    assert sorted(ranking.estimator) == sorted([NAME, "manual-ekf"])  # replicas are folded, not ranked
    row = ranking.set_index("estimator").loc[NAME]
    assert row.training_seeds == 3
    assert row.state_rmse_training_seed_min <= row.state_rmse <= row.state_rmse_training_seed_max
    assert row.state_rmse_training_seed_min < row.state_rmse_training_seed_max
    assert pd.isna(ranking.set_index("estimator").loc["manual-ekf"].training_seeds)
    assert "training seeds" in files["ds1.md"] and "(3) |" in files["ds1.md"]
    index = files["README.md"]
    overview = index[index.index("### Spread over training seeds"):].splitlines()
    rows = {line.split("|")[1].strip(): line for line in overview if line.startswith("| ")}
    assert NAME in rows and "manual-ekf" not in rows  # every trained estimator, nothing else
    low, high = (format_number(v, 4) for v in (row.state_rmse_training_seed_min, row.state_rmse_training_seed_max))
    assert f"({low}-{high})" in rows[NAME]


@pytest.mark.parametrize("name, path", [
    ("flexkalmannet", "fkn_bench/flexkalmannet/params/flexkalmannet-spin.json"),
    ("kalmannet", "fkn_bench/kalmannet/params/kalmannet-spin.json"),
    ("direct-tuned-ekf", "baselines/params/direct-tuned-ekf-spin.json"),
])
def test_a_committed_artifact_retrains_with_the_configuration_it_records(name: str, path: str) -> None:
    """``--config ARTEFACT.json``: what a seed study of a committed estimator starts from."""
    from fkn_bench.training import trainable

    committed = read_artifact(REPO / path)["training"]["config"]
    again = trainable(name).config({"config": str(REPO / path), "seed": 7}).train_config()
    assert again.seed == 7
    assert {k: v for k, v in committed.items() if v is not None and k != "seed"} == {
        k: list(v) if isinstance(v, tuple) else v for k, v in vars(again).items()
        if k in committed and committed[k] is not None and k != "seed"}
