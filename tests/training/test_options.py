"""Configuration values from files are data (issue 34, finding 5): a TOML configuration's numbers
are finite TOML numbers of the field's kind, and a refusal names the file and the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from fkn_bench.flexkalmannet import FlexKalmanNetConfig


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("lr = nan", "FlexKalmanNet config key 'lr' must be a finite number (got nan)"),
        ("lr = inf", "FlexKalmanNet config key 'lr' must be a finite number (got inf)"),
        ('lr = "0.1"', "FlexKalmanNet config key 'lr' must be a finite number (got '0.1')"),
        ("hidden = true", "FlexKalmanNet config key 'hidden' must be an integer (got True)"),
        ("weight_decay = -1.0", "weight_decay must be a finite number >= 0 (got -1.0)"),
        ("scheduler_factor = 1.5", "scheduler_factor must be a number in (0, 1) (got 1.5)"),
        ("dropout = 1.0", "dropout must be a number in [0, 1) (got 1.0)"),
        ("hiddn = 8", "unknown FlexKalmanNet config keys ['hiddn']"),
    ],
)
def test_a_toml_configuration_holds_finite_numbers_and_refusals_name_the_file(tmp_path: Path, line: str,
                                                                             message: str) -> None:
    path = tmp_path / "best.toml"
    path.write_text(f"[flexkalmannet]\n{line}\n")
    with pytest.raises(ValueError) as info:
        FlexKalmanNetConfig.from_toml(path)
    assert str(info.value).startswith(f"{path}: {message}")


def test_an_option_from_the_command_line_is_not_blamed_on_the_file(tmp_path: Path) -> None:
    path = tmp_path / "best.toml"
    path.write_text("[flexkalmannet]\nhidden = 8\n")
    with pytest.raises(ValueError) as info:
        FlexKalmanNetConfig.from_options({"config": str(path), "dropout": 2.0})
    assert str(info.value) == "dropout must be a number in [0, 1) (got 2.0)"
    assert FlexKalmanNetConfig.from_options({"config": str(path), "lr": 1}).hidden == 8
