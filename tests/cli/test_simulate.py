"""``fkn-bench simulate``: summary text, JSON values, exit codes; one run of the console script."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from fkn_bench.cli import main
from fkn_bench.envs import generate_episodes
from fkn_bench.scenarios import get_scenario, registry, scenario_names

SQRT3_TENTH_RAD_DEG = float(np.degrees(np.sqrt(3) * 0.1))  # rms of a 3-axis 0.1 rad error: 9.92 deg


@pytest.fixture(autouse=True)
def isolated_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """--scenario-file registers scenarios: keep them out of other tests."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def _json(capsys: pytest.CaptureFixture, *args: str) -> dict:
    assert main(["simulate", *args, "--json"]) == 0
    out = capsys.readouterr().out
    return json.loads(out)  # one JSON document, nothing else


def test_summary_text(capsys: pytest.CaptureFixture) -> None:
    assert main(["simulate", "--scenario", "ds1"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0] == f"Scenario ds1 (seed 0, full split, config {get_scenario('ds1').config_hash()})"
    assert "  dynamics            forced, |w| in [0.0748, 0.0748] rad/s" in lines
    assert "  samples             16000 x 0.1 s = 1600 s" in lines
    assert "  measurements        1600 (10.0% of steps)" in lines
    assert "  sign-flipped q      0" in lines
    assert any(line.startswith("  attitude noise      rms 9.") for line in lines)
    assert any(line.startswith("  position noise      rms 0.17") for line in lines)
    assert lines[-1] == "  initial position    [10.9, -6.7, 4.9] m"


def test_default_scenario_is_ds1(capsys: pytest.CaptureFixture) -> None:
    assert _json(capsys)["scenario"] == "ds1"


def test_json_values(capsys: pytest.CaptureFixture) -> None:
    doc = _json(capsys, "--scenario", "ds1")
    assert doc["scenario"] == "ds1" and doc["seed"] == 0 and doc["split"] == "full"
    assert doc["config_hash"] == get_scenario("ds1").config_hash()
    assert doc["dynamics"] == "forced"
    assert (doc["steps"], doc["dt_s"], doc["duration_s"]) == (16000, 0.1, 1600.0)
    assert doc["measurements"] == 1600 and doc["measurement_fraction"] == 0.1
    rate = np.linalg.norm([0.02, 0.04, 0.06])
    assert doc["rate_norm_rad_s"]["min"] == pytest.approx(rate, rel=1e-12)
    assert doc["rate_norm_rad_s"]["max"] == pytest.approx(rate, rel=1e-12)
    # 1600 samples of a 3-dof chi: the rms has a standard error of about 1%
    attitude, position = doc["measured_attitude_error_deg"], doc["measured_position_error_m"]
    assert attitude["rms"] == pytest.approx(SQRT3_TENTH_RAD_DEG, rel=0.04)
    assert position["rms"] == pytest.approx(np.sqrt(3) * 0.1, rel=0.04)
    assert attitude["rms"] < attitude["max"] < 45.0 and position["rms"] < position["max"] < 1.0
    assert doc["sign_flipped_quaternions"] == 0
    truth0 = generate_episodes("ds1", [0]).truth[0, 0]
    np.testing.assert_allclose(doc["initial_attitude_wxyz"], truth0[:4], atol=1e-6)
    assert doc["initial_position_m"] == [10.9, -6.7, 4.9]


def test_json_seed_split_and_noise(capsys: pytest.CaptureFixture) -> None:
    doc = _json(capsys, "--scenario", "ds1-noise5x", "--seed", "3", "--split", "test")
    assert (doc["seed"], doc["split"], doc["steps"], doc["measurements"]) == (3, "test", 1600, 160)
    assert doc["duration_s"] == pytest.approx(160.0)
    # 5x noise: 0.5 rad per axis, rms angle sqrt(3) * 0.5 rad (49.6 deg); 160 samples: ~3% error
    assert doc["measured_attitude_error_deg"]["rms"] == pytest.approx(5 * SQRT3_TENTH_RAD_DEG, rel=0.12)
    assert doc["measured_position_error_m"]["rms"] == pytest.approx(np.sqrt(3) * 0.5, rel=0.12)
    test = generate_episodes("ds1-noise5x", [3], split="test")
    np.testing.assert_allclose(doc["initial_attitude_wxyz"], test.truth[0, 0, :4], atol=1e-6)


def test_json_flips(capsys: pytest.CaptureFixture) -> None:
    flips = _json(capsys, "--scenario", "ds1-flips")
    assert flips["sign_flipped_quaternions"] == pytest.approx(flips["measurements"] / 2, rel=0.1)
    # 1% outliers with uniformly random attitudes
    assert flips["measured_attitude_error_deg"]["max"] > 90.0


def test_json_free_tumble(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "short.toml"
    path.write_text('[scenario.short-tumble]\nbase = "tumble-fast"\nn_steps = 3000\n')
    tumble = _json(capsys, "--scenario-file", str(path), "--scenario", "short-tumble", "--split", "val")
    assert tumble["dynamics"] == "free" and tumble["steps"] == 300
    assert tumble["rate_norm_rad_s"]["min"] < tumble["rate_norm_rad_s"]["max"]


def test_unknown_scenario_exits_2_and_lists_names(capsys: pytest.CaptureFixture) -> None:
    assert main(["simulate", "--scenario", "ds3"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith("fkn-bench simulate: error: unknown scenario 'ds3'; valid scenarios:")
    for name in scenario_names():
        assert name in captured.err


def test_bad_seed_exits_2(capsys: pytest.CaptureFixture) -> None:
    assert main(["simulate", "--seed", "-1"]) == 2
    assert "--seed must be a non-negative integer" in capsys.readouterr().err
    with pytest.raises(SystemExit) as excinfo:
        main(["simulate", "--seed", "zero"])
    assert excinfo.value.code == 2


def test_bad_split_exits_2(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as excinfo:
        main(["simulate", "--split", "dev"])
    assert excinfo.value.code == 2
    assert "invalid choice: 'dev'" in capsys.readouterr().err


def test_scenario_file(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "mine.toml"
    path.write_text('[scenario.my-gappy]\nbase = "ds2"\nmeasurement_every = 50\nn_steps = 1000\n')
    doc = _json(capsys, "--scenario-file", str(path), "--scenario", "my-gappy")
    assert (doc["scenario"], doc["steps"], doc["measurements"]) == ("my-gappy", 1000, 20)
    assert doc["rate_norm_rad_s"]["min"] == pytest.approx(np.linalg.norm([0.1, 0.2, 0.3]))
    assert main(["simulate", "--scenario-file", str(tmp_path / "absent.toml")]) == 2
    assert "scenario file not found" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text('[scenario.x]\nbase = "ds1"\ndropout = 7\n')
    assert main(["simulate", "--scenario-file", str(bad), "--scenario", "x"]) == 2
    assert "'dropout' must be a number in [0, 1]" in capsys.readouterr().err


def _console_script() -> str:
    name = "fkn-bench.exe" if sys.platform == "win32" else "fkn-bench"
    candidate = Path(sysconfig.get_path("scripts")) / name
    found = str(candidate) if candidate.exists() else shutil.which("fkn-bench")
    assert found, "the fkn-bench console script is not installed (pip install -e .)"
    return found


def test_console_script() -> None:
    out = subprocess.run(
        [_console_script(), "simulate", "--scenario", "ds1"], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("Scenario ds1 (seed 0, full split, config ")
    assert "measurements        1600 (10.0% of steps)" in out.stdout
    bad = subprocess.run(
        [_console_script(), "simulate", "--scenario", "nope"], capture_output=True, text=True, timeout=120
    )
    assert bad.returncode == 2 and "valid scenarios: ds1, ds2" in bad.stderr
