"""``fkn-bench scenarios``: listing, one scenario in full, JSON, errors; the top-level parser."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fkn_bench import __version__
from fkn_bench.cli import COMMANDS, main
from fkn_bench.scenarios import get_scenario, list_scenarios, registry, scenario_names

BUILT_IN = ("ds1", "ds2", "ds1-noise5x", "ds1-gap100", "ds1-dropout", "tumble-slow", "tumble-fast", "ds1-flips")


@pytest.fixture(autouse=True)
def isolated_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """--scenario-file registers scenarios: keep them out of other tests."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def test_lists_all_names(capsys: pytest.CaptureFixture) -> None:
    assert main(["scenarios"]) == 0
    lines = capsys.readouterr().out.splitlines()
    listed = [line.split()[0] for line in lines]
    priors = [s.name for s in list_scenarios() if "prior" in s.tags]  # the prior families lead
    assert listed == priors + [name for name in scenario_names() if name not in priors] and listed[0] == "spin"
    assert tuple(scenario_names()[: len(BUILT_IN)]) == BUILT_IN
    for line, name in zip(lines, listed):
        assert line.endswith(get_scenario(name).description)


def test_lists_json(capsys: pytest.CaptureFixture) -> None:
    assert main(["scenarios", "--json"]) == 0
    documents = json.loads(capsys.readouterr().out)
    assert sorted(d["name"] for d in documents) == sorted(scenario_names()) and documents[0]["name"] == "spin"
    assert next(d for d in documents if d["name"] == "ds2") == get_scenario("ds2").to_dict()


def test_shows_one_scenario(capsys: pytest.CaptureFixture) -> None:
    assert main(["scenarios", "ds1-dropout"]) == 0
    out = capsys.readouterr().out
    fields = dict(line.split(None, 1) for line in out.splitlines())
    scenario = get_scenario("ds1-dropout")
    assert fields["name"] == "ds1-dropout"
    assert fields["dropout"] == "0.2" and fields["burst_length"] == "50" and fields["burst_rate"] == "0.002"
    assert fields["omega0"] == "[0.02, 0.04, 0.06]"
    assert fields["config_hash"] == scenario.config_hash()
    prior = {f"prior.{k}": v for k, v in scenario.describe_prior().items()}  # the stated prior over its truth
    assert set(fields) == set(scenario.to_dict()) | {"config_hash"} | set(prior)
    assert fields["prior.rate"] == "fixed (0.02, 0.04, 0.06) rad/s (world frame)" and fields["prior.attitude"] == prior["prior.attitude"]


def test_shows_one_scenario_json(capsys: pytest.CaptureFixture) -> None:
    assert main(["scenarios", "tumble-fast", "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    scenario = get_scenario("tumble-fast")
    assert document == scenario.to_dict() | {"config_hash": scenario.config_hash(), "prior": scenario.describe_prior()}


def test_unknown_name_exits_2(capsys: pytest.CaptureFixture) -> None:
    assert main(["scenarios", "ds9"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fkn-bench scenarios: error: unknown scenario 'ds9'")
    for name in BUILT_IN:
        assert name in err


def test_scenario_file_adds_scenarios(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "extra.toml"
    path.write_text(
        '[scenario.extra-a]\nbase = "ds2"\ndescription = "my variant"\nnoise_scale = 2.0\n'
        '[scenario.extra-b]\nbase = "extra-a"\nmeasurement_every = 5\n'
    )
    assert main(["scenarios", "--scenario-file", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines][-2:] == ["extra-a", "extra-b"]
    assert lines[-2].endswith("my variant")
    assert main(["scenarios", "extra-b", "--json", "--scenario-file", str(path)]) == 0
    document = json.loads(capsys.readouterr().out)
    assert (document["noise_scale"], document["measurement_every"], document["omega0"]) == (2.0, 5, [0.1, 0.2, 0.3])


def test_bad_scenario_file_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "broken.toml"
    path.write_text("[scenario.x\n")
    assert main(["scenarios", "--scenario-file", str(path)]) == 2
    assert "is not valid TOML" in capsys.readouterr().err


def test_top_level_parser(capsys: pytest.CaptureFixture) -> None:
    assert COMMANDS[:2] == ("scenarios", "simulate")
    with pytest.raises(SystemExit) as excinfo:
        main(["--version"])
    assert excinfo.value.code == 0
    assert capsys.readouterr().out.strip() == f"fkn-bench {__version__}"
    with pytest.raises(SystemExit) as excinfo:
        main([])
    assert excinfo.value.code == 2
    with pytest.raises(SystemExit) as excinfo:
        main(["frobnicate"])
    assert excinfo.value.code == 2
