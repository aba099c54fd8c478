"""How far each test episode's motion is from every trajectory the learned estimators trained on,
and each estimator's score on the near and the far episodes (``fkn-bench leaderboard --novelty
SCENARIO``).

A learned filter is trained on a few trajectories (``episodes`` of each training scenario, 4 in
every committed artefact); its test episodes may spin about axes none of them had. The invariant
that says which way a body spins is its angular momentum, whose direction in the world frame is
fixed for a torque-free body: ``h = R J R^T omega`` with ``R`` the body-to-world rotation, ``J``
the scenario's nominal principal inertia (kg m^2) and ``omega`` the world-frame rate (rad/s) of the
split's first step; for the other dynamics (a constant or slowly drifting rate) ``h`` is the rate
itself. An episode's *novelty* is the angle (degrees) between its ``h`` and the nearest training
trajectory's. Scores are grouped at :data:`NEAR_DEGREES`: a filter that estimates should score
alike on both groups (the same noise, the same dynamics), one that memorised its training
trajectories should not. The training set is the one every committed artefact of the scenario's
family records (``training.data``: training scenarios, ``episodes`` and each scenario's
``dataset_seed``; :mod:`fkn_bench.training.data`); artefacts that disagree are an error.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from fkn_bench.envs import generate_episodes
from fkn_bench.geometry.quaternion import rotation_matrix
from fkn_bench.scenarios import Scenario, get_scenario

__all__ = ["NEAR_DEGREES", "TrainingSet", "momentum_directions", "novelty_degrees", "family_training_set",
           "novelty_table"]

NEAR_DEGREES = 45.0
"""An episode whose angular momentum lies within this angle of a training trajectory's is near."""


@dataclass(frozen=True)
class TrainingSet:
    """The trajectories a family's artefacts trained on: ``scenarios`` (names), ``episodes`` of
    each (seeds ``dataset_seed, dataset_seed + 1, ...`` of its train split)."""

    scenarios: tuple[str, ...]
    episodes: int

    def directions(self) -> np.ndarray:
        """``(N, 3)`` unit angular-momentum directions of every training trajectory."""
        from fkn_bench.training.data import episodes_of

        parts = []
        for name in self.scenarios:
            scenario = get_scenario(name)
            seeds = [scenario.dataset_seed + i for i in range(episodes_of(scenario, self.episodes))]
            parts.append(momentum_directions(scenario, seeds, split="train"))
        return np.concatenate(parts)


def momentum_directions(scenario: str | Scenario, seeds: Sequence[int], *, split: str = "test") -> np.ndarray:
    """``(B, 3)`` unit world-frame angular-momentum directions of ``scenario``'s episodes ``seeds``
    at the first step of ``split`` (module docstring); a row of NaN where the body does not spin."""
    scenario = get_scenario(scenario)
    episodes = generate_episodes(scenario, list(seeds), split=split)
    q, omega = episodes.truth[:, 0, :4], episodes.truth[:, 0, 7:10]
    if scenario.dynamics == "free":
        R = rotation_matrix(q)
        h = np.einsum("bij,j,bkj,bk->bi", R, np.asarray(scenario.inertia, dtype=float), R, omega)
    else:
        h = np.array(omega, dtype=float)
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 0, h / norm, np.nan)


def novelty_degrees(directions: np.ndarray, training: np.ndarray) -> np.ndarray:
    """``(B,)`` angle (degrees) from each of ``directions (B, 3)`` to the nearest of ``training
    (N, 3)`` (unit vectors; NaN where a direction is NaN)."""
    if not training.size:
        return np.full(len(directions), np.nan)
    cosines = np.clip(directions @ training.T, -1.0, 1.0)
    nearest = np.where(np.isnan(cosines), -np.inf, cosines).max(axis=1)
    return np.where(np.isfinite(nearest), np.degrees(np.arccos(np.clip(nearest, -1.0, 1.0))), np.nan)


def family_training_set(family: str) -> TrainingSet:
    """The training set of ``family``'s committed artefacts (module docstring); raises
    ``ValueError`` when none records one or two disagree."""
    from fkn_bench.estimators.registry import estimator_names
    from fkn_bench.training.artifacts import committed_artifact_path

    found: dict[TrainingSet, list[str]] = {}
    for name in estimator_names():
        path = committed_artifact_path(name, family)
        if path is None:
            continue
        artefact = json.loads(path.read_text())
        data = artefact.get("training", {}).get("data") or {}
        label = (artefact.get("scenario") or {}).get("name")
        if not label or not isinstance(data.get("episodes"), int):
            continue
        found.setdefault(TrainingSet(tuple(label.split("+")), int(data["episodes"])), []).append(name)
    if not found:
        raise ValueError(f"no committed artefact of family {family!r} records its training data")
    if len(found) > 1:
        described = "; ".join(f"{', '.join(names)}: {s.scenarios} x {s.episodes}" for s, names in found.items())
        raise ValueError(f"the artefacts of family {family!r} trained on different sets ({described})")
    return next(iter(found))


def novelty_table(rows: pd.DataFrame, scenario: str, *, near_degrees: float = NEAR_DEGREES) -> tuple[pd.DataFrame, np.ndarray]:
    """Per estimator label of ``rows`` (stored tidy rows, :meth:`~fkn_bench.harness.records.Results.rows`)
    on ``scenario``: mean 13-state RMSE and diverged count on the near and the far test episodes
    and the far-to-near ratio; returns it with the novelty (degrees) of each test seed."""
    own = rows[(rows["scenario"] == scenario) & rows["group"].isin(["state", "stability"])]
    if own.empty:
        raise ValueError(f"no stored results for scenario {scenario!r}")
    seeds = sorted(int(s) for s in own["seed"].unique())
    training = family_training_set(get_scenario(scenario).model_family).directions()
    degrees = novelty_degrees(momentum_directions(scenario, seeds), training)
    far = [seed for seed, angle in zip(seeds, degrees) if angle > near_degrees]
    table = []
    for label, part in own.groupby("estimator", sort=True):
        rmse = part[(part["group"] == "state") & (part["metric"] == "rmse")].set_index("seed")["value"]
        diverged = part[part["metric"] == "diverged"].set_index("seed")["value"]
        near_mean, far_mean = float(rmse[~rmse.index.isin(far)].mean()), float(rmse[rmse.index.isin(far)].mean())
        far_diverged = diverged.index.isin(far)
        table.append({
            "estimator": label, "near": near_mean, "far": far_mean,
            "far / near": far_mean / near_mean if near_mean > 0 else math.nan,
            "diverged near": int(diverged[~far_diverged].sum()), "diverged far": int(diverged[far_diverged].sum()),
        })
    return pd.DataFrame(table), degrees
