"""Trained estimators' configurations: a bad key is refused with the estimator's own class name."""

from __future__ import annotations

import pytest

from fkn_bench.estimators import make_estimator


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
