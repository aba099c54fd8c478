"""``fkn-bench run``: JSON document, table, defaults, exit codes, resume, determinism."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest

from fkn_bench.cli import main
from fkn_bench.estimators import estimator_names, make_estimator, registry as estimator_registry
from fkn_bench.scenarios import registry as scenario_registry
from fkn_bench.types import STATE_NAMES

pytestmark = pytest.mark.slow(seconds=8)  # fkn-bench run over every registered estimator

JSON_KEYS = (
    "estimator", "scenario", "seeds", "rmse", "attitude_rmse_deg", "position_rmse_m", "omega_rmse_rad_s",
    "velocity_rmse_m_s", "settling_time_s", "diverged_fraction", "anees", "nees_in_bounds_fraction", "us_per_step",
)
COST_KEYS = ("us_per_step", "us_per_step_batched", "peak_memory_mib")


@pytest.fixture(autouse=True)
def isolated_registries(monkeypatch: pytest.MonkeyPatch) -> None:
    """--scenario-file registers scenarios; some tests register estimators: keep both local."""
    monkeypatch.setattr(scenario_registry, "_REGISTRY", dict(scenario_registry._REGISTRY))
    estimator_names()
    monkeypatch.setattr(estimator_registry, "_REGISTRY", dict(estimator_registry._REGISTRY))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> str:
    """A TOML file defining ``tiny``: ds1 with 2000 samples (a 200-step test split)."""
    path = tmp_path_factory.mktemp("scenarios") / "tiny.toml"
    path.write_text('[scenario.tiny]\nbase = "ds1"\nn_steps = 2000\n')
    return str(path)


def _run_json(capsys: pytest.CaptureFixture, *args: str) -> dict:
    assert main(["run", *args, "--json"]) == 0
    captured = capsys.readouterr()
    return json.loads(captured.out)  # exactly one JSON document on stdout


def test_json_document(capsys: pytest.CaptureFixture, tiny: str) -> None:
    document = _run_json(capsys, "--estimator", "manual-ekf", "--scenario", "tiny", "--scenario-file", tiny,
                         "--seeds", "3", "--no-progress")
    (entry,) = document["results"]
    for key in JSON_KEYS:
        assert key in entry
    assert entry["estimator"] == "manual-ekf" and entry["scenario"] == "tiny" and entry["seeds"] == [0, 1, 2]
    assert list(entry["rmse"]) == list(STATE_NAMES)
    assert all(isinstance(v, float) for v in entry["rmse"].values())
    assert 0 < entry["attitude_rmse_deg"] < 20 and entry["diverged_fraction"] == 0.0
    assert entry["us_per_step"] > 0
    assert document["cells"] == {"total": 1, "computed": 1, "reused": 0, "failed": 0}


def test_progress_bar_goes_to_stderr(capsys: pytest.CaptureFixture, tiny: str) -> None:
    assert main(["run", "--scenario", "tiny", "--scenario-file", tiny, "--seeds", "2", "--json"]) == 0
    captured = capsys.readouterr()
    json.loads(captured.out)
    assert "fkn-bench run" in captured.err and "cell" in captured.err


def test_table_output(capsys: pytest.CaptureFixture, tiny: str) -> None:
    assert main(["run", "--estimator", "manual-ekf", "--estimator", "oracle-ekf", "--scenario", "tiny",
                 "--scenario-file", tiny, "--seeds", "2", "--no-progress"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("estimator / scenario")
    assert lines[2].startswith("manual-ekf / tiny") and lines[3].startswith("oracle-ekf / tiny")
    assert any("13-state RMSE" in line for line in lines[5:])


def _unavailable(scenario=None, **_):
    raise FileNotFoundError("no trained parameters")


def test_default_estimator_is_flexkalmannet_when_available(capsys: pytest.CaptureFixture, tiny: str) -> None:
    args = ("--scenario", "tiny", "--scenario-file", tiny, "--seeds", "1", "--no-progress")
    estimator_registry._REGISTRY.pop("flexkalmannet", None)
    assert [e["estimator"] for e in _run_json(capsys, *args)["results"]] == ["manual-ekf"]
    estimator_registry.register_estimator("flexkalmannet", _unavailable)
    assert [e["estimator"] for e in _run_json(capsys, *args)["results"]] == ["manual-ekf"]
    estimator_registry.register_estimator("flexkalmannet", lambda scenario=None, **_: make_estimator("manual-ekf"),
                                          overwrite=True)
    assert [e["estimator"] for e in _run_json(capsys, *args)["results"]] == ["flexkalmannet"]


def test_unavailable_estimator(capsys: pytest.CaptureFixture, tiny: str) -> None:
    """Named, an estimator that does not build exits 2 with the reason; under ``--all`` it is
    skipped with a message (:func:`run_all`)."""
    estimator_registry.register_estimator("needs-training", _unavailable)
    base = ["run", "--scenario", "tiny", "--scenario-file", tiny, "--seeds", "1", "--no-progress"]
    assert main([*base, "--estimator", "needs-training"]) == 2
    assert "not available for scenario tiny: FileNotFoundError: no trained parameters" in capsys.readouterr().err


def _only_for_tiny(scenario=None, **_):
    if scenario is None or scenario.name != "tiny":
        raise FileNotFoundError("no trained parameters for this scenario")
    return make_estimator("manual-ekf")


@pytest.fixture(scope="module")
def run_all(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """One ``run --all`` over two scenarios, shared by the tests of what ``--all`` runs and skips:
    ``tiny`` (ds1, 2000 samples) and ``other`` (400), with three estimators registered on top of
    the built-ins: ``needs-training`` builds for neither, ``partly-trained`` for ``tiny`` only,
    ``late-arrival`` (registered after the built-ins were loaded) for both. Each cell's online
    timing runs 5 ``step()`` calls once instead of 200 twice (the timing is not what these tests
    check; ``test_json_document`` checks it). Returns the JSON document, stderr and the
    estimators available for ``tiny``."""
    from fkn_bench.harness import cell, resolve
    from fkn_bench.scenarios import get_scenario

    two = tmp_path_factory.mktemp("scenarios") / "two.toml"
    two.write_text("[scenario.tiny]\nbase = \"ds1\"\nn_steps = 2000\n[scenario.other]\nbase = \"ds1\"\nn_steps = 400\n")
    real_time_online = cell.time_online
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(scenario_registry, "_REGISTRY", dict(scenario_registry._REGISTRY))
        estimator_names()
        patch.setattr(estimator_registry, "_REGISTRY", dict(estimator_registry._REGISTRY))
        patch.setattr(cell, "time_online", lambda estimator, measurements, dt: real_time_online(
            estimator, measurements[:5], dt, passes=1))
        estimator_registry.register_estimator("needs-training", _unavailable)
        estimator_registry.register_estimator("partly-trained", _only_for_tiny)
        estimator_registry.register_estimator("late-arrival", lambda scenario=None, **_: make_estimator("manual-mekf"),
                                              overwrite=True)
        with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.redirect_stderr(io.StringIO()) as err:
            code = main(["run", "--all", "--scenario", "tiny", "--scenario", "other", "--scenario-file", str(two),
                         "--seeds", "1", "--no-progress", "--cut", "10", "--json"])
        available = [r.name for r in resolve(None, [get_scenario("tiny")]) if r.available]
    assert code == 0, err.getvalue()
    return {"document": json.loads(out.getvalue()), "err": err.getvalue(), "available_on_tiny": available}


def test_all_runs_every_available_estimator(run_all: dict) -> None:
    available = run_all["available_on_tiny"]
    assert [e["estimator"] for e in run_all["document"]["results"] if e["scenario"] == "tiny"] == available
    assert "late-arrival" in available and {"manual-ekf", "oracle-ekf", "partly-trained"} <= set(available)


def test_all_skips_an_unavailable_estimator_with_a_message(run_all: dict) -> None:
    assert "skipping needs-training on tiny" in run_all["err"]
    assert "needs-training" not in [e["estimator"] for e in run_all["document"]["results"]]


def test_all_skips_only_the_unavailable_pairs(run_all: dict) -> None:
    pairs = [(e["estimator"], e["scenario"]) for e in run_all["document"]["results"]]
    assert ("partly-trained", "tiny") in pairs and ("partly-trained", "other") not in pairs
    assert ("manual-ekf", "other") in pairs


def test_default_scenario_and_seeds() -> None:
    from fkn_bench.cli.run import DEFAULT_SCENARIO, DEFAULT_SEEDS

    assert DEFAULT_SCENARIO == "spin" and DEFAULT_SEEDS >= 20  # the headline: a prior family, not the paper's memorisable ds1


def test_unknown_estimator_exits_2_with_the_list(capsys: pytest.CaptureFixture) -> None:
    assert main(["run", "--estimator", "kalmannet-9000", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "kalmannet-9000" in err and "valid estimators: " in err
    for name in estimator_names():
        assert name in err


def test_unknown_scenario_exits_2_with_the_list(capsys: pytest.CaptureFixture) -> None:
    assert main(["run", "--scenario", "ds9", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "ds9" in err and "valid scenarios: ds1, ds2" in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--seeds", "0"], "--seeds"),
        (["--workers", "0"], "--workers"),
        (["--scheduler", "tcp://127.0.0.1:1"], "--backend dask"),
        (["--rerun"], "--out"),
        (["--force"], "--force needs --out"),
        (["--cut", "5000"], "nothing to score"),
    ],
)
def test_usage_errors_exit_2(capsys: pytest.CaptureFixture, args: list[str], message: str) -> None:
    assert main(["run", *args, "--no-progress"]) == 2
    assert message in capsys.readouterr().err


def test_out_resumes_and_is_deterministic(capsys: pytest.CaptureFixture, tiny: str, tmp_path: Path) -> None:
    args = ("--estimator", "manual-ekf", "--scenario", "tiny", "--scenario-file", tiny, "--seeds", "12",
            "--out", str(tmp_path), "--no-progress")
    first = _run_json(capsys, *args)
    assert first["cells"] == {"total": 2, "computed": 2, "reused": 0, "failed": 0}
    assert len(list((tmp_path / "cells" / "manual-ekf" / "tiny").glob("*/*.json"))) == 2
    assert (tmp_path / "results.csv").exists() and json.loads((tmp_path / "results.json").read_text())["cells"] == 2
    second = _run_json(capsys, *args)
    assert second["cells"]["reused"] == 2 and second["results"] == first["results"]
    third = _run_json(capsys, *args, "--rerun")
    assert third["cells"]["computed"] == 2
    strip = [{k: v for k, v in r.items() if k not in COST_KEYS} for r in (first["results"][0], third["results"][0])]
    assert strip[0] == strip[1]  # recomputed: identical except timings


def test_help_lists_run(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["run", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for option in ("--estimator", "--scenario", "--seeds", "--split", "--json", "--out", "--backend", "--workers",
                   "--scheduler"):
        assert option in out


def _one_line_error(capsys: pytest.CaptureFixture, *args: str) -> str:
    """Run ``fkn-bench run`` expecting a usage error: exit 2 and one line on stderr, no traceback."""
    assert main(["run", *args, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_out_never_overwrites_a_directory_it_did_not_write(capsys: pytest.CaptureFixture, tiny: str, tmp_path: Path) -> None:
    args = ("--estimator", "manual-ekf", "--scenario", "tiny", "--scenario-file", tiny, "--seeds", "2", "--out", str(tmp_path))
    (tmp_path / "results.csv").write_text("mine\n")
    err = _one_line_error(capsys, *args)
    assert f"fkn-bench run: error: --out: {tmp_path} is not an fkn-bench results directory: it holds results.csv" in err
    assert "pass --force" in err and (tmp_path / "results.csv").read_text() == "mine\n"
    assert _run_json(capsys, *args, "--force")["cells"]["computed"] == 1
    assert (tmp_path / "results.csv").read_text() != "mine\n"
    assert _run_json(capsys, *args)["cells"]["reused"] == 1  # ours now: no --force needed


def test_out_naming_a_file_or_an_unwritable_path_is_a_one_line_error(capsys: pytest.CaptureFixture, tiny: str,
                                                                    tmp_path: Path) -> None:
    file = tmp_path / "results.txt"
    file.write_text("mine\n")
    args = ("--estimator", "manual-ekf", "--scenario", "tiny", "--scenario-file", tiny, "--seeds", "2")
    assert f"--out: {file} is a file, not a directory" in _one_line_error(capsys, *args, "--out", str(file), "--force")
    assert f"error: cannot write {file}/sub/.fkn-bench.lock: Not a directory" in _one_line_error(capsys, *args, "--out",
                                                                                                  str(file / "sub"))
    assert file.read_text() == "mine\n"


def test_a_scenario_file_that_is_not_utf8_is_one_line_not_a_traceback(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "latin1.toml"
    path.write_bytes(b"[scenario.caf\xe9]\nbase = \"ds1\"\n")
    assert main(["run", "--scenario-file", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "latin1.toml is not UTF-8 text" in err[0] and "Traceback" not in err[0]


def test_split_cut_and_options_keep_their_own_cells_in_one_out(capsys: pytest.CaptureFixture, tiny: str,
                                                               tmp_path: Path) -> None:
    """Issue 34, finding 3: each rerun into the same --out adds its cells, none replaces another's;
    a run with options is named by them."""
    args = ("--estimator", "manual-ekf", "--scenario", "tiny", "--scenario-file", tiny, "--seeds", "2",
            "--out", str(tmp_path), "--no-progress")
    variants = [(), ("--split", "val"), ("--cut", "150"), ("--estimator-option", "gate=0.5")]
    documents = [_run_json(capsys, *args, *variant) for variant in variants]
    assert [d["cells"]["computed"] for d in documents] == [1, 1, 1, 1]
    assert documents[3]["results"][0]["estimator"] == "manual-ekf (gate=0.5)"
    keys = [json.loads(p.read_text())["key"] for p in (tmp_path / "cells").rglob("seeds-0-1.json")]
    variants_kept = {(k["source"].rsplit(":", 1)[1], k["settings"]["cut"], str(k.get("estimator_options"))) for k in keys}
    assert variants_kept == {("test", 100, "None"), ("val", 100, "None"), ("test", 150, "None"),
                             ("test", 100, "[['gate', 0.5]]")}  # four cells: none replaced another


def test_a_full_disk_is_one_line_exit_2_and_leaves_no_cell_a_rerun_trusts(capsys: pytest.CaptureFixture, tiny: str,
                                                                         tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 34, finding 4 (run): ENOSPC while writing a cell's sums."""
    import errno

    from fkn_bench import io

    real_replace = io.os.replace

    def full(src: str, dst: str) -> None:
        if str(dst).endswith(".npz"):
            raise OSError(errno.ENOSPC, "No space left on device")
        real_replace(src, dst)

    args = ("--estimator", "manual-ekf", "--scenario", "tiny", "--scenario-file", tiny, "--seeds", "2",
            "--out", str(tmp_path))
    monkeypatch.setattr(io.os, "replace", full)
    err = _one_line_error(capsys, *args)
    assert "fkn-bench run: error: no space left on the device to write " in err and "seeds-0-1.npz" in err
    assert not list(tmp_path.rglob("*.json"))[1:]  # only the marker: no cell, no summary
    monkeypatch.setattr(io.os, "replace", real_replace)
    assert _run_json(capsys, *args, "--no-progress")["cells"] == {"total": 1, "computed": 1, "reused": 0, "failed": 0}


def test_a_second_run_into_one_out_is_refused_in_one_line(capsys: pytest.CaptureFixture, tiny: str, tmp_path: Path) -> None:
    from fkn_bench.io import directory_lock

    with directory_lock(tmp_path, "results"):
        err = _one_line_error(capsys, "--estimator", "manual-ekf", "--scenario", "tiny", "--scenario-file", tiny,
                              "--seeds", "1", "--out", str(tmp_path))
    assert f"fkn-bench run: error: {tmp_path} is in use by another fkn-bench process" in err


def test_without_seeds_each_scenario_scores_its_own_test_episodes(capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    two = tmp_path / "two.toml"
    two.write_text("[scenario.one]\nbase = \"ds1\"\nn_steps = 300\ntest_episodes = 1\n"
                   "[scenario.three]\nbase = \"ds1\"\nn_steps = 300\ntest_episodes = 3\n")
    document = _run_json(capsys, "--estimator", "manual-ekf", "--scenario", "one", "--scenario", "three",
                         "--scenario-file", str(two), "--no-progress", "--cut", "10")
    assert document["seeds"] == {"one": 1, "three": 3}
    assert {r["scenario"]: r["seeds"] for r in document["results"]} == {"one": [0], "three": [0, 1, 2]}
    given = _run_json(capsys, "--estimator", "manual-ekf", "--scenario", "one", "--scenario", "three",
                      "--scenario-file", str(two), "--no-progress", "--cut", "10", "--seeds", "2")
    assert given["seeds"] == 2 and all(r["seeds"] == [0, 1] for r in given["results"])
