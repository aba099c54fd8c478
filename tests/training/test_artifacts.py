"""Trained estimators' configurations (a bad key is refused with the estimator's own class name) and
their committed parameter files (in the package each registration names, found by their labels)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fkn_bench.estimators import make_estimator
from fkn_bench.scenarios import get_scenario


@pytest.mark.parametrize("name", ["flexkalmannet", "direct-tuned-ekf"])
def test_unknown_config_keys_name_the_class_and_the_valid_keys(name: str) -> None:
    estimator = make_estimator(name)
    config = estimator.to_config()
    assert type(estimator).from_config(config).to_config() == config
    with pytest.raises(ValueError, match=rf"unknown {type(estimator).__name__} config keys \['bogus'\]; valid: .*'metadata'"):
        type(estimator).from_config({**config, "bogus": 1})


def test_artifact_family_default_for_anything_but_a_built_in_scenario() -> None:
    from fkn_bench.scenarios import get_scenario
    from fkn_bench.training.artifacts import DEFAULT_FAMILY, artifact_family, artifact_path

    assert artifact_path("flexkalmannet", DEFAULT_FAMILY).is_file()  # the committed mixture
    assert artifact_family("flexkalmannet", get_scenario("ds2")) == "ds2"
    assert artifact_family("flexkalmannet", get_scenario("tumble-flip")) == "tumble"
    changed = get_scenario("ds2").replace(noise_scale=2.0)  # a user's variant of a named scenario
    assert artifact_family("flexkalmannet", changed) == DEFAULT_FAMILY
    assert artifact_family("flexkalmannet", None) == DEFAULT_FAMILY
    # without a default artefact, the scenario's own family (ds1 without a scenario)
    assert artifact_family("nll-tuned-ekf", changed) == "ds2" and artifact_family("nll-tuned-ekf", None) == "ds1"


def test_parameter_files_are_complete_or_rejected_naming_file_and_key(tmp_path) -> None:  # noqa: ANN001
    """Issue 19: a file without r_std is not completed with the manual tuning, a file of another
    estimator is not accepted, a sigma that overflows is refused, and both sources are refused."""
    import json

    from fkn_bench.training.artifacts import ArtifactError, artifact_path

    committed = json.loads(artifact_path("flexkalmannet", "ds1").read_text())

    def written(name: str, change) -> str:  # noqa: ANN001
        document = json.loads(json.dumps(committed))
        change(document)
        path = tmp_path / name
        path.write_text(json.dumps(document))
        return str(path)

    cases = {
        "no-r.json": (lambda d: d["estimator_config"].pop("r_std"), r"no-r\.json: 'estimator_config' lacks r_std \(or r_cov\)"),
        "other.json": (lambda d: d.update(estimator="nll-tuned-ekf"), r"other\.json holds 'nll-tuned-ekf' parameters, not flexkalmannet's"),
        "huge.json": (lambda d: d["estimator_config"]["r_std"].__setitem__(2, 1e160), r"huge\.json: .*r_std\[2\] = 1e\+160 is outside"),
        # issue 34, finding 5: numbers are JSON numbers (true was read as 1, "0.1" as 0.1)
        "true.json": (lambda d: d["estimator_config"]["r_std"].__setitem__(0, True),
                      r"true\.json: 'estimator_config': 'r_std' must be a list of finite numbers or none \(got \[True"),
        "text.json": (lambda d: d["estimator_config"]["q_std"].__setitem__(1, "0.1"), r"text\.json: .*'q_std' must be a list of"),
        "nan.json": (lambda d: d["estimator_config"]["p0_std"].__setitem__(1, float("nan")), r"nan\.json: .*'p0_std' must be"),
    }
    for name, (change, message) in cases.items():
        with pytest.raises(ArtifactError, match=message):
            make_estimator("flexkalmannet", parameters=written(name, change))
    assert make_estimator("flexkalmannet", parameters=written("same.json", lambda d: None)).r_std.tolist() == committed["estimator_config"]["r_std"]
    with pytest.raises(ArtifactError, match="file name is empty"):
        make_estimator("flexkalmannet", parameters="")
    with pytest.raises(ArtifactError, match="is a directory"):
        make_estimator("flexkalmannet", parameters=str(tmp_path))
    with pytest.raises(ValueError, match="give one of checkpoint=PATH, parameters=PATH and training_seed=K, not several"):
        make_estimator("flexkalmannet", parameters=written("same.json", lambda d: None), checkpoint="x.pt")


@pytest.mark.parametrize(
    ("estimator", "options", "message"),
    [
        ("flexkalmannet", {"hidden": "abc"}, "FlexKalmanNet config key 'hidden' must be an integer (got 'abc')"),
        ("flexkalmannet", {"lr": "fast"}, "FlexKalmanNet config key 'lr' must be a finite number (got 'fast')"),
        ("flexkalmannet", {"epochs": 2.5}, "FlexKalmanNet config key 'epochs' must be an integer (got 2.5)"),
        ("flexkalmannet", {"inertia": 1}, "FlexKalmanNet config key 'inertia' must be a list of 3 values or none (got 1)"),
        ("kalmannet", {"window": True}, "KalmanNet config key 'window' must be an integer (got True)"),
        ("nll-tuned-ekf", {"lr": "abc"}, "nll-tuned-ekf config key 'lr' must be a finite number (got 'abc')"),
    ],
)
def test_training_options_of_the_wrong_type_name_the_key_and_what_is_valid(estimator: str, options: dict, message: str) -> None:
    """Issue 20, item 2: `--set hidden=abc` said "'<' not supported between 'str' and 'int'"."""
    from fkn_bench.training import trainable

    with pytest.raises(ValueError) as info:
        trainable(estimator).config(options)
    assert str(info.value) == message
    assert trainable("flexkalmannet").config({"learn": "q_std,r_std", "lr": 1, "samples_per_window": None}).learn == ("q_std", "r_std")


def test_each_committed_file_lives_in_the_package_its_estimator_registration_names() -> None:
    """Issue 35, item 3: the parameter files belong to the package that trains them (the
    registration's ``params_package``), and the training layer finds them through the registry."""
    from fkn_bench.estimators import estimator_spec, estimator_specs
    from fkn_bench.training.artifacts import artifact_path, params_dir, read_artifact

    owners = {spec.name: spec.params_package for spec in estimator_specs() if spec.params_package is not None}
    assert owners["flexkalmannet"] == owners["flexkalmannet-tv"] == "fkn_bench.flexkalmannet"
    assert owners["kalmannet"] == owners["recursive-kalmannet"] == "fkn_bench.kalmannet"
    assert owners["sage-husa"] == owners["nll-tuned-ekf"] == "fkn_bench.baselines"
    assert estimator_spec("manual-ekf").params_package is None and "sage-husa-default" not in owners
    for package in set(owners.values()):
        files = sorted(params_dir(package).glob("*.json"))
        assert files, f"{package} declares committed parameter files and has none"
        for path in files:
            estimator = read_artifact(path)["estimator"]
            assert owners[estimator] == package and artifact_path(estimator, read_artifact(path)["family"]) == path, path


def test_labels_name_the_owning_package_and_the_old_baselines_labels_still_resolve(tmp_path) -> None:  # noqa: ANN001
    """A committed file's label is ``<package>/params/<file>``; the label of a file written
    before it moved (``fkn_bench.baselines/params/<file>``, in stored results and old estimator
    files) resolves to where it is now, and an estimator built from it names the new label."""
    from fkn_bench.estimators import load_estimator
    from fkn_bench.training.artifacts import artifact_label, artifact_path, resolve_artifact_label

    weights = artifact_path("kalmannet", "ds1").with_name("kalmannet-ds1.weights.pt")
    assert artifact_label(weights) == "fkn_bench.kalmannet/params/kalmannet-ds1.weights.pt"
    assert resolve_artifact_label("fkn_bench.kalmannet/params/kalmannet-ds1.weights.pt") == weights
    assert resolve_artifact_label("fkn_bench.baselines/params/kalmannet-ds1.weights.pt") == weights  # moved
    assert resolve_artifact_label("fkn_bench.baselines/params/flexkalmannet-ds1.json") == artifact_path("flexkalmannet", "ds1")
    assert resolve_artifact_label("fkn_bench.baselines/params/vbakf-ds1.json") == artifact_path("vbakf", "ds1")  # not moved
    assert resolve_artifact_label("runs/x/parameters.json") == Path("runs/x/parameters.json")
    assert resolve_artifact_label("fkn_bench.kalmannet/params/gone.pt") == weights.with_name("gone.pt")  # named when missing
    built = make_estimator("flexkalmannet-tv", scenario=get_scenario("spin"))
    old = {**built.to_config(), "checkpoint": "fkn_bench.baselines/params/flexkalmannet-tv-spin.weights.pt"}
    assert type(built).from_config(old).to_config() == built.to_config()
    assert built.to_config()["checkpoint"] == "fkn_bench.flexkalmannet/params/flexkalmannet-tv-spin.weights.pt"
    saved = json.loads(built.save(tmp_path / "tv.json").read_text())
    saved["config"]["checkpoint"] = "fkn_bench.baselines/params/flexkalmannet-tv-spin.weights.pt"  # saved before the move
    (tmp_path / "old.json").write_text(json.dumps(saved))
    assert load_estimator(tmp_path / "old.json").to_config() == built.to_config()


def test_an_estimator_registered_without_a_params_package_has_no_committed_files(monkeypatch: pytest.MonkeyPatch) -> None:
    from fkn_bench.estimators import registry
    from fkn_bench.training.artifacts import ArtifactError, artifact_factory, artifact_path, committed_artifact_path

    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    registry.register_estimator("plugin-trained", artifact_factory("plugin-trained"))
    with pytest.raises(ArtifactError, match="'plugin-trained' has no committed parameter files .*pass parameters=PATH"):
        make_estimator("plugin-trained", scenario=get_scenario("ds1"))
    assert committed_artifact_path("plugin-trained", "ds1") is None and committed_artifact_path("no-such", "ds1") is None
    assert committed_artifact_path("kalmannet", "nowhere") is None
    assert committed_artifact_path("kalmannet", "ds1") == artifact_path("kalmannet", "ds1")
    with pytest.raises(ValueError, match="params_package of estimator 'x' must be a dotted package name"):
        registry.register_estimator("x", artifact_factory("x"), params_package="my package/params")


def test_the_recorded_command_reruns_from_the_repository_root(tmp_path: Path) -> None:
    from fkn_bench.training.artifacts import artifact_path, portable_command

    committed = artifact_path("kalmannet", "ds1").resolve()
    outside = tmp_path / "run"
    outside.mkdir()
    command = portable_command(["/some/venv/bin/fkn-bench", "train", "--config", str(committed), "--out", str(outside),
                                "--seeds", "0", "1"])
    root = Path(__file__).resolve().parents[2]
    assert command == ["fkn-bench", "train", "--config", committed.relative_to(root).as_posix(), "--out", str(outside),
                       "--seeds", "0", "1"]
