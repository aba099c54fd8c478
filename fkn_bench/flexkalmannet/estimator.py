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
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fkn_bench.estimators.base import Estimates, Estimator, RecursiveEstimator, check_batch_inputs
from fkn_bench.estimators.kalman import KalmanEstimator, filter_result_to_estimates
from fkn_bench.filters import make_filter
from fkn_bench.flexkalmannet.checkpoint import model_from_checkpoint
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario
from fkn_bench.training.artifacts import ArtifactError, artifact_label, artifact_path, read_artifact
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["FlexKalmanNetEstimator", "AdaptiveFlexKalmanNetEstimator", "flexkalmannet_factory", "deployed_estimator_config"]


def deployed_estimator_config(model: Any, variant: str) -> dict[str, Any]:
    """KalmanEstimator config (variant and noise matrices or stds) of a trained model's deployed
    parameters."""
    with torch.no_grad():
        noise = model.parameter_set.to_noise(model.deployed_raw())
    config: dict[str, Any] = {"variant": variant}
    for entry, matrix in (("q", noise.process), ("r", noise.measurement), ("p0", noise.initial)):
        m = matrix.detach().to(torch.float64).numpy()
        if np.count_nonzero(m - np.diag(np.diag(m))) == 0:
            config[f"{entry}_std"] = np.sqrt(np.diag(m)).tolist()
        else:
            config[f"{entry}_cov"] = m.tolist()
    return config


class FlexKalmanNetEstimator(KalmanEstimator):
    """The filter with FlexKalmanNet's deployed constant parameters (see module docstring).

    Keyword-only arguments are those of :class:`KalmanEstimator` plus ``metadata`` (training and
    provenance information, kept in the saved config).
    """

    def __init__(self, *, metadata: Mapping[str, Any] | None = None, **config: Any) -> None:
        config.setdefault("name", "flexkalmannet")
        config.setdefault("description", "FlexKalmanNet: EKF with noise parameters learned by a network")
        super().__init__(**config)
        self.metadata = dict(metadata or {})

    @classmethod
    def from_artifact(cls, path: str | Path) -> FlexKalmanNetEstimator:
        document = read_artifact(path)
        metadata = {k: document.get(k) for k in ("family", "scenario", "training", "provenance")}
        metadata["artifact"] = artifact_label(path)
        return cls(metadata=metadata, **document["estimator_config"])

    @classmethod
    def from_checkpoint(cls, path: str | Path) -> FlexKalmanNetEstimator:
        model, config, scenario, document = model_from_checkpoint(path)
        metadata = {"checkpoint": str(path), "scenario": scenario.name, "best_epoch": document.get("best_epoch")}
        return cls(metadata=metadata, **deployed_estimator_config(model, config.variant))

    def to_config(self) -> dict[str, Any]:
        return {**super().to_config(), "metadata": self.metadata}

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> FlexKalmanNetEstimator:
        config = dict(config)
        metadata = config.pop("metadata", None)
        known = {"variant", "q_std", "r_std", "p0_std", "q_cov", "r_cov", "p0_cov", "name", "description"}
        unknown = sorted(set(config) - known)
        if unknown:
            raise ValueError(f"unknown FlexKalmanNetEstimator config keys {unknown}; valid: {sorted(known | {'metadata'})}")
        return cls(metadata=metadata, **config)


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
        self.filter = make_filter(self.config.variant)
        self._recent: deque[torch.Tensor] = deque(maxlen=self.model.history)

    def estimate(self, measurements: ArrayF, mask: ArrayB, dt: float) -> Estimates:
        z, m, step = check_batch_inputs(measurements, mask, dt)
        with torch.no_grad(), torch_threads():
            zt, mt = torch.from_numpy(z), torch.from_numpy(m)
            usable = mt & torch.isfinite(zt).all(-1)
            raw = self.model.time_varying_raw(torch.where(usable[..., None], zt, torch.zeros_like(zt)), usable)
            noise = self.model.parameter_set.to_noise(raw)
            result = self.filter.run(noise, zt, mt, dt=step)
        return filter_result_to_estimates(result, self.filter)

    def reset(self, *, dt: float) -> None:
        super().reset(dt=dt)
        self._recent.clear()

    def _current_raw(self) -> torch.Tensor:
        if not self._recent:
            return self.model.deployed_raw()
        return torch.stack(tuple(self._recent)).mean(0)

    def _online_observe(self, z: ArrayF | None) -> None:
        """The step's noise: the network's outputs averaged over the recent measurements, this
        step's included."""
        with torch.no_grad(), torch_threads():
            if z is not None:
                self._recent.append(self.model._outputs(torch.from_numpy(z))[0])
            noise = self.model.parameter_set.to_noise(self._current_raw()[None])
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
        scenario: picks the committed artefact of ``scenario.model_family`` (ds1 when None).
        checkpoint: use this trained checkpoint instead of the committed parameters.
        parameters: use this learned-parameter JSON (e.g. written by ``fkn-bench train``).
        mode: ``constant`` (paper) or ``time_varying`` (needs ``checkpoint``).
        history: time-varying mode: measurements averaged per step.
    """
    if mode == "time_varying":
        if checkpoint is None:
            raise ValueError("flexkalmannet mode 'time_varying' needs checkpoint=PATH (the network weights)")
        return AdaptiveFlexKalmanNetEstimator(checkpoint=checkpoint, history=history)
    if mode != "constant":
        raise ValueError(f"mode must be 'constant' or 'time_varying' (got {mode!r})")
    if checkpoint is not None:
        return FlexKalmanNetEstimator.from_checkpoint(checkpoint)
    if parameters is not None:
        return FlexKalmanNetEstimator.from_artifact(parameters)
    family = scenario.model_family if scenario is not None else "ds1"
    path = artifact_path("flexkalmannet", family)
    if not path.is_file():
        raise ArtifactError(
            f"no committed FlexKalmanNet parameters for model family '{family}' ({path}); train them with "
            f"`fkn-bench train --estimator flexkalmannet --scenario {family} --write-artifact`"
        )
    return FlexKalmanNetEstimator.from_artifact(path)
