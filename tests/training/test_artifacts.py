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
