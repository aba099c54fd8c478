"""``fkn-bench sweep --write-artifact``: a non-trainable estimator's best options become the tuned
settings that ``<name>`` runs (issue 21)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from fkn_bench.estimators import make_estimator
from fkn_bench.scenarios import get_scenario
from fkn_bench.sweep import parse_space
from fkn_bench.sweep.artifact import install_sweep_options, tuned_name
from fkn_bench.training import artifacts


def test_a_sweep_of_the_papers_settings_installs_the_tuned_settings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(artifacts, "params_dir", lambda package: tmp_path)  # not the package's own files
    space = parse_space({"fixed": {"warmup": 20}, "params": {"forgetting": {"values": [0.9, 0.97]}}}, "inline")
    settings = SimpleNamespace(estimator="sage-husa-default", scenario=get_scenario("ds2"), space=space, sampler="random")
    result = SimpleNamespace(best_params={"forgetting": 0.97}, best_value=0.0123, best_stage="random", best_number=1,
                             counts={"random": {"complete": 2}})
    path = install_sweep_options(settings, result)
    assert path == tmp_path / "sage-husa-ds2.json" and tuned_name("vbakf-default") == "vbakf"
    document = artifacts.read_artifact(path)
    assert document["estimator"] == "sage-husa" and document["estimator_config"] == {"warmup": 20, "forgetting": 0.97}
    assert document["training"]["best_value"] == 0.0123 and document["scenario"]["name"] == "ds2"
    built = make_estimator("sage-husa", scenario=get_scenario("ds2")).to_config()
    assert (built["forgetting"], built["warmup"]) == (0.97, 20)


def test_a_family_without_tuned_settings_names_the_sweep_that_makes_them(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(artifacts, "params_dir", lambda package: tmp_path)  # no committed settings at all
    with pytest.raises(artifacts.ArtifactError, match="fkn-bench sweep --space akhlaghi --scenario ds2 --write-artifact"):
        make_estimator("akhlaghi", scenario=get_scenario("ds2"))
