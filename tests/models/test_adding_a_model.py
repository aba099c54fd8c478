"""Adding a process model and an estimator from outside the package: one module (here, this
file) and one registration each, then the model runs through ``fkn-bench run``, ``fkn-bench
train`` and the conformance checker with no other change.

The toy model is the paper's constant-rate pose model with a velocity that decays with time
constant ``tau`` (``v' = exp(-dt / tau) v``, ``r' = r + v dt``): a different transition, so the
EKF must run the generic step (the model does not offer ``"structured-ekf"``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fkn_bench.cli import main
from fkn_bench.estimators import KalmanEstimator, make_estimator, registry as estimator_registry
from fkn_bench.estimators.conformance import (check_input_rules, check_survives_garbage, garbage_measurements,
                                              hostile_measurements)
from fkn_bench.filters import make_filter
from fkn_bench.models import PoseTwistModel, make_model, model_names, register_model
from fkn_bench.models import registry as model_registry
from fkn_bench.scenarios import registry as scenario_registry
from fkn_bench.training import fit

MODEL, ESTIMATOR = "damped-velocity", "damped-ekf"


class DampedVelocityModel(PoseTwistModel):
    """``[q, r, w, v]`` with ``v' = a v``, ``a = exp(-dt / tau)`` (tau in s); the rest the
    paper's model."""

    offers = frozenset({"pose-state"})

    def __init__(self, tau: float = 20.0) -> None:
        super().__init__()
        self.tau = tau

    def predict(self, x: Any, dt: float) -> Any:
        return self.transition(x, dt, jacobian=False)[0]

    def transition(self, x: Any, dt: float, *, jacobian: bool = True) -> tuple[Any, Any]:
        mean, F = super().transition(x, dt, jacobian=jacobian)
        scale = np.ones(13)
        scale[10:13] = math.exp(-dt / self.tau)
        if not isinstance(x, np.ndarray):
            import torch

            scale = torch.as_tensor(scale, dtype=x.dtype, device=x.device)
        return mean * scale, None if F is None else F * scale[:, None]


@pytest.fixture
def registered(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The model's and the estimator's one registration each (undone after the test)."""
    model_names()
    monkeypatch.setattr(model_registry, "_REGISTRY", dict(model_registry._REGISTRY))
    estimator_registry.estimator_names()
    monkeypatch.setattr(estimator_registry, "_REGISTRY", dict(estimator_registry._REGISTRY))
    monkeypatch.setattr(scenario_registry, "_REGISTRY", dict(scenario_registry._REGISTRY))
    register_model(MODEL, lambda inertia: DampedVelocityModel(), description="velocity decaying with tau = 20 s")
    estimator_registry.register_estimator(
        ESTIMATOR, lambda scenario=None, **options: KalmanEstimator(variant="ekf", model=MODEL, name=ESTIMATOR, **options),
        description="EKF on the damped-velocity model")
    yield


def test_the_toy_model_is_a_model_the_filters_run(registered: None) -> None:
    model = make_model(MODEL)
    assert isinstance(model, DampedVelocityModel) and MODEL in model_names()
    assert not make_filter("ekf", model=model)._structured  # (it offers no structured step)
    x = model.prior_state(2, np.float64)
    x[:, 10:13] = 1.0
    assert np.allclose(model.predict(x, 0.1)[:, 10:13], math.exp(-0.1 / 20.0))
    with pytest.raises(ValueError, match="unknown process model 'nope'; valid models: constant-velocity"):
        make_model("nope")
    with pytest.raises(ValueError, match="takes no inertia"):
        make_model(MODEL, inertia=(1.0, 2.0, 3.0))


def test_a_model_and_an_estimator_added_from_outside_run_train_and_conform(
    registered: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    estimator = make_estimator(ESTIMATOR)
    check_input_rules(estimator)
    hostile = hostile_measurements()
    check_survives_garbage(estimator, *garbage_measurements(hostile.measurements, hostile.mask, np.random.default_rng(0)),
                           hostile.dt)

    scenarios = tmp_path / "tiny.toml"
    scenarios.write_text('[scenario.tiny]\nbase = "ds1"\nn_steps = 2000\n')
    assert main(["run", "--estimator", ESTIMATOR, "--scenario", "tiny", "--scenario-file", str(scenarios),
                 "--seeds", "1", "--no-progress", "--json", "--out", str(tmp_path / "results")]) == 0
    (entry,) = json.loads(capsys.readouterr().out)["results"]
    assert entry["estimator"] == ESTIMATOR and 0 < entry["attitude_rmse_deg"] < 20

    outcome = fit("direct-tuned-ekf", "tiny", {"process_model": MODEL, "optimizer": "adam", "epochs": 1, "window": 200, "loss_cut": 50,
                                               "episodes": 1, "windows_per_batch": 4}, out=tmp_path / "train", progress=False, plots=False)
    assert outcome.estimator_config["model"] == MODEL and outcome.summary()["epochs_run"] == 1
    assert make_estimator("direct-tuned-ekf", parameters=str(outcome.artifact)).filter.model.tau == 20.0
