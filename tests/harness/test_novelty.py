"""Novelty of a test episode's spin axis against the training trajectories
(:mod:`fkn_bench.harness.novelty`): the angle is geometry, the axis is the conserved angular
momentum, and the table groups each estimator's stored scores by it."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fkn_bench.harness import novelty
from fkn_bench.harness.novelty import TrainingSet, family_training_set, momentum_directions, novelty_degrees, novelty_table


def test_the_novelty_is_the_angle_to_the_nearest_training_direction() -> None:
    training = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    directions = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [np.nan] * 3])
    degrees = novelty_degrees(directions, training)
    assert degrees[:3] == pytest.approx([0.0, 90.0, 90.0])  # -z: 180 from +z, 90 from +x
    assert np.isnan(degrees[3])


def test_a_free_tumble_keeps_its_angular_momentum_from_the_train_to_the_test_split() -> None:
    # tumble-flip splits one trajectory in time; the world-frame rate moves, the momentum does not
    train, test = (momentum_directions("tumble-flip", [5], split=split) for split in ("train", "test"))
    assert np.linalg.norm(train, axis=1) == pytest.approx([1.0])
    assert test == pytest.approx(train, abs=1e-6)


def test_the_family_training_set_is_what_its_committed_artefacts_record() -> None:
    assert family_training_set("tumble") == TrainingSet(("tumble-fast", "tumble-flip", "tumble-slow"), 4)
    with pytest.raises(ValueError, match="no committed artefact of family 'no-such-family'"):
        family_training_set("no-such-family")


def test_the_table_groups_each_estimator_by_the_novelty_of_its_episodes(monkeypatch: pytest.MonkeyPatch) -> None:
    near, far = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    monkeypatch.setattr(novelty, "family_training_set", lambda family: type("T", (), {"directions": lambda self: near[None]})())
    monkeypatch.setattr(novelty, "momentum_directions", lambda scenario, seeds: np.array([near, far, near])[list(seeds)])
    rows = pd.DataFrame(
        [("memory", 0, 0.01, 0.0), ("memory", 1, 0.5, 1.0), ("memory", 2, 0.03, 0.0),
         ("estimation", 0, 0.02, 0.0), ("estimation", 1, 0.02, 0.0), ("estimation", 2, 0.02, 0.0)],
        columns=["estimator", "seed", "rmse", "diverged"])
    tidy = pd.concat([
        rows.assign(scenario="tumble-flip", group="state", metric="rmse", value=rows["rmse"]),
        rows.assign(scenario="tumble-flip", group="stability", metric="diverged", value=rows["diverged"]),
        rows.assign(scenario="ds1", group="state", metric="rmse", value=9.0),
    ])[["estimator", "scenario", "seed", "group", "metric", "value"]]
    table, degrees = novelty_table(tidy, "tumble-flip")
    assert degrees == pytest.approx([0.0, 90.0, 0.0])
    by = table.set_index("estimator")
    assert by.loc["memory", "near"] == pytest.approx(0.02) and by.loc["memory", "far"] == pytest.approx(0.5)
    assert by.loc["memory", "far / near"] == pytest.approx(25.0)
    assert (by.loc["memory", "diverged near"], by.loc["memory", "diverged far"]) == (0, 1)
    assert by.loc["estimation", "far / near"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="no stored results for scenario 'spin'"):
        novelty_table(tidy, "spin")
