"""FlexKalmanNet as estimators of the common API.

* :class:`FlexKalmanNetEstimator` (``flexkalmannet``, the paper's use): the filter variant with the
  constant parameters the trained network yields on its training data. Runs from a learned-
  parameter artefact (the committed ``baselines/params/flexkalmannet-<family>.json`` by default,
  chosen by the scenario's ``model_family``) or from a checkpoint.
* :class:`AdaptiveFlexKalmanNetEstimator` (``flexkalmannet`` with ``mode="time_varying"``): the
  network re-evaluated along the sequence, each step's parameters the mean of its outputs over
  the last ``history`` measurements; needs a checkpoint (the weights).
"""

from __future__ import annotations

from collections import deque
from pathlib import Path
from typing import Any

import torch

from fkn_bench.estimators.base import Estimates, Estimator, RecursiveEstimator, check_batch_inputs, restart_diverged
from fkn_bench.estimators.kalman import filter_result_to_estimates
from fkn_bench.flexkalmannet.checkpoint import model_from_checkpoint
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario
from fkn_bench.training.artifacts import TrainedKalmanEstimator, artifact_factory, deployed_estimator_config
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["FlexKalmanNetEstimator", "AdaptiveFlexKalmanNetEstimator", "flexkalmannet_factory"]


class FlexKalmanNetEstimator(TrainedKalmanEstimator):
    """The filter with FlexKalmanNet's deployed constant parameters (see module docstring):
    a :class:`~fkn_bench.training.artifacts.TrainedKalmanEstimator` (keyword-only arguments of
    :class:`KalmanEstimator` plus ``metadata``), also built from a checkpoint."""

    default_name = "flexkalmannet"
    descriptions = {
        "flexkalmannet": "FlexKalmanNet: EKF with noise parameters learned by a network",
        "flexkalmannet-rigid-body": "FlexKalmanNet through the rigid-body model (inertia ratios estimated)",
    }

    @classmethod
    def from_checkpoint(cls, path: str | Path) -> FlexKalmanNetEstimator:
        model, config, scenario, document = model_from_checkpoint(path)
        metadata = {"checkpoint": str(path), "scenario": scenario.name, "best_epoch": document.get("best_epoch")}
        return cls(metadata=metadata, **deployed_estimator_config(model, config))


class AdaptiveFlexKalmanNetEstimator(RecursiveEstimator):
    """FlexKalmanNet's time-varying mode: per-step parameters from the recent measurements."""

    name = "flexkalmannet"
    description = "FlexKalmanNet, time-varying mode: the network's parameters averaged over recent measurements"

    def __init__(self, *, checkpoint: str | Path, history: int | None = None) -> None:
        self.checkpoint = str(checkpoint)
        self.model, self.config, self.scenario, _ = model_from_checkpoint(checkpoint)
        self.model.mode = "time_varying"
        if history is not None:
            if history < 1:
                raise ValueError(f"history must be >= 1 (got {history})")
            self.model.history = int(history)
        self.filter = self.config.build_filter()
        self._recent: deque[torch.Tensor] = deque(maxlen=self.model.history)

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        with torch.no_grad(), torch_threads():
            zt, mt = torch.from_numpy(z), torch.from_numpy(m)
            usable = mt & torch.isfinite(zt).all(-1)
            raw = self.model.time_varying_raw(torch.where(usable[..., None], zt, torch.zeros_like(zt)), usable)
            noise = self.model.parameter_set.to_noise(raw)
            result = self.filter.run(noise, zt, mt, dt=step)
        return restart_diverged(filter_result_to_estimates(result, self.filter), lambda zs, ms: self.estimate(zs, ms, step), z, m)

    def reset(self, *, dt: float) -> None:
        super().reset(dt=dt)
        self._recent.clear()

    def _online_observe(self, z: ArrayF | None) -> None:
        """The step's noise: the network's outputs averaged over the recent measurements, this
        step's included."""
        with torch.no_grad(), torch_threads():
            if z is not None:
                self._recent.append(self.model._outputs(torch.from_numpy(z))[0])
            raw = torch.stack(tuple(self._recent)).mean(0) if self._recent else self.model.deployed_raw()
            noise = self.model.parameter_set.to_noise(raw[None])
        self._online_noise = tuple(m[0].to(torch.float64).numpy() for m in (noise.process, noise.measurement, noise.initial))

    def to_config(self) -> dict[str, Any]:
        return {"checkpoint": self.checkpoint, "history": self.model.history}


def flexkalmannet_factory(
    scenario: Scenario | None = None,
    *,
    checkpoint: str | Path | None = None,
    parameters: str | Path | None = None,
    mode: str = "constant",
    history: int | None = None,
) -> Estimator:
    """Registry factory of ``flexkalmannet``.

    Args:
        scenario: picks the committed artefact of the scenario's model family (see
            :func:`~fkn_bench.training.artifacts.artifact_family`).
        checkpoint: use this trained checkpoint instead of the committed parameters.
        parameters: use this learned-parameter JSON (e.g. written by ``fkn-bench train``).
        mode: ``constant`` (paper) or ``time_varying`` (needs ``checkpoint``).
        history: time-varying mode: measurements averaged per step.
    """
    if checkpoint is not None and parameters is not None:
        raise ValueError("give either checkpoint=PATH or parameters=PATH, not both")
    if mode == "time_varying":
        if checkpoint is None:
            raise ValueError("flexkalmannet mode 'time_varying' needs checkpoint=PATH (the network weights)")
        return AdaptiveFlexKalmanNetEstimator(checkpoint=checkpoint, history=history)
    if mode != "constant":
        raise ValueError(f"mode must be 'constant' or 'time_varying' (got {mode!r})")
    if checkpoint is not None:
        return FlexKalmanNetEstimator.from_checkpoint(checkpoint)
    return artifact_factory("flexkalmannet", FlexKalmanNetEstimator)(scenario, parameters=parameters)
